"""`fourierjax characteristic`: the Fourier characteristics A − B of two gaits (Unuma 1995, eq. 7).

Characteristic file format ``fourierjax.fourier_characteristic``, version 1: an uncompressed
``.npz`` (read with ``allow_pickle=False``) holding

* ``header``: a 0-d unicode array with one JSON object::

      {"format": "fourierjax.fourier_characteristic", "version": 1,
       "representation": "euler" | "expmap", "channel_names": [...C names...],
       "num_channels": C, "num_harmonics": N, "phase_convention": "sine",
       "a": "<source of A>", "b": "<source of B>", "alignment": "..."}

* ``offset [C]`` (A0_A − A0_B), ``amplitude [C, N]`` (A_A − A_B, may be negative),
  ``phase [C, N]`` (φ_A − φ_B wrapped to (−π, π]), ``phasor [C, N, 2]``
  (c_A − c_B with c = (A cos φ, A sin φ)), ``log_omega []`` (log ω_A/ω_B), float64,

i.e. the fields of `fourierjax.style.Characteristic`. Apply it with
`fourierjax.style.superpose(base, [characteristic], [weight])`.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import zipfile

import numpy as np

HELP = "Fourier characteristics A - B of two gaits (Unuma eq. 7), e.g. briskness = brisk - walk."

FORMAT_NAME = "fourierjax.fourier_characteristic"
FORMAT_VERSION = 1
_ARRAYS = ("offset", "amplitude", "phase", "phasor", "log_omega")


def save_characteristic(path, char, *, a: str = "", b: str = "", alignment: str = "none") -> None:
    """Write one (unstacked) `fourierjax.style.Characteristic` to `path` (format above)."""
    from fourierjax.errors import UserError

    amp = np.asarray(char.amplitude, np.float64)
    if amp.ndim != 2:
        raise UserError(f"save_characteristic: one characteristic expected, got {amp.shape}")
    header = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "representation": char.representation,
        "channel_names": list(char.channel_names),
        "num_channels": int(amp.shape[0]),
        "num_harmonics": int(amp.shape[1]),
        "phase_convention": "sine",
        "a": a,
        "b": b,
        "alignment": alignment,
    }
    arrays = {k: np.asarray(getattr(char, k), np.float64) for k in _ARRAYS}
    arrays["header"] = np.array(json.dumps(header))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    with open(path, "wb") as f:
        f.write(buf.getvalue())


def load_characteristic(path):
    """Read a characteristic file: returns `(Characteristic, header dict)`.

    Raises `fourierjax.errors.UserError` (one line naming the path) for anything that is not a
    readable characteristic file of a version this fourierjax knows.
    """
    from fourierjax.errors import UserError
    from fourierjax.style import Characteristic

    path = os.fspath(path)
    if not os.path.exists(path):
        raise UserError(f"{path}: no such file")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        header = json.loads(str(data["header"]))
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as err:
        raise UserError(f"{path}: not a fourierjax characteristic file: {err}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        got = header.get("format") if isinstance(header, dict) else None
        raise UserError(f"{path}: format is {got!r}, expected {FORMAT_NAME!r}")
    version = header.get("version")
    if not isinstance(version, int) or not 1 <= version <= FORMAT_VERSION:
        raise UserError(f"{path}: unsupported format version {version!r}")
    missing = [k for k in _ARRAYS if k not in data]
    if missing:
        raise UserError(f"{path}: missing arrays {missing}")
    c, n = header.get("num_channels"), header.get("num_harmonics")
    names = tuple(header.get("channel_names", ()))
    shapes = {k: data[k].shape for k in _ARRAYS}
    expected = {"offset": (c,), "amplitude": (c, n), "phase": (c, n), "phasor": (c, n, 2), "log_omega": ()}
    if shapes != expected or (names and len(names) != c):
        raise UserError(f"{path}: inconsistent shapes {shapes} for C={c}, N={n}")
    char = Characteristic(
        **{k: data[k] for k in _ARRAYS}, representation=str(header.get("representation", "")), channel_names=names
    )
    return char, header


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from fourierjax.cli.interpolate import add_gait_arguments

    add_gait_arguments(parser)
    parser.add_argument(
        "--out", required=True, metavar="C.npz", help="characteristic file to write (format in the module docstring)"
    )


def run(args: argparse.Namespace) -> int:
    from fourierjax import style
    from fourierjax.cli.interpolate import check_out, load_gait_pair

    out = check_out(args.out, (".npz",))
    a, b = load_gait_pair(args)
    char = style.characteristic(a.model, b.model)
    save_characteristic(out, char, a=a.source, b=b.source, alignment=a.alignment)
    ratio = float(np.exp(np.asarray(char.log_omega)))
    print(
        f"wrote {out}: {len(char.channel_names) or char.offset.shape[0]} channels, "
        f"{char.amplitude.shape[1]} harmonics, omega ratio A/B {ratio:.3f}"
    )
    return 0
