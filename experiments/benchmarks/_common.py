"""Timing, records and sizes shared by the benchmarks."""

from __future__ import annotations

import dataclasses
import os
import platform
import subprocess
import time
from collections.abc import Callable

import numpy as np

SIZES = ("full", "small")

#: First-call times (s) measured inside other benchmarks, merged by `compile_times` (entry points
#: too slow to compile twice in one run, e.g. the stance solver).
COMPILE_TIMES: dict[str, dict] = {}


def load_average() -> list[float] | None:
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


def cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _block(x):
    import jax

    return jax.block_until_ready(x)


#: JAX's duration events (seconds) for the phases of a first call, summed over every program
#: that call compiles (the entry point's own and any small eager op around it).
PHASE_EVENTS = {
    "trace_s": "/jax/core/compile/jaxpr_trace_duration",
    "lower_s": "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "xla_compile_s": "/jax/core/compile/backend_compile_duration",
}


def first_call_phases(fn) -> tuple[float, dict]:
    """`(seconds, phases)` of a first call: `phases` holds trace / lowering / XLA compile seconds
    (`PHASE_EVENTS`) and `programs_compiled` (how many XLA programs the call compiled)."""
    from jax import monitoring

    phases = dict.fromkeys(PHASE_EVENTS, 0.0)
    phases["programs_compiled"] = 0
    by_event = {v: k for k, v in PHASE_EVENTS.items()}

    def listener(event, duration_secs, **_):
        key = by_event.get(event)
        if key is not None:
            phases[key] += duration_secs
            phases["programs_compiled"] += key == "xla_compile_s"

    monitoring.register_event_duration_secs_listener(listener)
    try:
        seconds = first_call(fn)
    finally:
        monitoring.unregister_event_duration_listener(listener)
    return seconds, {k: round(v, 4) if isinstance(v, float) else v for k, v in phases.items()}


def timeit(fn: Callable[[], object], repeats: int = 5, warmup: int = 1) -> dict:
    """Median and spread of `fn()` wall time after `warmup` calls; JAX results are blocked on.

    Returns a dict of seconds: `median`, `min`, `max`, `q25`, `q75` and `repeats`.
    """
    for _ in range(warmup):
        _block(fn())
    ts = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        _block(fn())
        ts.append(time.perf_counter() - t0)
    a = np.asarray(ts)
    return {
        "median": float(np.median(a)),
        "min": float(a.min()),
        "max": float(a.max()),
        "q25": float(np.percentile(a, 25)),
        "q75": float(np.percentile(a, 75)),
        "repeats": len(ts),
    }


def first_call(fn: Callable[[], object]) -> float:
    """Seconds of the first call (trace + compile + one run), blocked on."""
    t0 = time.perf_counter()
    _block(fn())
    return time.perf_counter() - t0


@dataclasses.dataclass
class Record:
    """One row of results.json.

    `ours` and `baseline` are in `unit`; `ratio` says how many times better ours is (ours /
    baseline for rates, baseline / ours for times). `target` applies to `target_on` (the
    field it is compared with: "ratio", "ours" or a key of `details`), with `target_op`
    ">=" or "<=". `met` is None when nothing was measured.
    """

    name: str
    ours: float | None
    baseline: float | None
    unit: str
    ratio: float | None = None
    target: float | None = None
    target_on: str = "ratio"
    target_op: str = ">="
    met: bool | None = None
    description: str = ""
    baseline_name: str = ""
    ours_stats: dict | None = None
    baseline_stats: dict | None = None
    details: dict = dataclasses.field(default_factory=dict)
    notes: list[str] = dataclasses.field(default_factory=list)
    lower_is_better: bool = False

    def finish(self) -> Record:
        if self.ratio is None and self.ours is not None and self.baseline:
            self.ratio = (self.baseline / self.ours) if self.lower_is_better else (self.ours / self.baseline)
        if self.target is not None and self.met is None:
            value = {"ratio": self.ratio, "ours": self.ours}.get(self.target_on, self.details.get(self.target_on))
            if value is not None:
                self.met = bool(value >= self.target) if self.target_op == ">=" else bool(value <= self.target)
        return self

    def as_json(self) -> dict:
        return dataclasses.asdict(self.finish())


def not_measured(name: str, unit: str, reason: str, target=None, target_on="ratio") -> Record:
    return Record(name, None, None, unit, target=target, target_on=target_on, met=None,
                  notes=[f"not measured: {reason}"])


def metadata(size: str, device: str) -> dict:
    import jax
    import numpy

    try:
        import scipy

        scipy_version = scipy.__version__
    except ImportError:  # scipy is a dev dependency
        scipy_version = None
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        commit = None
    return {
        "size": size,
        "device_requested": device,
        "devices": [str(d) for d in jax.devices()],
        "jax": jax.__version__,
        "jaxlib": getattr(jax.lib, "__version__", None) if hasattr(jax, "lib") else None,
        "numpy": numpy.__version__,
        "scipy": scipy_version,
        "python": platform.python_version(),
        "cpu_count": cpu_count(),
        "machine": platform.machine(),
        "load_average_start": load_average(),
        "dtype": "float32",
        "git_commit": commit,
        "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def rate_str(x: float | None) -> str:
    if x is None:
        return "-"
    for scale, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if abs(x) >= scale:
            return f"{x / scale:.3g}{suffix}"
    return f"{x:.3g}"
