"""Case generators and runners of the fuzz suite; each runner returns a `Report` of counts.

Small seeded runs are tests (`tests/fuzz/test_fuzz.py`); `make fuzz` runs the large ones
(`python -m tests.fuzz`). Every case is generated from `numpy.random.default_rng(seed)`, so a
finding is reproduced by its suite, seed and case number.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import pathlib
import signal
import struct
import tempfile
import time
import zipfile

import numpy as np

from fourierjax import data
from fourierjax.errors import UserError


@dataclasses.dataclass
class Report:
    """Counts of one suite: cases run, accepted, refused with a typed error, and the others."""

    suite: str
    cases: int = 0
    accepted: int = 0
    typed: int = 0
    untyped: int = 0
    slow: int = 0  # CLI cases stopped by the per-case time limit (not failures, but reported)
    examples: list = dataclasses.field(default_factory=list)  # (case, what) of untyped ones
    seconds: float = 0.0

    def add_untyped(self, case, what) -> None:
        self.untyped += 1
        if len(self.examples) < 10:
            self.examples.append((case, what))

    def line(self) -> str:
        slow = f", {self.slow} stopped at the time limit" if self.slow else ""
        return (f"{self.suite}: {self.cases} cases, {self.accepted} accepted, {self.typed} typed "
                f"errors, {self.untyped} untyped exceptions/tracebacks{slow} ({self.seconds:.1f} s)")


# -- BVH ---------------------------------------------------------------------------------

_TOKENS = ("{", "}", "ROOT", "JOINT", "End Site", "OFFSET", "CHANNELS", "MOTION", "Frames:",
           "Frame Time:", "HIERARCHY", "nan", "inf", "-inf", "1e308", "-1e308", "1e6", "1e-320",
           "0", "-0", "99999999999999999999", "3", "6", "Xrotation", "Yposition", "@@", "1_0",
           "\u0661\u0662", "\x00", "\t", "\r", "\r\n", "\n\n", "-", ".", "+", "e5", "0x10",
           "Frames: 1000000000", "Frames: 0", "Frame Time: 0", "Frame Time: 1e300",
           "CHANNELS 999999999", "CHANNELS -1", " " * 50)


def bvh_base_texts() -> list[str]:
    """Two bundled clips cut to 12 frames (a CMU hierarchy) and a two-joint file."""
    out = []
    for name in ("07_01", "02_01"):
        text = data.path(name).read_text() if hasattr(data.path(name), "read_text") else \
            pathlib.Path(data.path(name)).read_text()
        head, motion = text.split("MOTION", 1)
        lines = motion.strip().split("\n")
        rows = [ln for ln in lines[2:] if ln.strip()][:12]
        out.append(head + "MOTION\n" + f"Frames: {len(rows)}\n" + lines[1].strip() + "\n"
                   + "\n".join(rows) + "\n")
    out.append("HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 6 Xposition Yposition "
               "Zposition Zrotation Xrotation Yrotation\n\tJOINT Chest\n\t{\n\t\tOFFSET 0 5 0\n"
               "\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n\t\tEnd Site\n\t\t{\n\t\t\tOFFSET"
               " 0 3 0\n\t\t}\n\t}\n}\nMOTION\nFrames: 2\nFrame Time: 0.033333\n"
               "0 1 2 3 4 5 6 7 8\n0 1 2 3 4 5 6 7 8\n")
    return out


def mutate_text(rng, text: str) -> str:
    """One to four random edits: bytes, tokens, lines, numbers, truncation."""
    for _ in range(int(rng.integers(1, 5))):
        n = len(text)
        op = int(rng.integers(0, 11))
        i = int(rng.integers(0, max(n, 1)))
        if op == 0:  # delete a span
            text = text[:i] + text[i + int(rng.integers(1, 40)):]
        elif op == 1:  # insert a token
            text = text[:i] + str(rng.choice(_TOKENS)) + text[i:]
        elif op == 2:  # replace a character with a random one (ASCII, control or not)
            text = text[:i] + chr(int(rng.integers(0, 128 if rng.random() < 0.8 else 0x3000))) \
                + text[i + 1:]
        elif op == 3:  # truncate
            text = text[:i]
        else:
            lines = text.split("\n")
            k = int(rng.integers(0, len(lines)))
            if op == 4:  # duplicate a line
                lines.insert(k, lines[k])
            elif op == 5:  # delete a line
                del lines[k]
            elif op == 6:  # swap two lines
                j = int(rng.integers(0, len(lines)))
                lines[k], lines[j] = lines[j], lines[k]
            elif op == 7:  # replace one word of a line with a token
                words = lines[k].split(" ")
                words[int(rng.integers(0, len(words)))] = str(rng.choice(_TOKENS))
                lines[k] = " ".join(words)
            elif op == 8:  # a number made huge, tiny, negative or odd
                words = lines[k].split()
                if words:
                    w = int(rng.integers(0, len(words)))
                    words[w] = str(rng.choice(["1e308", "-1e400", "nan", "1e7", "-0.0", "1e-5",
                                               "12345678901234567890.5", "5e-324", "1.5.2"]))
                    lines[k] = " ".join(words)
            elif op == 9:  # the frame count changed
                for j, ln in enumerate(lines):
                    if ln.startswith("Frames:"):
                        lines[j] = f"Frames: {int(rng.choice([0, 1, 11, 13, 10**9, 10**12]))}"
            else:  # line endings
                return ("\r\n" if rng.random() < 0.5 else "\r").join(lines)
            text = "\n".join(lines)
    return text


def run_bvh(num_cases: int, seed: int = 0, *, file_every: int = 10) -> Report:
    """Mutated BVH texts through `parse_bvh` (every `file_every`-th as bytes through
    `read_bvh`, with raw byte damage): only `BVHError` may come out, and an accepted file is a
    `Motion` of finite values within +-1e6."""
    from fourierjax.io.bvh import BVHError, parse_bvh, read_bvh

    rep, rng, bases = Report("bvh"), np.random.default_rng(seed), bvh_base_texts()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "case.bvh")
        for case in range(num_cases):
            text = mutate_text(rng, bases[case % len(bases)])
            rep.cases += 1
            try:
                if case % file_every == file_every - 1:
                    raw = bytearray(text.encode("utf-8", "surrogatepass"))
                    for _ in range(int(rng.integers(0, 3))):
                        if raw:
                            raw[int(rng.integers(0, len(raw)))] = int(rng.integers(0, 256))
                    with open(path, "wb") as f:
                        f.write(bytes(raw))
                    m = read_bvh(path)
                else:
                    m = parse_bvh(text)
                ok = (np.isfinite(m.channels).all() and np.abs(m.channels).max() <= 1e6
                      and m.channels.shape == (m.num_frames, m.topology.num_channels))
                if not ok:
                    rep.add_untyped((seed, case), "accepted a motion with bad values")
                else:
                    rep.accepted += 1
            except BVHError:
                rep.typed += 1
            except Exception as err:  # noqa: BLE001 - counting what escapes is the point
                rep.add_untyped((seed, case), f"{type(err).__name__}: {err}"[:200])
    rep.seconds = time.perf_counter() - t0
    return rep


# -- model files -------------------------------------------------------------------------


def model_file_bytes(tmp: str) -> bytes:
    """A valid model file with a skeleton (07_01), written by `save_model`."""
    from fourierjax.features import channel_names_for
    from fourierjax.fourier import FourierModel
    from fourierjax.io import model_io

    motion = data.load("07_01")[:3]
    names = channel_names_for(motion.topology, "euler")
    rng = np.random.default_rng(0)
    C, N = len(names), 2
    model = FourierModel(rng.normal(size=C) * 0.1, rng.uniform(0, 0.1, (C, N)),
                         rng.uniform(-np.pi, np.pi, (C, N)), np.asarray(6.0), "euler", names)
    path = os.path.join(tmp, "base.npz")
    model_io.save_model(path, model, motion=motion)
    return pathlib.Path(path).read_bytes()


def _rezip(raw: bytes, edit) -> bytes:
    """The archive with its members edited by `edit(name, bytes) -> bytes`."""
    src = zipfile.ZipFile(io.BytesIO(raw))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as dst:
        for info in src.infolist():
            dst.writestr(info.filename, edit(info.filename, src.read(info.filename)))
    return buf.getvalue()


def _npy_header_edit(rng, member: bytes) -> bytes:
    """A `.npy` member whose header declares another shape, dtype or order, or is junk."""
    if member[:6] != b"\x93NUMPY" or member[6] != 1:
        return member
    size = struct.unpack("<H", member[8:10])[0]
    header, body = member[10:10 + size].decode("latin-1"), member[10 + size:]
    choice = int(rng.integers(0, 6))
    if choice == 0:
        header = header.replace("'shape': (", f"'shape': ({10**12}, ", 1)
    elif choice == 1:
        header = header.replace("<f8", str(rng.choice(["<c16", "|O", "<U5", "<i8", "|b1", "<f2"])))
    elif choice == 2:
        header = header.replace("'shape': (", "'shape': (-1, ", 1)
    elif choice == 3:
        header = header.replace("False", "True")
    elif choice == 4:
        header = header.replace("'shape': (", f"'shape': ({'9' * 5000}, ", 1)
    else:
        header = "{" * 100_000 + "\n"
    raw = header.encode("latin-1")
    # Version 2 headers have a 4-byte length (for headers over 64 kB).
    return b"\x93NUMPY\x02\x00" + struct.pack("<I", len(raw)) + raw + body


def _json_edit(rng, header_member: bytes) -> bytes:
    """The header member (a 0-d unicode `.npy`) with its JSON changed."""
    arr = np.load(io.BytesIO(header_member), allow_pickle=False)
    try:
        head = json.loads(str(arr))
    except ValueError:
        return header_member
    key = str(rng.choice(sorted(head)))
    choice = int(rng.integers(0, 9))
    values = [None, -1, 10**30, "expmap", "euler", [], {}, 1e308, "x" * 5000,
              True, [[1, 2], 3], -0.0]
    if choice == 0:
        del head[key]
    elif choice == 1:
        head[key] = values[int(rng.integers(0, len(values)))]
    elif choice == 2:
        text = "[" * 100_000 + "]" * 100_000
        return _npy_str(text)
    elif choice == 3:
        return _npy_str(json.dumps(head).replace("1", "9" * 5000, 1))
    elif choice == 4 and isinstance(head.get("channel_names"), list) and head["channel_names"]:
        k = int(rng.integers(0, len(head["channel_names"])))
        head["channel_names"][k] = str(rng.choice(["a.expmap0", "", "root.vx", "x" * 300]))
    elif choice == 5 and isinstance(head.get("skeleton"), dict):
        sk = head["skeleton"]
        sub = str(rng.choice(sorted(sk)))
        sk[sub] = values[int(rng.integers(0, len(values)))]
    elif choice == 6:
        head["representation"] = "expmap" if head.get("representation") == "euler" else "euler"
    elif choice == 7:
        head["version"] = int(rng.choice([0, 2, 10**9]))
    else:
        return header_member[: int(rng.integers(0, len(header_member)))]
    return _npy_str(json.dumps(head))


def _npy_str(text: str) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.array(text))
    return buf.getvalue()


def _array_edit(rng, member: bytes) -> bytes:
    """A float64 `.npy` member with some values replaced (NaN, negative, huge, subnormal)."""
    try:
        a = np.load(io.BytesIO(member), allow_pickle=False)
    except Exception:  # noqa: BLE001 - an earlier edit broke it; keep the broken bytes
        return member
    if a.dtype.kind != "f":
        return member
    a = a.copy()
    flat = a.reshape(-1)
    if flat.size:
        k = int(rng.integers(0, flat.size))
        flat[k] = float(rng.choice([np.nan, np.inf, -1.0, 1e308, 5e-324, -5.0, 0.0, 1e7]))
    if rng.random() < 0.2:
        a = a.reshape(-1)[: max(0, a.size - 1)]
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def mutate_model(rng, raw: bytes) -> bytes:
    """Raw byte damage (flips, truncation, zip flags) or a structured edit of one member."""
    op = int(rng.integers(0, 6))
    if op == 0:
        b = bytearray(raw)
        for _ in range(int(rng.integers(1, 8))):
            b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
        return bytes(b)
    if op == 1:
        return raw[: int(rng.integers(0, len(raw)))]
    if op == 2:  # zip header fields: version, flags (encrypted), compression method
        b = bytearray(raw)
        starts = [i for i in range(len(b) - 4) if b[i:i + 4] in (b"PK\x03\x04", b"PK\x01\x02")]
        if starts:
            s = starts[int(rng.integers(0, len(starts)))]
            field = int(rng.choice([4, 6, 8, 10]))
            b[s + field] = int(rng.choice([1, 99, 200, 255]))
        return bytes(b)
    if op == 3:
        return _rezip(raw, lambda n, m: _json_edit(rng, m) if n == "header.npy" else m)
    names = zipfile.ZipFile(io.BytesIO(raw)).namelist()
    target = str(rng.choice([n for n in names if n != "header.npy"]))
    if op == 4:
        return _rezip(raw, lambda n, m: _npy_header_edit(rng, m) if n == target else m)
    return _rezip(raw, lambda n, m: _array_edit(rng, m) if n == target else m)


def run_models(num_cases: int, seed: int = 0) -> Report:
    """Mutated model files through `load_model`: only `UserError` subclasses may come out;
    an accepted model has finite values, amplitudes >= 0 and omega > 0."""
    from fourierjax.io import model_io

    rep, rng = Report("model files"), np.random.default_rng(seed)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        base = model_file_bytes(tmp)
        path = os.path.join(tmp, "case.npz")
        for case in range(num_cases):
            rep.cases += 1
            try:
                raw = mutate_model(rng, base)
            except Exception as err:  # noqa: BLE001 - the generator's own failure
                rep.add_untyped((seed, case), f"generator: {type(err).__name__}: {err}"[:200])
                continue
            with open(path, "wb") as f:
                f.write(raw)
            try:
                mf = model_io.load_model(path)
                m = mf.model
                ok = (all(np.isfinite(np.asarray(getattr(m, k))).all()
                          for k in ("offset", "amplitude", "phase", "omega"))
                      and (np.asarray(m.amplitude) >= 0).all() and float(m.omega) > 0)
                if not ok:
                    rep.add_untyped((seed, case), "accepted a model with bad values")
                else:
                    rep.accepted += 1
            except UserError:
                rep.typed += 1
            except Exception as err:  # noqa: BLE001
                rep.add_untyped((seed, case), f"{type(err).__name__}: {err}"[:200])
    rep.seconds = time.perf_counter() - t0
    return rep


# -- command line ------------------------------------------------------------------------

_NUMBERS = ("0", "1", "2", "3", "-1", "0.5", "1e308", "-1e308", "nan", "inf", "-inf", "1e9",
            "1000000000", "abc", "", "1e-320", "0x10", "7")
#: Commands fuzzed. `demo` is left out: with valid arguments it renders the whole demo
#: (minutes), which a fuzz case cannot afford.
CLI_COMMANDS = ("info", "positions", "characteristic", "interpolate", "transition", "fit",
                "synth", "plot", "stance")


class _Slow(BaseException):
    """Raised by the per-case alarm (a BaseException: no `except Exception` swallows it)."""


def cli_files(tmp: str) -> dict[str, list[str]]:
    """Files the CLI cases name: good, damaged and missing inputs, and output paths."""
    t = pathlib.Path(tmp)
    bvh = str(data.path("07_01"))
    model = t / "m.npz"
    model.write_bytes(model_file_bytes(tmp))
    (t / "bad.bvh").write_text(mutate_text(np.random.default_rng(1), bvh_base_texts()[0]))
    (t / "latin1.txt").write_bytes(b"\xff\xfe caf\xe9 \x00")
    np.save(t / "bare.npy", np.arange(3.0))
    (t / "empty.npz").write_bytes(b"")
    (t / "dir").mkdir()
    char = pathlib.Path(__file__).parents[1] / "data" / "characteristic_v1.npz"
    inputs = [bvh, str(model), str(char), str(t / "bad.bvh"), str(t / "latin1.txt"),
              str(t / "bare.npy"), str(t / "empty.npz"), str(t / "dir"), str(t / "missing.bvh"),
              ""]
    outs = [str(t / n) for n in ("o.bvh", "o.npz", "o.txt", "o.png", "o.json", "dir",
                                 "nodir/o.bvh")] + [""]
    return {"in": inputs, "out": outs, "tmp": tmp}


def cli_argsets(rng, files, num_cases: int) -> list[list[str]]:
    """Argument lists built from the parsers' own options, with values drawn from pools of
    numbers, choices, input files and output paths."""
    from fourierjax.cli import _build_parser

    parser = _build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    out = []
    for _ in range(num_cases):
        name = str(rng.choice(CLI_COMMANDS))
        argv = [name]
        # Each value is a plausible one with probability `sane` (so that cases reach the
        # commands' work, not only their argument checks), else drawn from the odd pools.
        sane = float(rng.choice([0.95, 0.8, 0.5]))
        for action in sub.choices[name]._actions:
            if action.dest == "help":
                continue
            positional = not action.option_strings
            if not positional and not action.required and rng.random() < 0.5:
                continue
            if action.nargs == 0:
                argv.append(action.option_strings[0])
                continue
            good = _good_value(name, action.dest, files)
            if good is not None and rng.random() < sane:
                value = good
            elif action.choices:
                value = (str(rng.choice(list(action.choices))) if rng.random() < 0.8
                         else str(rng.choice(_NUMBERS)))
            elif action.dest in ("out",):
                value = str(rng.choice(files["out"]))
            elif action.dest in ("file", "files", "a", "b", "model", "input", "shape_set"):
                value = str(rng.choice(files["in"]))
            elif action.dest == "add":
                value = f"{rng.choice(files['in'])}={rng.choice(_NUMBERS)}"
            elif action.dest == "kind":
                value = str(rng.choice(["stick", "spectrum", "fit", "hip", "curves", "x", ""]))
            elif action.dest in ("joint", "object", "target", "clips"):
                value = str(rng.choice(["Hips", "LeftFoot", "", "x", "1", "01_01"]))
            elif action.dest in ("seconds", "fps", "duration") and rng.random() < 0.5:
                value = str(rng.choice(["0.5", "1", "1e308", "1e6", "0"]))
            else:
                value = str(rng.choice(_NUMBERS))
            if positional:
                argv.append(value)
            elif value.startswith("-"):  # "--s -inf" would read "-inf" as an option
                argv.append(f"{action.option_strings[0]}={value}")
            else:
                argv += [action.option_strings[0], value]
        out.append(argv)
    return out


_GOOD_OUT = {"fit": "o.npz", "characteristic": "o.npz", "plot": "o.png", "positions": "o.npy",
             "stance": "o.bvh", "synth": "o.bvh", "interpolate": "o.bvh", "transition": "o.bvh"}
_GOOD_NUMBER = {"harmonics": "3", "seconds": "1", "fps": "30", "s": "0.5", "noise": "1",
                "noise_harmonics": "2", "seed": "0", "start": "0.2", "duration": "0.3",
                "frame": "0", "phase": "0.5", "max_frames": "10", "intensity": "0.5",
                "height": "1.7", "start_frame": "0", "step": "1", "speed": "1", "gait": "0.5",
                "jump": "1"}


def _good_value(command: str, dest: str, files) -> str | None:
    """A value the command accepts for `dest`, or None where there is no simple one."""
    if dest == "out":
        return os.path.join(files["tmp"], _GOOD_OUT.get(command, "o.txt"))
    if dest == "model":
        return files["in"][1]
    if dest in ("file", "files", "a", "b", "input"):
        return files["in"][0]
    if dest == "add":
        return f"{files['in'][2]}=0.5"
    if dest == "kind":
        return "stick"
    return _GOOD_NUMBER.get(dest)


def run_cli(num_cases: int, seed: int = 0, *, case_seconds: int = 60,
            verbose: bool = False) -> Report:
    """Argument sets through `fourierjax.cli.main` in this process: an exception escaping
    `main` (what the script would print as a traceback), "Traceback" in the output, or an exit
    code other than 0, 2 (errors) and argparse's usage exit is counted untyped. A case still
    running after `case_seconds` is stopped and counted `slow`."""
    import matplotlib

    matplotlib.use("Agg")
    from fourierjax.cli import main

    rep, rng = Report("cli"), np.random.default_rng(seed)
    t0 = time.perf_counter()
    previous = signal.signal(signal.SIGALRM, _raise_slow)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            files = cli_files(tmp)
            for case, argv in enumerate(cli_argsets(rng, files, num_cases)):
                rep.cases += 1
                err_out, std_out = io.StringIO(), io.StringIO()
                code, escaped = None, None
                signal.alarm(case_seconds)
                try:
                    with contextlib.redirect_stderr(err_out), contextlib.redirect_stdout(std_out):
                        code = main(argv)
                except SystemExit as e:
                    code = e.code
                except _Slow:
                    rep.slow += 1
                    continue
                except Exception as e:  # noqa: BLE001
                    escaped = f"{type(e).__name__}: {e}"[:200]
                finally:
                    signal.alarm(0)
                    import matplotlib.pyplot as plt

                    plt.close("all")
                text = err_out.getvalue() + std_out.getvalue()
                if verbose:
                    print(code, argv, text.strip().splitlines()[-1:] if text.strip() else "")
                if escaped or "Traceback" in text or code not in (0, 2, None):
                    rep.add_untyped(argv, escaped or f"exit {code}: {text[-200:]}")
                elif code == 0 or code is None:
                    rep.accepted += 1
                else:
                    rep.typed += 1
    finally:
        signal.signal(signal.SIGALRM, previous)
    rep.seconds = time.perf_counter() - t0
    return rep


def _raise_slow(signum, frame):
    raise _Slow


# -- gradients at singular points ---------------------------------------------------------


def gradient_probes():
    """(name, scalar function, point) at the singular points of public differentiable
    functions: zero vectors and quaternions, the zero-norm threshold, gimbal lock, the
    identity, antipodal quaternions, zero amplitude, square roots at 0."""
    import jax.numpy as jnp

    from fourierjax import _math, fourier, rotations

    f32 = np.float32
    thr = rotations.zero_norm_threshold("float32")
    tiny_vecs = [np.zeros(3, f32), np.array([thr, 0, 0], f32), np.array([thr * 0.5, 0, 0], f32),
                 np.array([1e-30, 0, 0], f32), np.array([1e-6, 1e-6, 0], f32),
                 np.array([np.pi, 0, 0], f32), np.array([0, 2 * np.pi, 0], f32)]
    quats = [np.array([1, 0, 0, 0], f32), np.array([-1, 0, 0, 0], f32), np.zeros(4, f32),
             np.array([0, 1, 0, 0], f32), np.array([thr, 0, 0, 0], f32),
             np.array([thr * 0.5, 0, 0, 0], f32), np.array([1e-15, 0, 0, 0], f32),
             np.array([0, 1e-13, 0, 0], f32), np.array([0.5, 0.5, 0.5, 0.5], f32)]
    gimbal = [np.array([0.3, np.pi / 2, 0.1], f32), np.array([0.0, -np.pi / 2, 0.0], f32),
              np.zeros(3, f32), np.array([np.pi, 0, np.pi], f32)]
    probes = []
    for i, v in enumerate(tiny_vecs):
        probes += [(f"quat_from_expmap[{i}]", lambda x: rotations.quat_from_expmap(x).sum(), v),
                   (f"matrix_from_expmap[{i}]", lambda x: rotations.matrix_from_expmap(x).sum(), v)]
        if np.linalg.norm(v) > thr or not v.any():
            probes.append((f"quat_from_axis_angle[{i}]",
                           lambda x: rotations.quat_from_axis_angle(x, jnp.float32(0.7)).sum(), v))
    for i, q in enumerate(quats):
        probes += [(f"expmap_from_quat[{i}]", lambda x: rotations.expmap_from_quat(x).sum(), q),
                   (f"quat_normalize[{i}]", lambda x: rotations.quat_normalize(x).sum(), q),
                   (f"matrix_from_quat[{i}]", lambda x: rotations.matrix_from_quat(x).sum(), q),
                   (f"quat_power[{i}]",
                    lambda x: rotations.quat_power(x, jnp.float32(0.5)).sum(), q)]
    for i, a in enumerate(gimbal):
        for order in ("ZYX", "XYZ", "ZXZ"):
            m = np.asarray(rotations.matrix_from_euler(jnp.asarray(a), order))
            probes.append((f"euler_from_matrix[{order},{i}]",
                           lambda x, o=order: rotations.euler_from_matrix(x, o).sum(), m))
            probes.append((f"quat_from_matrix[{order},{i}]",
                           lambda x: rotations.quat_from_matrix(x).sum(), m))
    probes += [("safe_sqrt(0)", lambda x: _math.safe_sqrt(x).sum(), np.zeros(3, f32)),
               ("wrap_angle(pi)", lambda x: _math.wrap_angle(x).sum(),
                np.array([np.pi, -np.pi, 0], f32))]
    zero = fourier.FourierModel(jnp.zeros(2), jnp.zeros((2, 3)), jnp.zeros((2, 3)),
                                jnp.asarray(6.0))
    probes.append(("synthesize(zero amplitude)",
                   lambda x: fourier.synthesize(fourier.FourierModel(
                       zero.offset, x, zero.phase, zero.omega), jnp.linspace(0, 1, 5)).sum(),
                   np.zeros((2, 3), f32)))
    return probes


def run_gradients() -> Report:
    """`jax.grad` at every probe: the value and the gradient must be finite."""
    import jax
    import jax.numpy as jnp

    rep = Report("gradients")
    t0 = time.perf_counter()
    for name, fn, x in gradient_probes():
        rep.cases += 1
        try:
            value, grad = jax.value_and_grad(fn)(jnp.asarray(x))
        except UserError:
            rep.typed += 1
            continue
        except Exception as err:  # noqa: BLE001
            rep.add_untyped(name, f"{type(err).__name__}: {err}"[:200])
            continue
        if np.isfinite(np.asarray(value)) and np.isfinite(np.asarray(grad)).all():
            rep.accepted += 1
        else:
            rep.add_untyped(name, f"value {np.asarray(value)}, gradient {np.asarray(grad).ravel()}")
    rep.seconds = time.perf_counter() - t0
    return rep
