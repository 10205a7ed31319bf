"""`fourierjax cache`: where the persistent compile cache is, how much it holds, and clearing it."""

from __future__ import annotations

import argparse
import json

HELP = ("Show the persistent compile cache (folder, files, size, budget) or clear it with --clear. "
        "It is kept under $FOURIERJAX_CACHE_MAX_MB MiB (default 2048): least recently used files "
        "go first.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--clear", action="store_true",
                        help="remove every compiled and saved program (they are rebuilt when needed)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of lines")


def run(args: argparse.Namespace) -> int:
    from fourierjax import _compile_cache as cc
    from fourierjax.errors import UserError

    try:
        budget = cc.cache_max_bytes()
    except ValueError as err:
        raise UserError(str(err)) from None
    folder = cc.cache_dir()
    removed = freed = 0
    if args.clear:
        removed, freed = cc.clear_cache(folder)
    files, size = cc.cache_usage(folder)
    facts = {"folder": folder, "files": files, "bytes": size, "budget_bytes": budget,
             "on": not cc.cache_disabled()}
    if args.clear:
        facts.update(removed_files=removed, removed_bytes=freed)
    if args.json:
        print(json.dumps(facts))
        return 0
    mib = 2.0**20
    print(f"folder     {folder}{'' if facts['on'] else '  (off: $FOURIERJAX_NO_CACHE is set)'}")
    if args.clear:
        print(f"removed    {removed} files, {freed / mib:.1f} MiB")
    print(f"holds      {files} files, {size / mib:.1f} MiB")
    print(f"budget     {budget / mib:.0f} MiB (${cc.CACHE_MAX_MB_ENV}; least recently used files go first)")
    return 0
