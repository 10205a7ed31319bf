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
    """`x` as a NumPy array, or None when it is traced: values are checked on concrete inputs
    only (a host copy of a small value; under jit, vmap and grad the checks are skipped)."""
    if isinstance(x, jax.core.Tracer):
        return None
    return np.asarray(x)


def number(x, label: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    """`x` as a finite Python float (> 0 with `positive`, >= 0 with `nonnegative`), else a
    UserError naming `label`. NaN fails every comparison, so finiteness is checked first."""
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
    truncated), else a UserError naming `label`."""
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
