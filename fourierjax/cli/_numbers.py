"""Numbers from the command line: parsed finite values and frame counts that never overflow."""

from __future__ import annotations

import math

#: Most frames a command writes (2.3 hours at 120 fps; a BVH of ~0.7 GB for a CMU skeleton):
#: `synth --seconds 1000000` asked XLA for 46 GB and died with a JAX traceback.
MAX_FRAMES = 1_000_000


def frame_count(seconds: float, dt: float) -> int:
    """Frames of a `seconds`-long motion at `dt` seconds per frame.

    Arguments:
        seconds: length of the motion (> 0, finite).
        dt: seconds per frame (> 0).

    Returns:
        The frame count, at least 2.

    Raises:
        UserError: past `MAX_FRAMES`, including a count too large to be an integer at all
            (``--seconds 1e308`` or ``--fps 1e308``: ``int(round(inf))`` raised OverflowError).
    """
    from fourierjax.errors import UserError

    frames = seconds / dt if dt > 0 else math.inf
    if not frames <= MAX_FRAMES:  # also inf and NaN
        shown = f"{frames:.3g}" if math.isfinite(frames) else "too many"
        raise UserError(f"--seconds: {seconds:g} s at {1 / dt if dt > 0 else math.inf:g} fps is "
                        f"{shown} frames, more than the {MAX_FRAMES} a command writes; use "
                        "fewer seconds or a lower --fps")
    return max(2, int(round(frames)))


def parse_number(text: str, option: str, *, positive=False, nonnegative=False, integer=False):
    """A finite float (or int) from a command-line string.

    Arguments:
        text: the string given.
        option: the option's name, for the message (``"--seconds"``).
        positive: require > 0.
        nonnegative: require >= 0.
        integer: parse an int instead of a float.

    Returns:
        The value.

    Raises:
        UserError: one line naming the option.
    """
    from fourierjax.errors import UserError

    try:
        value = int(text) if integer else float(text)
    except ValueError:
        kind = "an integer" if integer else "a number"
        raise UserError(f"{option}: {text!r} is not {kind}") from None
    if not math.isfinite(value):
        raise UserError(f"{option}: {text!r} is not a finite number")
    if positive and not value > 0:
        raise UserError(f"{option}: {text} must be > 0")
    if nonnegative and value < 0:
        raise UserError(f"{option}: {text} must be >= 0")
    return value
