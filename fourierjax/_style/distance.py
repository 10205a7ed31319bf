"""Distances between gait models in body space: a cycle of root-relative joint positions, best cyclic shift."""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from fourierjax._fourier._model import FourierModel
from fourierjax._jit import filter_jit
from fourierjax._math import safe_sqrt
from fourierjax.errors import UserError
from fourierjax.skeleton import Skeleton

if TYPE_CHECKING:
    from fourierjax.body import BodyMap


def _positions(model: FourierModel, skeleton: Skeleton, num_samples: int, pelvis: int) -> Float[Array, "K J 3"]:
    """Pelvis-relative joint positions of one model at `num_samples` evenly spaced cycle phases (unjitted)."""
    from fourierjax import features, fourier

    phase = jnp.arange(num_samples, dtype=model.amplitude.dtype) * (2 * jnp.pi / num_samples)
    return features.root_relative_positions(skeleton, fourier.synthesize_phase(model, phase), model.representation,
                                            pelvis)


_positions_jit = filter_jit(_positions)


#: Pelvis inferred per topology (a rig's pelvis does not change from clip to clip; inference poses
#: a whole cycle, too slow to repeat per distance).
_INFERRED_PELVIS: dict = {}


def _pelvis(where: str, body_map, skeleton: Skeleton, *models: FourierModel) -> int:
    """The pelvis joint of the poses: `body_map`'s, else that of the first concrete model's own cycle."""
    from fourierjax.body import BodyMap

    if body_map is None:
        from fourierjax.gait import model_body_map

        if not isinstance(skeleton, Skeleton):
            raise UserError(f"{where}: `skeleton` must be a Skeleton, got {type(skeleton).__name__}")
        if skeleton.topology in _INFERRED_PELVIS:
            return _INFERRED_PELVIS[skeleton.topology]
        concrete = [m for m in models if not isinstance(m.offset, jax.core.Tracer)]
        if not concrete:
            raise UserError(f"{where}: the pelvis is read from a body map, inferred from a concrete model; "
                            "under jit, vmap or grad of both models pass `body_map=`")
        m = concrete[0]
        if m.amplitude.ndim == 3:  # stacked: the first pair's
            m = jax.tree_util.tree_map(lambda x: x[0] if eqx.is_array(x) else x, m)
        body_map = model_body_map(m, skeleton)
        _INFERRED_PELVIS[skeleton.topology] = int(body_map.pelvis)
    if not isinstance(body_map, BodyMap):
        raise UserError(f"{where}: `body_map` must be a BodyMap, got {type(body_map).__name__}")
    if tuple(body_map.joint_names) != tuple(skeleton.topology.names):
        raise UserError(f"{where}: `body_map` was made for another skeleton (joints "
                        f"{tuple(body_map.joint_names)[:3]}..., the skeleton's {skeleton.topology.names[:3]}...)")
    return int(body_map.pelvis)


def cycle_positions(
    model: FourierModel, skeleton: Skeleton, *, num_samples: int = 64, body_map: BodyMap | None = None
) -> Float[Array, "K J 3"]:
    """One cycle of a gait model's pelvis-relative joint positions, the poses `cycle_distance` compares.

    Arguments:
        model: one FourierModel (gait channel layout of `skeleton`).
        skeleton: the Skeleton it was fitted on.
        num_samples: phases `2πk / num_samples`, `k = 0 … num_samples − 1` (static).
        body_map: the rig's `body.BodyMap` (its pelvis is put at the origin); `None`: the map of
            the model's own cycle (`gait.model_body_map`, which needs a concrete model).

    Returns:
        `[num_samples, J, 3]` joint positions in file units, the pelvis at the origin of the heading frame.
    """
    _check("cycle_positions", model, model, skeleton, num_samples)
    return _positions_jit(model, skeleton, num_samples, _pelvis("cycle_positions", body_map, skeleton, model))


def shift_distances(pa: Float[Array, "K J 3"], pb: Float[Array, "K J 3"]) -> Float[Array, " K"]:
    """Mean joint distance between `pa[k]` and `pb[(k + s) % K]` for every shift `s` (unjitted)."""
    k = pa.shape[0]
    d = pa[:, None, :, :] - pb[None, :, :, :]  # [K (a), K (b), J, 3]
    # Shim: sqrt'(0) is infinite, and identical poses (a model against itself) are the common case.
    dist = safe_sqrt(jnp.sum(d * d, axis=-1)).mean(axis=-1)  # [K, K]
    idx = (jnp.arange(k)[:, None] + jnp.arange(k)[None, :]) % k  # [k, s] -> b's sample k + s
    return jnp.take_along_axis(dist, idx, axis=1).mean(axis=0)


def _cycle_distance(model_a, model_b, skeleton, num_samples, pelvis):
    d = shift_distances(_positions(model_a, skeleton, num_samples, pelvis),
                        _positions(model_b, skeleton, num_samples, pelvis))
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
    model_a: FourierModel, model_b: FourierModel, skeleton: Skeleton, *, num_samples: int = 64,
    body_map: BodyMap | None = None,
) -> Float[Array, ""]:
    """Body-frame distance of two gait models over one cycle, after the best cyclic shift.

    Both models are synthesized at `num_samples` evenly spaced cycle phases and posed through
    forward kinematics with the body map's pelvis at the origin of the heading frame
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
        body_map: the rig's `body.BodyMap` (pass it where you have it: a clip's
            `body.infer_body_map`); `None`: the map of the first concrete model's own cycle
            (`gait.model_body_map`), inferred once per topology. Under jit, vmap or grad of
            both models, with no pelvis inferred yet for the topology, it is required.

    Returns:
        Scalar distance, in the skeleton's file units (Bandai: cm; CMU: ~0.0564 m).
    """
    _check("cycle_distance", model_a, model_b, skeleton, num_samples)
    pelvis = _pelvis("cycle_distance", body_map, skeleton, model_a, model_b)
    return _cycle_distance_jit(model_a, model_b, skeleton, num_samples, pelvis)[0]


def cycle_distance_shift(
    model_a: FourierModel, model_b: FourierModel, skeleton: Skeleton, *, num_samples: int = 64,
    body_map: BodyMap | None = None,
) -> tuple[Float[Array, ""], Int[Array, ""]]:
    """`cycle_distance` and the best shift.

    Arguments:
        model_a, model_b, skeleton, num_samples, body_map: as for `cycle_distance`.

    Returns:
        `(distance, shift)`: sample `k` of `model_a` is matched with sample `k + shift` (mod
        `num_samples`) of `model_b`, i.e. `model_b` at phase `θ + 2π shift / num_samples`.
    """
    _check("cycle_distance_shift", model_a, model_b, skeleton, num_samples)
    pelvis = _pelvis("cycle_distance_shift", body_map, skeleton, model_a, model_b)
    return _cycle_distance_jit(model_a, model_b, skeleton, num_samples, pelvis)


def cycle_distances(
    models_a: FourierModel, models_b: FourierModel, skeleton: Skeleton, *, num_samples: int = 64,
    body_map: BodyMap | None = None,
) -> Float[Array, " B"]:
    """`cycle_distance` of stacked pairs (leading axis `B`), one compiled program for the batch.

    Arguments:
        models_a, models_b: stacked FourierModels (`style.stack`), `B` each, on one skeleton.
        skeleton: the Skeleton; num_samples, body_map: as for `cycle_distance` (`None`: the
            map of the first pair's own cycle).

    Returns:
        `[B]` distances in file units.
    """
    if models_a.amplitude.ndim != 3 or models_b.amplitude.shape != models_a.amplitude.shape:
        raise UserError(f"cycle_distances: expected two stacked models of one shape, got amplitudes "
                        f"{models_a.amplitude.shape} and {models_b.amplitude.shape}")
    if not isinstance(num_samples, int) or isinstance(num_samples, bool) or num_samples < 2:
        raise UserError(f"cycle_distances: `num_samples` must be an int >= 2, got {num_samples!r}")
    pelvis = _pelvis("cycle_distances", body_map, skeleton, models_a, models_b)
    return _cycle_distances_jit(models_a, models_b, skeleton, num_samples, pelvis)


@filter_jit
def _cycle_distances_jit(models_a, models_b, skeleton, num_samples, pelvis):
    def one(a, b):
        return _cycle_distance(a, b, skeleton, num_samples, pelvis)[0]

    # lax.map, not vmap: one pair's [K, K, J] distance table in memory at a time.
    pairs = (models_a, models_b)
    dyn, static = eqx.partition(pairs, eqx.is_array)
    return jax.lax.map(lambda d: one(*eqx.combine(d, static)), dyn)
