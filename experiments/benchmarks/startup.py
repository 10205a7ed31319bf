"""Start-up costs (issue 25): `--help`, imports, a fresh parse + FK, and second calls of commands.

Every figure is the wall time of a fresh process (`subprocess`), against a baseline measured in
the same run, interleaved with it: `python -c pass` for `--help`, `python -c "import jax.numpy"`
for the imports and the parse + FK, the first (cold-cache) call for the second calls. A command's first call
saves its largest programs (`fourierjax._saved`), which the second and third calls read.
pymotion's parse + FK of the same clip is measured when an interpreter that imports it is found
(``$PYMOTION_PYTHON``, else this one); never installed here.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from experiments.benchmarks._common import Record, not_measured

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CLIP = "07_01"

#: Parse a bundled clip and run FK, in a fresh process with the compile cache on; prints the
#: phases (seconds) as JSON: JAX's own for the FK call too (`ProgramCount`: trace, lowering,
#: compile or cache load, of which the cache read). The first run saves FK's executable
#: (`fourierjax._saved.saved_executable`); the timed runs load it, with no trace, lowering or
#: compile event (their `fk_s` is the load and the run).
FK_SCRIPT = """
import json, sys, time
t0 = time.perf_counter()
import fourierjax as fj
fj.enable_compile_cache()
from fourierjax import data
from fourierjax._programs import ProgramCount
from fourierjax.io.bvh import read_bvh
from fourierjax.kinematics import joint_positions
t1 = time.perf_counter()
m = read_bvh(data.path(sys.argv[1]))
t2 = time.perf_counter()
sk = m.skeleton()
t3 = time.perf_counter()
with ProgramCount() as count:
    p = joint_positions(sk, m.channels).block_until_ready()
t4 = time.perf_counter()
out = {"import_s": t1 - t0, "parse_s": t2 - t1, "skeleton_s": t3 - t2, "fk_s": t4 - t3}
out.update({f"fk_{k}_s": v for k, v in count.seconds.items()})
print(json.dumps(out))
"""

#: `FK_SCRIPT` leaving by `os._exit` (no interpreter finalization): against `FK_SCRIPT`, what
#: the exit costs (`EXIT_SCRIPT` the same for `import jax.numpy` alone).
FK_EXIT_SCRIPT = FK_SCRIPT + "import os; sys.stdout.flush(); os._exit(0)\n"
EXIT_SCRIPT = "import os, jax.numpy; os._exit(0)"

#: The least a process that runs JAX pays: one op on the CPU backend.
ONE_OP_SCRIPT = "import jax.numpy as jnp; jnp.ones(3).block_until_ready()"

PYMOTION_SCRIPT = """
import sys
from pymotion.io.bvh import BVH
from pymotion.ops.skeleton_np import fk
bvh = BVH()
bvh.load(sys.argv[1])
rots, pos, parents, offsets, _, _ = bvh.get_data()
fk(rots, pos[:, 0, :], offsets, parents)
"""

#: Runs one command under `fourierjax._programs.ProgramCount` (the program counter the tests
#: use through $FOURIERJAX_PROGRAM_LOG) and writes where its seconds and programs went.
PHASES_SCRIPT = """
import json, logging, sys, time
t0 = time.perf_counter()
from fourierjax._programs import ProgramCount
uncacheable = []
class Misses(logging.Handler):
    def emit(self, record):
        msg = record.getMessage()
        if msg.startswith("Not writing persistent cache entry"):
            uncacheable.append(msg.split("'")[1])
logging.getLogger("jax._src.compiler").addHandler(Misses())
logging.getLogger("jax._src.compiler").setLevel(logging.DEBUG)
with ProgramCount() as count:
    from fourierjax.cli import main
    code = main(sys.argv[2:])
out = count.summary()
out["total_s"] = time.perf_counter() - t0
out["uncacheable"] = sorted(set(uncacheable))
with open(sys.argv[1], "w") as f:
    json.dump(out, f)
sys.exit(code)
"""


def _env(cache: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("FOURIERJAX_NO_CACHE", "MPLBACKEND")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [ROOT, os.environ.get("PYTHONPATH")]))
    env["FOURIERJAX_CACHE_DIR"] = cache
    env.setdefault("JAX_PLATFORMS", "cpu")
    return env


def _wall(cmd: list[str], env: dict, cwd: str) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=900)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[-6:])} failed ({proc.returncode}): {proc.stderr[-800:]}")
    return dt, proc.stdout


def _interleaved(cmds: dict[str, list[str]], repeats: int, env: dict, cwd: str) -> dict[str, list[float]]:
    """Wall seconds of each command, `repeats` rounds, one of each per round (same load)."""
    out: dict[str, list[float]] = {k: [] for k in cmds}
    for _ in range(repeats):
        for k, cmd in cmds.items():
            out[k].append(_wall(cmd, env, cwd)[0])
    return out


def _stats(ts: list[float]) -> dict:
    return {"median": statistics.median(ts), "min": min(ts), "max": max(ts), "repeats": len(ts)}


def _vs(name, ours, base, target_extra, description, baseline_name, **details) -> Record:
    mo, mb = statistics.median(ours), statistics.median(base)
    return Record(name, mo, mb, "s", target=target_extra, target_on="extra_s", target_op="<=",
                  lower_is_better=True, description=description, baseline_name=baseline_name,
                  ours_stats=_stats(ours), baseline_stats=_stats(base),
                  details={"extra_s": round(mo - mb, 4), **details})


def _pymotion_python(env: dict, cwd: str) -> str | None:
    for py in filter(None, [os.environ.get("PYMOTION_PYTHON"), sys.executable]):
        try:
            ok = subprocess.run([py, "-c", "import pymotion.io.bvh"], env=env, cwd=cwd,
                                capture_output=True, timeout=120).returncode == 0
        except (OSError, subprocess.SubprocessError):
            ok = False
        if ok:
            return py
    return None


def _commands(py: str) -> dict[str, tuple[list[str], list[list[str]]]]:
    """name -> (the command, commands that make its inputs first)."""
    cli = [py, "-m", "fourierjax"]
    fit = [*cli, "fit", CLIP, "--harmonics", "3", "--out", "m.npz"]
    fit_run = [*cli, "fit", "09_01", "--harmonics", "3", "--out", "r.npz"]
    return {
        "fit": (fit, []),
        "synth": ([*cli, "synth", "m.npz", "--seconds", "4", "--out", "s.bvh"], [fit]),
        "transition": ([*cli, "transition", "m.npz", "r.npz", "--seconds", "4", "--start", "1",
                        "--duration", "1.5", "--out", "t.bvh"], [fit, fit_run]),
        "stance": ([*cli, "stance", "--shape-set", "posture", "--out", "p.bvh"], []),
    }


def _saved_files(env: dict) -> list[str]:
    """The saved programs (`fourierjax._saved`) in the benchmark's cache folder so far."""
    folder = os.path.join(env["FOURIERJAX_CACHE_DIR"], "exported")
    return sorted(os.listdir(folder)) if os.path.isdir(folder) else []


def _phases(py: str, cmd: list[str], env: dict, cwd: str) -> dict:
    """Where a warm call's seconds go: JAX's trace / lowering / compile-or-load / cache-read
    totals, and how many programs (compiled or read from the cache) and traces it made."""
    path = os.path.join(cwd, "phases.json")
    _wall([py, "-c", PHASES_SCRIPT, path, *cmd[3:]], env, cwd)
    with open(path) as f:
        ev = json.load(f)
    out = {f"{k}_s": round(v, 3) for k, v in ev["seconds"].items()}
    out["programs"] = ev["programs"]
    out["traces"] = ev["traces"]
    out["programs_where"] = ev["where"]
    out["programs_not_cacheable"] = ev["uncacheable"]
    out["total_in_process_s"] = round(ev["total_s"], 3)
    out["seconds_by_name_top"] = dict(list(ev.get("seconds_by_name", {}).items())[:8])
    return out


def run(size: str) -> list[Record]:
    py = sys.executable
    small = size != "full"
    # $FOURIERJAX_BENCH_REPEATS: fewer rounds on a crowded machine (default 7).
    repeats = 1 if small else int(os.environ.get("FOURIERJAX_BENCH_REPEATS", "7"))
    records = []
    with tempfile.TemporaryDirectory(prefix="fourierjax-startup-") as tmp:
        env = _env(os.path.join(tmp, "cache"))
        t = _interleaved({
            "pass": [py, "-c", "pass"],
            "help": [py, "-m", "fourierjax", "--help"],
            "jnp": [py, "-c", "import jax.numpy"],
            "fj": [py, "-c", "import fourierjax"],
            "fj_fk": [py, "-c", "import fourierjax.io.bvh, fourierjax.kinematics"],
        }, repeats, env, tmp)
        records.append(_vs("startup_help", t["help"], t["pass"], 0.15,
                           "`fourierjax --help` (python -m) against `python -c pass`", "python -c pass"))
        records.append(_vs(
            "startup_import", t["fj"], t["jnp"], 0.15, "`import fourierjax` against `import jax.numpy`",
            "import jax.numpy",
            import_fk_modules_s=round(statistics.median(t["fj_fk"]), 4),
            import_fk_modules_extra_s=round(statistics.median(t["fj_fk"]) - statistics.median(t["jnp"]), 4),
            note="import fourierjax loads nothing (PEP 562); import_fk_modules_* is "
                 "`import fourierjax.io.bvh, fourierjax.kinematics` (equinox included)"))
        if small:
            for name in ("startup_parse_fk", *(f"startup_second_{c}" for c in _commands(py))):
                records.append(not_measured(name, "s", "small size (CI): full size only"))
            return records

        # A fresh process that parses a clip and runs FK, with a warm cache.
        fk_cmd = [py, "-c", FK_SCRIPT, CLIP]
        _wall(fk_cmd, env, tmp)  # fills the cache
        phases = []
        fk_t, jnp_t, op_t, fk_exit_t, jnp_exit_t = [], [], [], [], []
        for _ in range(repeats):
            dt, out = _wall(fk_cmd, env, tmp)
            fk_t.append(dt)
            phases.append(json.loads(out))
            jnp_t.append(_wall([py, "-c", "import jax.numpy"], env, tmp)[0])
            op_t.append(_wall([py, "-c", ONE_OP_SCRIPT], env, tmp)[0])
            fk_exit_t.append(_wall([py, "-c", FK_EXIT_SCRIPT, CLIP], env, tmp)[0])
            jnp_exit_t.append(_wall([py, "-c", EXIT_SCRIPT], env, tmp)[0])
        details = {f"median_{k}": round(statistics.median(p.get(k, 0.0) for p in phases), 4)
                   for k in sorted({k for p in phases for k in p})}
        # The interpreter's exit (finalizing modules and a few full garbage collections over
        # every object JAX and fourierjax made): in the script and in the baseline.
        details["exit_s"] = round(statistics.median(fk_t) - statistics.median(fk_exit_t), 4)
        details["baseline_exit_s"] = round(statistics.median(jnp_t) - statistics.median(jnp_exit_t), 4)
        # What any process pays once JAX runs one op: the CPU backend's start (the exit's
        # finalization of JAX, 0.25-0.35 s on 2 cores, is in both baselines).
        details["one_jax_op_extra_s"] = round(statistics.median(op_t) - statistics.median(jnp_t), 4)
        details["extra_over_one_jax_op_s"] = round(statistics.median(fk_t) - statistics.median(op_t), 4)
        from fourierjax import data

        clip_path = str(data.path(CLIP))
        pm_py = _pymotion_python(env, tmp)
        notes = []
        if pm_py is None:
            notes.append("pymotion not importable (set PYMOTION_PYTHON to a private venv's python): skipped")
        else:
            pm = [_wall([pm_py, "-c", PYMOTION_SCRIPT, clip_path], env, tmp)[0] for _ in range(repeats)]
            details["pymotion_parse_fk_s"] = round(statistics.median(pm), 4)
            details["ours_over_pymotion"] = round(statistics.median(fk_t) / statistics.median(pm), 2)
            details["import_fourierjax_over_pymotion"] = round(statistics.median(t["fj_fk"]) / statistics.median(pm), 2)
        rec = _vs("startup_parse_fk", fk_t, jnp_t, 0.3,
                  f"fresh process: parse {CLIP} + FK, warm cache, against `import jax.numpy`",
                  "import jax.numpy", **details)
        rec.notes += notes
        records.append(rec)

        # Second calls of commands (cache warm from the first).
        work = os.path.join(tmp, "work")
        os.makedirs(work)
        for name, (cmd, prepare) in _commands(py).items():
            for p in prepare:
                _wall(p, env, work)
            cold = _wall(cmd, env, work)[0]
            # The second call reads the programs the first saved (`fourierjax._saved`); the
            # third is reported too (it should equal the second: nothing left to save).
            warm = [_wall(cmd, env, work)[0] for _ in range(max(2, min(3, repeats)))]
            details = _phases(py, cmd, env, work)
            details.update(second_call_s=round(warm[0], 3), third_call_s=round(warm[1], 3),
                           saved_programs=sorted(n.split("-")[0] for n in _saved_files(env)))
            rec = Record(f"startup_second_{name}", statistics.median(warm), cold, "s", target=3.0,
                         target_on="ours", target_op="<=", lower_is_better=True,
                         description=f"second call of `fourierjax {' '.join(cmd[3:])}` (warm cache)",
                         baseline_name="first call (cold cache)", ours_stats=_stats(warm),
                         details=details)
            records.append(rec)
    return records
