"""Style features of fitted clips for recognition: joint-angle harmonics and body-space (FK) harmonics, in groups."""

from __future__ import annotations

import numpy as np

#: Feature groups, in the order `features` concatenates them.
GROUPS = ("angles", "positions", "timing", "quat", "sixd")
#: Rotation channels of the `quat` and `sixd` groups.
ROTATION_KINDS = ("quat", "sixd")


def _cycle_rotations_fn():
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from fourierjax import features as fx
    from fourierjax import fourier

    @eqx.filter_jit
    def cycle_rotations(model, skeleton, pelvis: int, num_samples: int):
        phase = jnp.arange(num_samples, dtype=model.amplitude.dtype) * (2 * jnp.pi / num_samples)
        f = fourier.synthesize_phase(model, phase)
        return jax.vmap(lambda x: fx.local_pose_from_features(skeleton, x, model.representation, pelvis)[1])(f)

    return cycle_rotations


_CYCLE_ROTATIONS = []


def _rotation_harmonics(model, skeleton, body_map, num_harmonics: int, num_samples: int = 32):
    """Fourier coefficients over one cycle of every joint's local rotation as a unit quaternion
    (on one hemisphere per joint, continuous over the cycle) and as the 6-D representation (the
    first two columns of its matrix; Zhou et al. 2019). The pelvis is in the heading frame.

    Returns ``{"quat": [J, 4, 1 + 2 N], "sixd": [J, 6, 1 + 2 N]}``.
    """
    from fourierjax import rotations

    if not _CYCLE_ROTATIONS:
        _CYCLE_ROTATIONS.append(_cycle_rotations_fn())
    q = np.asarray(_CYCLE_ROTATIONS[0](model, skeleton, int(body_map.pelvis), num_samples), float)  # [K, J, 4]
    for k in range(1, num_samples):  # continuity over the cycle (q and -q are one rotation)
        q[k] *= np.where((q[k] * q[k - 1]).sum(-1, keepdims=True) < 0, -1.0, 1.0)
    q *= np.where(q.mean(0, keepdims=True)[..., :1] < 0, -1.0, 1.0)  # one hemisphere: w of the mean >= 0
    r = np.asarray(rotations.matrix_from_quat(q), float)  # [K, J, 3, 3]
    six = np.concatenate([r[..., :, 0], r[..., :, 1]], axis=-1)  # [K, J, 6]
    out = {}
    for name, v in (("quat", q), ("sixd", six)):
        c = np.fft.rfft(v, axis=0) / num_samples
        h = c[1 : num_harmonics + 1] * 2
        out[name] = np.concatenate([c[:1].real, h.real, h.imag], axis=0).transpose(1, 2, 0)
    return out


def _position_harmonics(model, skeleton, body_map, num_harmonics: int, num_samples: int = 32):
    """Fourier coefficients over one cycle of the pelvis-relative joint positions, per leg length.

    Returns ``[J, 3, 1 + 2 N]``: the mean and ``(re, im)`` of harmonics ``1..N`` of every
    joint coordinate in the heading frame, divided by the body map's leg length, so rigs of
    different sizes and units compare.
    """
    from fourierjax import style

    p = style.cycle_positions(model, skeleton, num_samples=num_samples, body_map=body_map)
    p = np.asarray(p, float)  # [K, J, 3]
    p = (p - p[:, body_map.pelvis : body_map.pelvis + 1]) / body_map.leg_length
    c = np.fft.rfft(p, axis=0) / num_samples  # [K/2+1, J, 3]
    h = c[1 : num_harmonics + 1] * 2
    return np.concatenate([c[:1].real, h.real, h.imag], axis=0).transpose(1, 2, 0)


def _angle_harmonics(model, skip):
    """Per rotation channel: the offset (wrapped to (-pi, pi]) and the harmonics' phasors; a tangent
    model's channels are about each joint's clip mean, so its clip means follow (each as the first
    two columns of its matrix, continuous at any angle)."""
    from fourierjax import rotations

    off = np.asarray(model.offset, float)
    amp, ph = np.asarray(model.amplitude, float), np.asarray(model.phase, float)
    keep = np.array([not any(n.startswith(s) for s in skip) for n in model.channel_names])
    off = np.angle(np.exp(1j * off))
    re, im = amp * np.cos(ph), amp * np.sin(ph)
    out = np.concatenate([off[:, None], re, im], axis=1)[keep].ravel()
    if model.frames is None:
        return out
    r = np.asarray(rotations.matrix_from_quat(model.frames), float)  # [K, 3, 3]
    return np.concatenate([out, r[..., :, 0].ravel(), r[..., :, 1].ravel()])


def _timing(model, body_map):
    """Cadence and stride: log omega, travel per cycle and root height per leg length, root height sway."""
    names = list(model.channel_names)
    off, amp = np.asarray(model.offset, float), np.asarray(model.amplitude, float)
    omega = float(model.omega)
    vx, vz, y = (names.index(n) for n in ("root.vx", "root.vz", "root.y"))
    stride = np.hypot(off[vx], off[vz]) * 2 * np.pi / omega / body_map.leg_length
    return np.array([np.log(omega), stride, off[y] / body_map.leg_length, *(amp[y] / body_map.leg_length)])


def features(model, skeleton, body_map, *, num_harmonics: int | None = None) -> dict[str, np.ndarray]:
    """The feature groups of one fitted clip (flat arrays, see `GROUPS`).

    ``angles``: the joint-angle channels (the root's velocity and height channels left out; a
    tangent model's tangent coordinates and its joints' clip means);
    ``positions``: body-space harmonics of the pelvis-relative joint positions through FK, per
    leg length (rig- and unit-independent); ``timing``: cadence, stride and root height;
    ``quat`` and ``sixd``: harmonics of the joints' rotations as quaternions and in 6-D.
    """
    n = model.amplitude.shape[1] if num_harmonics is None else num_harmonics
    rot = _rotation_harmonics(model, skeleton, body_map, n)
    return {"angles": _angle_harmonics(model, ("root.",)),
            "positions": _position_harmonics(model, skeleton, body_map, n).ravel(),
            "timing": _timing(model, body_map),
            **{k: rot[k].ravel() for k in ROTATION_KINDS}}


def feature_matrix(feats, groups=GROUPS):
    """Rows of concatenated feature groups and the column weights that balance them.

    Arguments:
        feats: one `features` dict per clip; groups: the keys to concatenate, in order.

    Returns:
        ``(x [M, D], column_weights [D])``: a group of ``d`` columns gets the weight
        ``1 / sqrt(d)``, to apply after z-scoring (`classify(..., column_weights=)`), so that
        each group counts the same and not by its size.
    """
    x = np.concatenate([np.stack([f[g] for f in feats]) for g in groups], 1)
    w = np.concatenate([np.full(feats[0][g].size, 1 / np.sqrt(feats[0][g].size)) for g in groups])
    return x, w
