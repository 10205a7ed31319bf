"""`fourierjax characteristic`: the Fourier characteristics A − B of two gaits (Unuma 1995, eq. 7).

Writes a characteristic file (format ``fourierjax.fourier_characteristic``, documented and
read/written by `fourierjax.io.model_io`: `save_characteristic`, `load_characteristic`). Apply it
with `fourierjax.style.superpose(base, [characteristic], [weight])` or ``fourierjax synth --add``.
"""

from __future__ import annotations

import argparse

# Re-exported: `fourierjax.cli.synth` and older callers import them from here.

__all__ = ["HELP", "add_arguments", "run", "load_characteristic", "save_characteristic"]  # noqa: F822 (module __getattr__)


def __getattr__(name: str):
    # The model-file functions load on first use: building the parser (`fourierjax --help`)
    # must not import JAX.
    if name in ("load_characteristic", "save_characteristic"):
        from fourierjax.io import model_io

        return getattr(model_io, name)
    raise AttributeError(name)

HELP = "Fourier characteristics A - B of two gaits (Unuma eq. 7), e.g. briskness = brisk - walk."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from fourierjax.cli._inputs import add_gait_arguments

    add_gait_arguments(parser)
    parser.add_argument(
        "--out", required=True, metavar="C.npz", help="characteristic file to write (format: fourierjax.io.model_io)"
    )


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from fourierjax import style
    from fourierjax.cli._inputs import load_gait_pair
    from fourierjax.cli.interpolate import check_out
    from fourierjax.io.model_io import save_characteristic

    out = check_out(args.out, (".npz",))
    a, b = load_gait_pair(args)
    from fourierjax.cli._speed_limit import characteristic_speeds

    char = style.characteristic(a.model, b.model)
    save_characteristic(out, char, a=a.source, b=b.source, alignment=a.alignment,
                        joint_speed=characteristic_speeds(a, b))
    ratio = float(np.exp(np.asarray(char.log_omega)))
    print(
        f"wrote {out}: {len(char.channel_names) or char.offset.shape[0]} channels, "
        f"{char.amplitude.shape[1]} harmonics, omega ratio A/B {ratio:.3f}"
    )
    return 0
