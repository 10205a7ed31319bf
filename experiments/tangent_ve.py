"""Issue #20: position variance explained at N = 3, tangent vs euler vs expmap, on every bundled clip.

Fits every bundled CMU clip with `fourierjax.motion.fit_motions` in each representation and
prints ``ClipFit.variance_explained_positions`` (root-relative joint positions over the fitted
frames). Usage: ``python -m experiments.tangent_ve [--harmonics N]``.
"""

from __future__ import annotations

import argparse

REPRESENTATIONS = ("tangent", "euler", "expmap")


def table(num_harmonics: int = 3) -> dict[str, dict[str, float]]:
    """``{clip: {representation: position VE (NaN for a failed fit)}}``."""
    import fourierjax.data
    from fourierjax.motion import fit_motions

    names = fourierjax.data.list()
    clips = [fourierjax.data.load(n) for n in names]
    out: dict[str, dict[str, float]] = {n: {} for n in names}
    for rep in REPRESENTATIONS:
        for n, f in zip(names, fit_motions(clips, num_harmonics, rep, throw=False)):
            out[n][rep] = f.variance_explained_positions if f.successful else float("nan")
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--harmonics", type=int, default=3)
    args = parser.parse_args(argv)
    rows = table(args.harmonics)
    print("clip     " + "".join(f"{r:>9}" for r in REPRESENTATIONS))
    for n, row in rows.items():
        print(f"{n:<9}" + "".join(f"{row[r]:9.4f}" for r in REPRESENTATIONS))


if __name__ == "__main__":
    main()
