"""Argument checks shared by the NumPy-edge and jnp entry points (one message format each).

`label` is what the message names, e.g. ``"frame_time_s:"`` or ``"fit: num_harmonics"``; the
messages read ``"{label} must be ..., got ..."``.
"""

from __future__ import annotations

import operator

import jax
import numpy as np

from fourierjax.errors import UserError


def concrete(x) -> np.ndarray | None:
    """`x` as a NumPy array, or None when it is traced.

    Values are checked on concrete inputs only (a host copy of a small value); a caller that
    gets None must check the traced value another way (`eqx.error_if` or a returned status).

    Arguments:
        x: an array or a tracer.

    Returns:
        A NumPy array, or None for a tracer.
    """
    if isinstance(x, jax.core.Tracer):
        return None
    return np.asarray(x)


def number(x, label: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    """`x` as a finite Python float (> 0 with `positive`, >= 0 with `nonnegative`), else a
    UserError naming `label`. NaN fails every comparison, so finiteness is checked first.

    Arguments:
        x: the value.
        label: what the message names, e.g. ``"frame_time_s:"``.
        positive: require `x > 0`.
        nonnegative: require `x >= 0`.

    Returns:
        The value as a float.
    """
    if isinstance(x, bool | np.bool_):
        raise UserError(f"{label} must be a number, got {x!r}")
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise UserError(f"{label} must be a number, got {x!r}") from None
    if not np.isfinite(v):
        raise UserError(f"{label} must be finite, got {v}")
    if positive and v <= 0:
        raise UserError(f"{label} must be positive, got {v}")
    if nonnegative and v < 0:
        raise UserError(f"{label} must be >= 0, got {v}")
    return v


def integer(x, label: str, minimum: int) -> int:
    """`x` as a Python int >= `minimum` (NumPy integers too; no bools, and 10.7 is not
    truncated), else a UserError naming `label`.

    Arguments:
        x: the value.
        label: what the message names.
        minimum: the smallest accepted value.

    Returns:
        The value as an int.
    """
    try:
        if isinstance(x, bool | np.bool_):
            raise TypeError
        n = operator.index(x)
    except TypeError:
        raise UserError(
            f"{label} must be an integer >= {minimum}, got {x!r} ({type(x).__name__})"
        ) from None
    if n < minimum:
        raise UserError(f"{label} must be an integer >= {minimum}, got {n}")
    return n
