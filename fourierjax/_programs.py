"""Counting the XLA programs and traces a piece of code makes (the cost of a warm command line call)."""

from __future__ import annotations

import collections
import json
import os
import traceback

#: Set to a file path: the command line writes there, as JSON, what `ProgramCount` saw during
#: the command (tests and `experiments/benchmarks/startup.py` read it).
PROGRAM_LOG_ENV = "FOURIERJAX_PROGRAM_LOG"

_PHASES = {
    "jaxpr_trace_duration": "trace",
    "jaxpr_to_mlir_module_duration": "lower",
    "backend_compile_duration": "compile_or_load",
    "cache_retrieval_time_sec": "cache_read",
}


class ProgramCount:
    """A context manager that counts JAX's compile events while it is open.

    Every program a call needs is traced, lowered and then compiled or read from the
    persistent compile cache, even when the cache is warm; an eager `jnp` operation on a new
    shape is a program too. On a warm cache these counts, not XLA, set a second call's time.

    Attributes (after the block):
        programs: XLA programs compiled or loaded from the cache.
        traces: functions traced to jaxprs.
        seconds: `{"trace", "lower", "compile_or_load", "cache_read"}` totals.
        by_name: programs per traced function name (from the trace events).
        where: programs per innermost three fourierjax source lines that asked for them.
        seconds_by_name: `{name: {phase: seconds}}` per traced, lowered or compiled function
            name (the cache read has no name).
    """

    def __init__(self):
        self.programs = 0
        self.traces = 0
        self.seconds: dict[str, float] = collections.defaultdict(float)
        self.by_name: collections.Counter = collections.Counter()
        self.where: collections.Counter = collections.Counter()
        self.seconds_by_name: dict = collections.defaultdict(lambda: collections.defaultdict(float))

    def _listener(self, event: str, duration_secs: float, **kwargs) -> None:
        phase = _PHASES.get(event.rsplit("/", 1)[-1])
        if phase is None:
            return
        self.seconds[phase] += duration_secs
        if "fun_name" in kwargs:
            self.seconds_by_name[str(kwargs["fun_name"])][phase] += duration_secs
        if phase == "trace":
            self.traces += 1
            self.by_name[str(kwargs.get("fun_name"))] += 1
        elif phase == "compile_or_load":
            self.programs += 1
            self.where[_caller()] += 1

    def __enter__(self) -> ProgramCount:
        from jax import monitoring

        monitoring.register_event_duration_secs_listener(self._listener)
        return self

    def __exit__(self, *exc) -> None:
        from jax import monitoring

        monitoring.unregister_event_duration_listener(self._listener)

    def summary(self) -> dict:
        """The counts as a JSON-ready dict.

        Returns:
            `{"programs", "traces", "seconds", "by_name", "where", "seconds_by_name"}`
            (``seconds_by_name`` sorted by total, largest first).
        """
        by_name = sorted(self.seconds_by_name.items(), key=lambda kv: -sum(kv[1].values()))
        return {"programs": self.programs, "traces": self.traces,
                "seconds": {k: round(v, 4) for k, v in self.seconds.items()},
                "by_name": dict(self.by_name.most_common()), "where": dict(self.where.most_common()),
                "seconds_by_name": {k: {p: round(t, 4) for p, t in v.items()} for k, v in by_name}}

    def write(self, path: str | os.PathLike) -> None:
        """Write `summary()` to `path` as JSON.

        Arguments:
            path: the file to write.
        """
        with open(path, "w") as f:
            json.dump(self.summary(), f, indent=1)


def _caller() -> str:
    """The innermost three fourierjax source lines on the stack (outside site-packages)."""
    frames = [f for f in traceback.extract_stack()[:-2]
              if "fourierjax" in f.filename and "site-packages" not in f.filename
              and not f.filename.endswith("_programs.py")]
    return " < ".join(f"{f.filename.rsplit('fourierjax/', 1)[-1]}:{f.lineno}" for f in frames[::-1][:3])
