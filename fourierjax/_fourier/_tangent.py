"""The "tangent" representation: each joint's rotation about its clip mean, ``R_j = M_j exp(d_j)``.

A change of joint frames ``R' = C_p^T R C_j`` moves the chordal mean the same way
(``M' = C_p^T M C_j``) and maps the tangent coordinates linearly (``d' = C_j^T d``); a least-squares
Fourier fit with one basis on all three channels of a joint commutes with that map, so the fit of
a rewritten clip is the rewritten fit, whatever the rig's rest frames or Euler orders.

Features (what `fit` takes and synthesis returns) stay exponential maps, each on the branch
nearest ``log M_j``; only the model's coefficients are the ``d_j`` and ``FourierModel.frames``
``[K, 4]`` holds the ``M_j`` (wxyz).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import _jit, rotations
from fourierjax._rotations._common import _safe_atan2
from fourierjax._rotations._quat import nearest_rotation_vector
from fourierjax.errors import UserError

#: Suffix of the first channel of a joint's triple (``"<joint>.expmap_tangent0..2"``).
_FIRST = ".expmap_tangent0"
# Power iterations of the 4x4 scatter matrix after the sign-aligned start: the start is already
# within a few degrees of the dominant eigenvector for a gait clip; each iteration shrinks the
# error by the eigenvalue ratio (plain jnp: no batched LAPACK call, see STYLE "Known traps").
_POWER_STEPS = 12


def triples(channel_names: tuple[str, ...], num_channels: int, num_joints: int | None = None) -> np.ndarray:
    """Static ``[K, 3]`` column indices of the joints' tangent triples.

    From the channel names when there are any (``"<joint>.expmap_tangent0..2"``), else the last
    ``3 * num_joints`` channels (the feature layout: root channels first).
    """
    if channel_names:
        first = [i for i, n in enumerate(channel_names) if n.endswith(_FIRST)]
        return np.asarray([[i, i + 1, i + 2] for i in first], dtype=int).reshape(-1, 3)
    if num_joints is None:
        raise UserError("tangent models need channel_names (`<joint>.expmap_tangent0..2`)")
    start = num_channels - 3 * num_joints
    return np.arange(start, num_channels).reshape(-1, 3)


def check_frames(where: str, frames, num_channels: int, channel_names, lead: tuple[int, ...]) -> None:
    """Static checks of ``FourierModel.frames`` for a model of ``representation``."""
    shape = jnp.shape(frames)
    if len(shape) < 2 or shape[-1] != 4 or tuple(shape[:-2]) != tuple(lead):
        raise UserError(
            f"{where}: `frames` must be [..., K, 4] (wxyz clip-mean quaternions, one per rotation "
            f"joint) with the model's leading axes {lead}, got shape {shape}")
    K = shape[-2]
    if channel_names:
        k = len(triples(channel_names, num_channels))
        if k != K:
            raise UserError(f"{where}: {K} `frames` for {k} `.expmap_tangent0..2` joints in "
                            "channel_names")
    elif 3 * K > num_channels:
        raise UserError(f"{where}: {K} `frames` need {3 * K} channels, the model has {num_channels}")


def clip_means(q: Float[Array, "T K 4"], w: Float[Array, "T K"]) -> Float[Array, "K 4"]:
    """Weighted chordal mean of each joint's quaternions (the dominant eigenvector of
    ``sum_t w q q^T``, sign-invariant), ``w >= 0`` canonical; equivariant: ``mean(a q b) = a mean(q) b``.
    """
    ref = jnp.take_along_axis(q, jnp.argmax(w, axis=0)[None, :, None], axis=0)[0]  # [K, 4]
    s = jnp.where(jnp.sum(q * ref[None], axis=-1) < 0, -1.0, 1.0).astype(q.dtype)
    m = rotations.quat_normalize(jnp.sum((w * s)[..., None] * q, axis=0))
    # One pass over the frames builds each joint's 4x4 scatter matrix; the power steps are then
    # 4x4 products. Stepping over the frames each time was 12 passes over [T, K, 4] (issue 25:
    # the tangent fit of 500 Bandai-1 clips 1.73 -> 1.31 CPU-s).
    scatter = jnp.einsum("tki,tkj->kij", w[..., None] * q, q)  # [K, 4, 4]
    for _ in range(_POWER_STEPS):
        m = rotations.quat_normalize(jnp.sum(scatter * m[:, None, :], axis=-1))
    return canonical_frames(m)


def _log_about(frames: Array, v: Array) -> Array:
    """``d = log(M^-1 exp(v))`` on the hemisphere of ``M`` (angle in [0, pi])."""
    q = rotations.quat_from_expmap(v)
    return rotations.expmap_from_quat(rotations.quat_multiply(rotations.quat_conjugate(frames), q))


def to_tangent(features: Float[Array, "*B T C"], weights: Float[Array, "*B T K"],
               cols: np.ndarray) -> tuple[Float[Array, "*B T C"], Float[Array, "*B K 4"]]:
    """Fit inputs: expmap features to tangent coordinates about the clip means (weights: frames
    used per joint). Returns ``(features with d in the triples, frames)``."""
    v = features[..., cols]  # [*B, T, K, 3]
    q = rotations.quat_from_expmap(v)
    mean = clip_means
    for _ in range(features.ndim - 2):
        mean = jax.vmap(mean)
    frames = mean(q, weights)
    d = _log_about(frames[..., None, :, :], v)
    out = features.at[..., cols.reshape(-1)].set(d.reshape(*d.shape[:-2], -1))
    return out, frames


def from_tangent(x: Float[Array, "*B T C"], frames: Float[Array, "*B K 4"],
                 cols: np.ndarray) -> Float[Array, "*B T C"]:
    """Synthesized tangent coordinates to expmap features: ``exp(v) = M exp(d)``, ``v`` on the
    branch nearest ``log M``.

    One jitted program (the columns static): run eagerly, its ~40 ops were each compiled on
    first use, 3-4 s of a tangent model's first synthesis on 2 cores (Euler's: 0.8 s)."""
    return _from_tangent(x, frames, tuple(int(c) for c in np.asarray(cols).ravel()))


@_jit.jit(static_argnums=2)
def _from_tangent(x, frames, flat_cols: tuple[int, ...]):
    cols = np.asarray(flat_cols, int).reshape(-1, 3)
    d = x[..., cols]  # [*B, T, K, 3]
    m = jnp.asarray(frames, x.dtype)[..., None, :, :]
    v = rotations.expmap_from_quat(rotations.quat_multiply(m, rotations.quat_from_expmap(d)))
    v, _ = nearest_rotation_vector(rotations.expmap_from_quat(m), v)
    return x.at[..., cols.reshape(-1)].set(v.reshape(*v.shape[:-2], -1))


def fit_inputs(name: str, features, mask, channel_names):
    """`fit` / `fit_batch` hook: ``(tangent features, frames)`` of expmap ``features [*B, T, C]``
    with ``mask`` None, ``[*B, T]`` or ``[*B, T, C]`` (the frames each joint's mean uses)."""
    if not channel_names:
        raise UserError(f"{name}: representation 'tangent' needs channel_names "
                        "(`<joint>.expmap_tangent0..2`, features.channel_names_for)")
    cols = triples(tuple(channel_names), features.shape[-1])
    if len(cols) == 0:
        raise UserError(f"{name}: representation 'tangent' but no `.expmap_tangent0` channels")
    traced = isinstance(features, jax.core.Tracer)
    x = jnp.asarray(features)
    if mask is None:
        w = jnp.ones((*x.shape[:-1], len(cols)), x.dtype)
    else:
        m = jnp.asarray(mask)
        w = (m[..., cols[:, 0]] if m.ndim == x.ndim else
             jnp.broadcast_to(m[..., None], (*m.shape, len(cols)))).astype(x.dtype)
        # Frames left out may hold NaN: they must not reach the means.
        keep = w[..., None] > 0
        v = jnp.where(keep, x[..., cols], 0.0)
        x = x.at[..., cols.reshape(-1)].set(v.reshape(*v.shape[:-2], -1))
    out, frames = to_tangent(x, w, cols)
    if not traced:
        out, frames = np.asarray(out), np.asarray(frames)
    return out, frames


# ------------------------------------------------------------------ style algebra on the frames
# A change of rig maps the frames M' = C_p^T M C_j and the tangent coordinates d' = C_j^T d. The
# frame difference Delta = M_b^-1 M_a maps to C_j^T Delta C_j, and so do its logarithm (a rotation
# vector: log(C^T Delta C) = C^T log Delta) and every power of it: `frame_difference` and
# `compose_frames` commute with the rewrite, as the linear algebra on d does.


def canonical_frames(q: Array) -> Array:
    """``q`` with ``w >= 0`` (the sign `clip_means` stores; ``q`` and ``-q`` are one rotation)."""
    return jnp.where(q[..., :1] < 0, -q, q)


def frame_difference(frames_a: Float[Array, "*B K 4"], frames_b: Float[Array, "*B K 4"]) -> Float[Array, "*B K 4"]:
    """``Delta = M_b^-1 M_a`` per joint (wxyz, ``w >= 0``): ``M_b Delta = M_a``."""
    d = rotations.quat_multiply(rotations.quat_conjugate(frames_b), frames_a)
    return canonical_frames(rotations.quat_normalize(d))


def compose_frames(frames: Float[Array, "K 4"], deltas: Float[Array, "N K 4"],
                   weights: Float[Array, " N"]) -> Float[Array, "K 4"]:
    """``M exp(sum_k w_k log Delta_k)`` per joint: for one difference the geodesic power
    ``M Delta^w`` (``w = 0``: ``M``; ``w = 1``: ``M Delta``). The logs add, so several differences
    commute and the result is smooth in ``w`` (finite derivatives at ``w = 0`` and at ``Delta = I``:
    the library's Taylor-branch log and exp)."""
    logs = rotations.expmap_from_quat(jnp.asarray(deltas, frames.dtype))  # [N, K, 3], angle <= pi
    v = jnp.sum(jnp.asarray(weights, frames.dtype)[:, None, None] * logs, axis=0)
    return canonical_frames(rotations.quat_multiply(frames, rotations.quat_from_expmap(v)))


def features_at(d: Float[Array, "T C"], frames: Float[Array, "T K 4"], cols: np.ndarray) -> Float[Array, "T C"]:
    """`from_tangent` with one set of frames per sample (a transition's slerped means)."""
    return jax.vmap(lambda x, m: from_tangent(x[None], m, cols)[0])(d, frames)


def model_columns(model) -> np.ndarray:
    """Static ``[K, 3]`` tangent triples of a tangent model (or characteristic)."""
    return triples(tuple(model.channel_names), model.offset.shape[-1], model.frames.shape[-2])


# Unuma's polar form per joint. A joint's harmonic n is the complex 3-vector z = u + i v (the
# channels' phasors `(A cos phi, A sin phi)`); a change of joint frame maps z to C^T z, which
# leaves the Hermitian product <y, x> = sum_i x_i conj(y_i) alone. Its argument, the phase of x
# relative to y, is the one phase per joint and harmonic that the polar form turns along the
# shorter arc (for a single channel it is the wrapped phi_x - phi_y of Unuma's polar form), and
# the rest moves linearly: so the polar algebra commutes with the rewrite, as the phasor one does.


def joint_phasors(c: Float[Array, "*B C N 2"], cols: np.ndarray) -> Float[Array, "*B K 3 N 2"]:
    """The channels' phasors grouped by joint triple."""
    return c[..., cols, :, :]


def relative_phase(x: Float[Array, "*B K 3 N 2"], y: Float[Array, "*B K 3 N 2"]) -> Float[Array, "*B K N"]:
    """``arg <y, x>`` per joint and harmonic (0 where the product vanishes; finite gradients)."""
    re = jnp.sum(x[..., 0] * y[..., 0] + x[..., 1] * y[..., 1], axis=-2)
    im = jnp.sum(x[..., 1] * y[..., 0] - x[..., 0] * y[..., 1], axis=-2)
    return _safe_atan2(im, re)


def turn_phase(z: Float[Array, "*B K 3 N 2"], angle: Float[Array, "*B K N"]) -> Float[Array, "*B K 3 N 2"]:
    """``z e^{i angle}`` (every channel of a joint by the same angle)."""
    c, s = jnp.cos(angle)[..., None, :], jnp.sin(angle)[..., None, :]
    return jnp.stack([z[..., 0] * c - z[..., 1] * s, z[..., 0] * s + z[..., 1] * c], axis=-1)


def polar_interpolate(za, zb, s):
    """Per-joint polar eq. 3: ``e^{i s D} ((1 - s) z_a + s z_b e^{-i D})``, ``D = arg <z_a, z_b>``
    (``s = 0``: ``z_a``; ``s = 1``: ``z_b``)."""
    d = relative_phase(zb, za)
    return turn_phase((1 - s) * za + s * turn_phase(zb, -d), s * d)


def polar_difference(za, zb):
    """Per-joint polar characteristic: ``(D, z_a e^{-i D} - z_b)``, ``D = arg <z_b, z_a>``."""
    d = relative_phase(za, zb)
    return d, turn_phase(za, -d) - zb


def polar_superpose(z, phases, aligned, w):
    """``e^{i sum w_k D_k} (z + sum_k w_k aligned_k)`` (phases ``[N_k, ...]``, aligned ``[N_k, ...]``):
    ``z_b`` with one difference of ``(a, b)`` at weight 1 gives ``z_a``."""
    wa = w.reshape((-1,) + (1,) * (aligned.ndim - 1))
    wp = w.reshape((-1,) + (1,) * (phases.ndim - 1))
    return turn_phase(z + jnp.sum(wa * aligned, axis=0), jnp.sum(wp * phases, axis=0))


def relative_rotvecs(reference: Float[Array, "*B K 4"], frames: Float[Array, "*B K 4"]) -> Float[Array, "*B K 3"]:
    """``log(R^-1 M)`` per joint (angle <= pi): the frames as rotation vectors about a reference,
    linear near it (a change of rig maps them as it maps ``d``)."""
    q = rotations.quat_multiply(rotations.quat_conjugate(jnp.asarray(reference, frames.dtype)), frames)
    return rotations.expmap_from_quat(q)


def frames_from_rotvecs(reference: Float[Array, "*B K 4"], v: Float[Array, "*B K 3"]) -> Float[Array, "*B K 4"]:
    """Inverse of `relative_rotvecs`: ``R exp(v)`` (wxyz, ``w >= 0``)."""
    q = rotations.quat_multiply(jnp.asarray(reference, v.dtype), rotations.quat_from_expmap(v))
    return canonical_frames(q)
