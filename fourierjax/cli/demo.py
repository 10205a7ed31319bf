"""`fourierjax demo`: fit the bundled CMU clips and write styled gaits, plots, GIFs and a summary."""

from __future__ import annotations

import argparse

HELP = ("Run the demo on the bundled CMU clips: fitted models, styled BVH gaits, stance gallery, "
        "plots, GIFs, summary.json.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out/demo", metavar="DIR",
                        help="output folder (default out/demo)")
    parser.add_argument("--harmonics", default="3", metavar="N",
                        help="harmonics per fitted model (default 3)")
    parser.add_argument("--seconds", default="4", metavar="S",
                        help="length of each synthesized motion in seconds (default 4)")
    parser.add_argument("--clips", default=None, metavar="A,B,...",
                        help="bundled clips to fit (default: every cmu_mb walk and run)")
    parser.add_argument("--no-gifs", action="store_true", help="skip the animated GIFs")
    parser.add_argument("--no-stance", action="store_true", help="skip the stance gallery")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _number(text: str, name: str, kind=float):
    from fourierjax.errors import UserError

    try:
        return kind(text)
    except ValueError:
        raise UserError(f"{name}: {text!r} is not a{'n integer' if kind is int else ' number'}") from None


def run(args: argparse.Namespace) -> int:
    from fourierjax.demo import DemoConfig, run_demo

    kw = dict(harmonics=_number(args.harmonics, "--harmonics", int),
              seconds=_number(args.seconds, "--seconds"),
              gifs=not args.no_gifs, stance=not args.no_stance)
    if args.clips is not None:  # `--clips ''` names no clip; it ran the whole demo
        kw["clips"] = tuple(c.strip() for c in args.clips.split(",") if c.strip())
        if not kw["clips"]:
            from fourierjax.errors import UserError

            raise UserError(f"--clips: {args.clips!r} names no clip; give bundled clip names "
                            "separated by commas (e.g. 07_01,07_04)")
    summary = run_demo(args.out, DemoConfig(**kw), progress=not args.quiet)
    print(f"{'clip':<7} {'f0 (Hz)':>8} {'rms_deg':>8} {'VE_ang':>7} {'VE_pos':>7}")
    for clip, f in summary["fits"].items():
        print(f"{clip:<7} {f['fundamental_hz']:8.3f} {f['rms_deg']:8.2f} "
              f"{100 * f['variance_explained_angles']:6.1f}% "
              f"{100 * f['variance_explained_positions']:6.1f}%")
    counts = ", ".join(f"{len(v)} {k}" for k, v in summary["written"].items() if v)
    print(f"wrote {counts} under {args.out} ({summary['total_s']:.0f} s); see "
          f"{args.out}/summary.json")
    for s in summary["skipped"]:
        print(f"skipped {s['part']}: {s['reason']}")
    return 0
