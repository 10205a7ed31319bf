"""The `fourierjax` command line: one module per subcommand, registered in COMMANDS."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# Subcommand name -> module under fourierjax.cli. Each module defines
#   add_arguments(parser: argparse.ArgumentParser) -> None
#   run(args: argparse.Namespace) -> int
#   HELP: str  (one line for `fourierjax --help`)
COMMANDS: dict[str, str] = {
    "info": "info",
    "positions": "positions",
    "characteristic": "characteristic",
    "interpolate": "interpolate",
    "transition": "transition",
    "fit": "fit",
    "synth": "synth",
    "plot": "plot",
    "demo": "demo",
    "stance": "stance",
    "explore": "explore",
    "cache": "cache",
}


#: Subcommands that draw with matplotlib: they write files and never open a window.
_DRAWS = frozenset({"plot", "demo", "stance"})


def use_agg() -> None:
    """Choose matplotlib's Agg backend (files only, no window), as the CLI and the demo do.

    `fourierjax.viz` leaves the backend alone, so that Jupyter's inline backend shows figures.
    """
    import matplotlib

    matplotlib.use("Agg")


_NO_CACHE_HELP = ("do not use the persistent compile cache (default: on, in $FOURIERJAX_CACHE_DIR "
                  "or ~/.cache/fourierjax/jax; a second call then compiles nothing)")


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fourierjax",
        description="Fourier gait models and expressive stance for human motion (JAX).",
    )
    parser.add_argument("--no-cache", action="store_true", help=_NO_CACHE_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(f"fourierjax.cli.{module_name}")
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        # Also after the subcommand (`fourierjax fit --no-cache ...`); SUPPRESS keeps the
        # subparser's default from overwriting a `fourierjax --no-cache fit ...`.
        p.add_argument("--no-cache", action="store_true", default=argparse.SUPPRESS,
                       help=_NO_CACHE_HELP)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `fourierjax` script. Returns the process exit code.

    With ``$FOURIERJAX_PROGRAM_LOG`` set to a path, the JAX programs and traces the command
    made are written there as JSON (`fourierjax._programs.ProgramCount`).
    """
    parser = _build_parser()
    args = parser.parse_args(argv)
    from fourierjax import _compile_cache

    # Every command: set before JAX is imported (by the command), so nothing is imported here.
    if args.no_cache:
        _compile_cache.disable_compile_cache()
    else:
        _compile_cache.enable_compile_cache()
    if args.command in _DRAWS:
        use_agg()
    log = os.environ.get("FOURIERJAX_PROGRAM_LOG")  # `_programs.PROGRAM_LOG_ENV`, unimported
    if log:
        from fourierjax._programs import ProgramCount

        with ProgramCount() as count:
            try:
                return _run(args)
            finally:
                count.write(log)
    return _run(args)


def console() -> None:
    """The installed `fourierjax` script and `python -m fourierjax`: `main`, then a quick exit.

    Once JAX is imported, the interpreter's own exit (finalizing JAX's and XLA's modules and
    objects) took 0.25-0.35 s on the 2-core machine, even after `import jax.numpy` alone: the
    time between a script's last line and its process's end. A command has closed its files
    when `main` returns, so the script flushes its streams and leaves with `os._exit`. `--help`,
    a usage error and a command that never imported JAX exit normally. `main` itself (what
    tests and Python callers use) is unchanged.
    """
    code = main()
    if "jax" not in sys.modules:
        sys.exit(code)
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (`| head`): nothing more to say
            pass
    os._exit(code)


def _run(args: argparse.Namespace) -> int:
    """Run the parsed command; user errors become one line on stderr and exit status 2."""
    from fourierjax.errors import FourierJaxError

    try:
        return int(args._run(args) or 0)
    except FourierJaxError as err:
        print(f"fourierjax: error: {err}", file=sys.stderr)
        return 2
    except FileNotFoundError as err:
        print(f"fourierjax: error: {err.filename or err}: no such file", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader of our output stopped early (`fourierjax info x.bvh | head -1`): not an
        # error of ours. Point stdout at devnull so the interpreter's final flush is quiet.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as err:
        # A file that cannot be read or written (permission denied, a directory where a file
        # goes, no space left, a file-size limit): one line naming it, not a traceback.
        where = f"{err.filename}: " if err.filename else ""
        print(f"fourierjax: error: {where}{err.strerror or err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fourierjax: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
