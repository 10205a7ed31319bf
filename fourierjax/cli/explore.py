"""`fourierjax explore`: start the interactive editor (a local web page) and print its URL."""

from __future__ import annotations

import argparse
import time

HELP = "Start the interactive gait and stance editor in the browser (Unuma 1995 Fig. 8; viser)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sources", nargs="*", metavar="MODEL_OR_BVH",
                        help="model files, characteristic files, BVH clips or bundled clip names "
                        "(default: the bundled CMU walks and runs)")
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this "
                        "machine only; 0.0.0.0 opens it to the network)")
    parser.add_argument("--port", type=int, default=8080, help="port (default 8080; the next free one if taken)")
    parser.add_argument("--no-browser", action="store_true", help="print the URL without opening a browser")
    parser.add_argument("--out-dir", default=".", metavar="DIR", help="folder of exported files (default .)")
    parser.add_argument("--seconds", type=float, default=4.0, metavar="S",
                        help="length of the synthesized motion (default 4)")
    parser.add_argument("--fps", type=float, default=60.0, metavar="F", help="frame rate (default 60)")


def _serve_forever() -> None:
    """Keep the process alive while the server's threads work (Ctrl-C ends it)."""
    while True:
        time.sleep(1.0)


def run(args: argparse.Namespace) -> int:
    from fourierjax.errors import UserError

    try:
        import viser  # noqa: F401
    except ImportError:
        raise UserError("explore needs viser: pip install 'fourierjax[explore]'") from None
    from fourierjax._compile_cache import enable_compile_cache
    from fourierjax.explore import Explorer, Params, load_sources

    Params("a", "b", seconds=args.seconds, fps=args.fps)  # refuse a bad --seconds or --fps before any fit
    enable_compile_cache()
    print("fourierjax explore: loading and fitting the gaits (first start: ~30 s)...", flush=True)
    library, messages = load_sources(args.sources)
    explorer = Explorer(library, host=args.host, port=args.port, out_dir=args.out_dir, seconds=args.seconds,
                        fps=args.fps, messages=messages)
    print(f"fourierjax explore: open {explorer.url} (Ctrl-C stops)", flush=True)
    if not args.no_browser:
        import webbrowser

        webbrowser.open(explorer.url)
    try:
        _serve_forever()
    finally:
        explorer.close()
