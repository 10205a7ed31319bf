"""Distances between gait models in body space: a cycle of root-relative joint positions, best cyclic shift."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from fourierjax._fourier._model import FourierModel
from fourierjax._jit import filter_jit
from fourierjax._math import safe_sqrt
from fourierjax.errors import UserError
from fourierjax.skeleton import Skeleton


def _positions(model: FourierModel, skeleton: Skeleton, num_samples: int) -> Float[Array, "K J 3"]:
    """Root-relative joint positions of one model at `num_samples` evenly spaced cycle phases (unjitted)."""
    from fourierjax import features, fourier

    phase = jnp.arange(num_samples, dtype=model.amplitude.dtype) * (2 * jnp.pi / num_samples)
    return features.root_relative_positions(skeleton, fourier.synthesize_phase(model, phase), model.representation)


_positions_jit = filter_jit(_positions)


def cycle_positions(model: FourierModel, skeleton: Skeleton, *, num_samples: int = 64) -> Float[Array, "K J 3"]:
    """One cycle of a gait model's root-relative joint positions, the poses `cycle_distance` compares.

    Arguments:
        model: one FourierModel (gait channel layout of `skeleton`).
        skeleton: the Skeleton it was fitted on.
        num_samples: phases `2πk / num_samples`, `k = 0 … num_samples − 1` (static).

    Returns:
        `[num_samples, J, 3]` joint positions in file units, root at the origin of the heading frame.
    """
    _check("cycle_positions", model, model, skeleton, num_samples)
    return _positions_jit(model, skeleton, num_samples)


def shift_distances(pa: Float[Array, "K J 3"], pb: Float[Array, "K J 3"]) -> Float[Array, " K"]:
    """Mean joint distance between `pa[k]` and `pb[(k + s) % K]` for every shift `s` (unjitted)."""
    k = pa.shape[0]
    d = pa[:, None, :, :] - pb[None, :, :, :]  # [K (a), K (b), J, 3]
    # Shim: sqrt'(0) is infinite, and identical poses (a model against itself) are the common case.
    dist = safe_sqrt(jnp.sum(d * d, axis=-1)).mean(axis=-1)  # [K, K]
    idx = (jnp.arange(k)[:, None] + jnp.arange(k)[None, :]) % k  # [k, s] -> b's sample k + s
    return jnp.take_along_axis(dist, idx, axis=1).mean(axis=0)


def _cycle_distance(model_a, model_b, skeleton, num_samples):
    d = shift_distances(_positions(model_a, skeleton, num_samples), _positions(model_b, skeleton, num_samples))
    s = jnp.argmin(d)
    return d[s], s


_cycle_distance_jit = filter_jit(_cycle_distance)


def _check(where: str, model_a, model_b, skeleton, num_samples) -> None:
    if not isinstance(model_a, FourierModel) or not isinstance(model_b, FourierModel):
        raise UserError(f"{where}: `model_a` and `model_b` must be FourierModels")
    for name, m in (("model_a", model_a), ("model_b", model_b)):
        if m.amplitude.ndim != 2:
            raise UserError(f"{where}: `{name}` is a stacked model (amplitude {m.amplitude.shape}); "
                            "pass one model, or vmap")
    if not isinstance(skeleton, Skeleton):
        raise UserError(f"{where}: `skeleton` must be a Skeleton, got {type(skeleton).__name__}")
    if not isinstance(num_samples, int) or isinstance(num_samples, bool) or num_samples < 2:
        raise UserError(f"{where}: `num_samples` must be an int >= 2, got {num_samples!r}")


def cycle_distance(
    model_a: FourierModel, model_b: FourierModel, skeleton: Skeleton, *, num_samples: int = 64
) -> Float[Array, ""]:
    """Body-frame distance of two gait models over one cycle, after the best cyclic shift.

    Both models are synthesized at `num_samples` evenly spaced cycle phases and posed through
    forward kinematics with the root at the origin of the heading frame
    (`features.root_relative_positions`); the distance is the mean over samples and joints of
    the Euclidean distance between corresponding joints, minimised over the `num_samples`
    cyclic shifts of `model_b`'s cycle (so two models that differ only in phase alignment are
    at distance 0 up to the sampling step). Symmetric; the two models may use different
    representations (`"euler"`, `"expmap"`) of the same skeleton. Travel speed and root height
    do not enter (root-relative); ω does not either (one cycle each).

    Arguments:
        model_a, model_b: one FourierModel each (gait channel layout of `skeleton`).
        skeleton: the Skeleton both models were fitted on.
        num_samples: phases per cycle (a static shape: each value compiles once).

    Returns:
        Scalar distance, in the skeleton's file units (Bandai: cm; CMU: ~0.0564 m).
    """
    _check("cycle_distance", model_a, model_b, skeleton, num_samples)
    return _cycle_distance_jit(model_a, model_b, skeleton, num_samples)[0]


def cycle_distance_shift(
    model_a: FourierModel, model_b: FourierModel, skeleton: Skeleton, *, num_samples: int = 64
) -> tuple[Float[Array, ""], Int[Array, ""]]:
    """`cycle_distance` and the best shift.

    Arguments:
        model_a, model_b, skeleton, num_samples: as for `cycle_distance`.

    Returns:
        `(distance, shift)`: sample `k` of `model_a` is matched with sample `k + shift` (mod
        `num_samples`) of `model_b`, i.e. `model_b` at phase `θ + 2π shift / num_samples`.
    """
    _check("cycle_distance_shift", model_a, model_b, skeleton, num_samples)
    return _cycle_distance_jit(model_a, model_b, skeleton, num_samples)


def cycle_distances(
    models_a: FourierModel, models_b: FourierModel, skeleton: Skeleton, *, num_samples: int = 64
) -> Float[Array, " B"]:
    """`cycle_distance` of stacked pairs (leading axis `B`), one compiled program for the batch.

    Arguments:
        models_a, models_b: stacked FourierModels (`style.stack`), `B` each, on one skeleton.
        skeleton: the Skeleton; num_samples: as for `cycle_distance`.

    Returns:
        `[B]` distances in file units.
    """
    if models_a.amplitude.ndim != 3 or models_b.amplitude.shape != models_a.amplitude.shape:
        raise UserError(f"cycle_distances: expected two stacked models of one shape, got amplitudes "
                        f"{models_a.amplitude.shape} and {models_b.amplitude.shape}")
    if not isinstance(num_samples, int) or isinstance(num_samples, bool) or num_samples < 2:
        raise UserError(f"cycle_distances: `num_samples` must be an int >= 2, got {num_samples!r}")
    return _cycle_distances_jit(models_a, models_b, skeleton, num_samples)


@filter_jit
def _cycle_distances_jit(models_a, models_b, skeleton, num_samples):
    import equinox as eqx

    def one(a, b):
        return _cycle_distance(a, b, skeleton, num_samples)[0]

    # lax.map, not vmap: one pair's [K, K, J] distance table in memory at a time.
    pairs = (models_a, models_b)
    dyn, static = eqx.partition(pairs, eqx.is_array)
    return jax.lax.map(lambda d: one(*eqx.combine(d, static)), dyn)
