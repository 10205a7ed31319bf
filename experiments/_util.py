"""Shared plumbing of the experiment scripts: arguments, config, tables (CSV/JSON/Markdown)."""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs" / "experiments"


def parse(name: str, description: str, argv=None) -> tuple[dict, pathlib.Path]:
    """Parse ``--config --out --small``; load and validate the config; make the output folder.

    Returns ``(config, out_dir)`` with ``out_dir = <out>/<name>``.
    """
    from fourierjax.config import load_experiment_config

    p = argparse.ArgumentParser(prog=f"python -m experiments.{name}", description=description)
    p.add_argument("--config", default=str(CONFIGS / f"{name}.toml"), help="TOML config")
    p.add_argument("--out", default="out/experiments", help="output root (default out/experiments)")
    p.add_argument("--small", action="store_true", help="the quick setting of the config ([small])")
    a = p.parse_args(argv)
    cfg = load_experiment_config(a.config, small=a.small, experiment=name)
    out = pathlib.Path(a.out) / name
    out.mkdir(parents=True, exist_ok=True)
    return cfg, out


def write_table(rows: list[dict], out: pathlib.Path, stem: str, title: str, floatfmt: str = ".4g"):
    """Write rows as ``stem.csv``, ``stem.json`` and ``stem.md`` (a Markdown table)."""
    if not rows:
        return
    keys = list(rows[0])
    with open(out / f"{stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    (out / f"{stem}.json").write_text(json.dumps(rows, indent=1))

    def fmt(v):
        return format(v, floatfmt) if isinstance(v, float) else str(v)

    lines = [f"### {title}", "", "| " + " | ".join(keys) + " |",
             "|" + "|".join("---" for _ in keys) + "|"]
    lines += ["| " + " | ".join(fmt(r[k]) for k in keys) + " |" for r in rows]
    (out / f"{stem}.md").write_text("\n".join(lines) + "\n")
    return "\n".join(lines)


def run_main(fn, argv=None) -> int:
    """Run an experiment's body; user mistakes (bad config) print one line and return 2."""
    from fourierjax.errors import FourierJaxError

    t0 = time.perf_counter()
    try:
        fn(argv)
    except FourierJaxError as err:
        print(f"experiments: error: {err}", file=sys.stderr)
        return 2
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0
