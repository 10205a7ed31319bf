"""Style space (Tilmanne & Dutoit; Troje 2002): style vectors, PCA and least-squares style weights."""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from fourierjax import rotations
from fourierjax._checks import concrete
from fourierjax._fourier import _tangent
from fourierjax._jit import filter_jit
from fourierjax._linalg import spd_solve
from fourierjax._style._common import (
    channel_kinds,
    check_compatible,
    check_finite,
    check_log_omega,
    check_models_omega,
    check_scalar,
    dtype_of,
    num_harmonics,
    phasor,
    polar_from_phasor,
    replace,
    turns,
)
from fourierjax._style.characteristics import (
    Characteristic,
    pad_harmonics,
    stack,
    stacked_characteristics,
)
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel


def style_vector_core(model, reference=None):
    """The style vector of one model (unchecked, not jitted); a tangent model's frames as
    rotation vectors about `reference` (`[K, 4]`, default its own frames)."""
    c = phasor(model) / jnp.sqrt(2.0)  # [C, N, 2]
    per_channel = jnp.concatenate([model.offset[:, None], jnp.reshape(c, (c.shape[0], -1))], axis=1)
    parts = [jnp.reshape(per_channel, (-1,))]
    if model.representation == "tangent":
        ref = model.frames if reference is None else reference
        parts.append(jnp.reshape(_tangent.relative_rotvecs(ref, model.frames), (-1,)))
    return jnp.concatenate([*parts, jnp.log(model.omega)[None]])


_style_vector = filter_jit(style_vector_core)


def _reference(where: str, model, reference):
    """`reference` for a tangent model (None: keep the default), checked; None otherwise."""
    if model.representation != "tangent":
        if reference is not None:
            raise UserError(f"{where}: `reference` (clip-mean frames) is for tangent models only")
        return None
    if reference is None:
        return None
    reference = jnp.asarray(reference, dtype=dtype_of(model))
    if reference.shape != model.frames.shape[-2:]:
        raise UserError(f"{where}: `reference` must be [K, 4] (wxyz, one per joint, like the "
                        f"model's frames {model.frames.shape[-2:]}), got shape {reference.shape}")
    return check_finite(where, "reference", reference)


def style_vector(model: FourierModel, *, reference: Float[ArrayLike, "K 4"] | None = None) -> Float[Array, " dim"]:
    """The flat style vector of one model (Tilmanne & Dutoit §2.2: C × 5 + 1 = 271 numbers for
    54 channels and N = 2), in PHASOR coordinates.

    Layout: per channel `[A0, re_1, im_1, …, re_N, im_N]` with `(re, im) = A(cos φ, sin φ)/√2`,
    channels in order, then `log ω`. Why not Tilmanne's raw `(p, φ)`: phases wrap (the mean of
    3.0 and −3.0 is 0, the wrong way round) and are undefined at zero amplitude, so linear
    combinations and PCA of raw phases are meaningless; phasors add like the signals do. The
    `1/√2` makes the Euclidean norm match the signal (Parseval): for two models with the same
    ω, `|v_A − v_B|²` (without the last entry) is the mean over one cycle of
    `Σ_c (Θ_A,c(θ) − Θ_B,c(θ))²`. The fundamental enters as `log ω` (unscaled).

    Tangent models (`representation="tangent"`, `R_j = M_j exp(d_j)`): the channels hold the
    tangent coordinates `d`, and the joints' clip means follow as rotation vectors
    `log(R_j⁻¹ M_j)` about a reference `R` (`[K · 3]`, before `log ω`), linear near it. Compare
    or combine only vectors taken about one reference (`style_matrix` uses the first model's
    frames); the default, the model's own frames, gives zeros there. A change of rig maps the
    vector by a rotation per joint (`d' = C_jᵀ d`, `log' = C_jᵀ log`), so distances between
    vectors, and PCA, are the same on every rig.

    Arguments:
        model: FourierModel with `C` channels and `N` harmonics.
        reference: tangent models only: `[K, 4]` wxyz frames the clip means are taken about
            (default the model's own).

    Returns:
        `[C (1 + 2N) + 1]` (tangent: `[C (1 + 2N) + 3K + 1]`). Raises `UserError` when
        `model.omega` is not finite and > 0 (`log ω` would be −inf or NaN; under jit, from
        `eqx.error_if`).
    """
    reference = _reference("style_vector", model, reference)
    model = check_models_omega("style_vector", model=model)
    return _style_vector(model, reference)


def _vector_size(like) -> int:
    c, n = like.amplitude.shape[-2:]
    k = like.frames.shape[-2] if like.representation == "tangent" else 0
    return c * (1 + 2 * n) + 3 * k + 1


def model_from_style_vector(vector: Float[ArrayLike, " dim"], like: FourierModel, *,
                            reference: Float[ArrayLike, "K 4"] | None = None) -> FourierModel:
    """Inverse of `style_vector`: a FourierModel shaped like `like` (channels, harmonics and
    static fields) from a style vector, e.g. a PCA reconstruction.

    Arguments:
        vector: `[C (1 + 2N) + 1]` (tangent: `[C (1 + 2N) + 3K + 1]`).
        like: a FourierModel giving C, N and the static fields.
        reference: tangent models only: the frames the vector's rotation vectors are about
            (default `like.frames`: `style_matrix`'s reference when `like` is its first model).

    Returns:
        A FourierModel.
    """
    reference = _reference("model_from_style_vector", like, reference)
    c, n = like.amplitude.shape
    vector = jnp.asarray(vector, dtype=dtype_of(like))
    size = _vector_size(like)
    if vector.shape != (size,):
        raise UserError(
            f"model_from_style_vector: `vector` has shape {vector.shape}, expected "
            f"({size},) for {c} channels and {n} harmonics"
            + (f" and {like.frames.shape[-2]} joint frames" if like.representation == "tangent" else "")
        )
    return _model_from_style_vector(vector, like, reference)


@filter_jit
def _model_from_style_vector(vector, like, reference=None):
    c, n = like.amplitude.shape
    per_channel = jnp.reshape(vector[: c * (1 + 2 * n)], (c, 1 + 2 * n))
    amplitude, phase = polar_from_phasor(jnp.reshape(per_channel[:, 1:], (c, n, 2)) * jnp.sqrt(2.0))
    out = replace(like, offset=per_channel[:, 0], amplitude=amplitude, phase=phase, omega=jnp.exp(vector[-1]))
    if like.representation == "tangent":
        ref = like.frames if reference is None else reference
        v = jnp.reshape(vector[c * (1 + 2 * n):-1], (like.frames.shape[-2], 3))
        out = replace(out, frames=_tangent.frames_from_rotvecs(ref, v))
    return out


def style_matrix(models, *, reference: Float[ArrayLike, "K 4"] | None = None) -> Float[Array, "models dim"]:
    """Stack models into a matrix of style vectors (one row per model, see `style_vector`).

    Arguments:
        models: a sequence of compatible FourierModels (harmonic counts are padded to the
            largest) or a stacked batch (leading axis).
        reference: tangent models only: the frames every row's clip means are taken about
            (default the first model's; `model_from_style_vector(row, like=models[0])` inverts).

    Returns:
        `[M, C (1 + 2N) + 1]` (tangent: `[M, C (1 + 2N) + 3K + 1]`).
    """
    if isinstance(models, Sequence):
        models = stack(models)
    reference = _reference("style_matrix", models, reference)
    if models.representation == "tangent" and reference is None:
        reference = models.frames[0]
    models = check_models_omega("style_matrix", models=models)
    return _style_matrix(models, reference)


@filter_jit
def _style_matrix(models, reference=None):
    return eqx.filter_vmap(lambda m: style_vector_core(m, reference))(models)


class StylePCA(eqx.Module):
    """Principal components of a set of style vectors (Troje 2002; Tilmanne & Dutoit).

    Attributes:
        mean: `[D]`, the mean style vector.
        components: `[K, D]`, orthonormal principal directions, largest variance first (sign
            fixed so that each direction's largest-magnitude entry is positive).
        explained_variance: `[K]`, variance along each direction (divided by `M − 1`).
        explained_variance_ratio: `[K]`, fraction of the total variance.
    """

    mean: Float[Array, " dim"]
    components: Float[Array, "k dim"]
    explained_variance: Float[Array, " k"]
    explained_variance_ratio: Float[Array, " k"]


def style_pca(matrix: Float[ArrayLike, "models dim"], num_components: int | None = None) -> StylePCA:
    """PCA over style vectors (rows of `style_matrix`).

    Arguments:
        matrix: `[M, D]` with `M ≥ 2`.
        num_components: how many to keep (default `min(M − 1, D)`, the rank of the centred
            data).

    Returns:
        A StylePCA.
    """
    matrix = jnp.asarray(matrix)
    if matrix.ndim != 2 or matrix.shape[0] < 2:
        raise UserError(f"style_pca: `matrix` has shape {matrix.shape}; need [M, D] with at least 2 rows")
    m, d = matrix.shape
    k = min(m - 1, d) if num_components is None else int(num_components)
    if not 1 <= k <= min(m, d):
        raise UserError(f"style_pca: `num_components`={num_components}; must be in 1..{min(m, d)}")
    return _style_pca(matrix, k)


@filter_jit
def _style_pca(matrix, k: int):
    mean = jnp.mean(matrix, axis=0)
    centred = matrix - mean[None, :]
    _, sv, vt = jnp.linalg.svd(centred, full_matrices=False)
    signs = jnp.sign(vt[jnp.arange(vt.shape[0]), jnp.argmax(jnp.abs(vt), axis=1)])
    vt = vt * jnp.where(signs == 0, 1.0, signs)[:, None]
    var = sv**2 / (matrix.shape[0] - 1)
    total = jnp.sum(var)
    return StylePCA(
        mean=mean,
        components=vt[:k],
        explained_variance=var[:k],
        explained_variance_ratio=var[:k] / jnp.where(total > 0, total, 1.0),
    )


def pca_project(pca: StylePCA, vectors: Float[ArrayLike, "*batch dim"]) -> Float[Array, "*batch k"]:
    """Coordinates of style vectors in the principal basis: `(v − mean) · components`.

    Arguments:
        pca: a StylePCA.
        vectors: `[..., D]`.

    Returns:
        `[..., K]`.
    """
    vectors = jnp.asarray(vectors)
    d = pca.mean.shape[-1]
    if vectors.ndim < 1 or vectors.shape[-1] != d:
        raise UserError(
            f"pca_project: `vectors` must be [..., {d}] style vectors (the PCA's dimension), "
            f"got shape {vectors.shape}"
        )
    centred = vectors - jnp.broadcast_to(pca.mean, vectors.shape)
    components = jnp.broadcast_to(pca.components, (*vectors.shape[:-1], *pca.components.shape))
    return jnp.sum(centred[..., None, :] * components, axis=-1)


def pca_reconstruct(pca: StylePCA, coords: Float[ArrayLike, "*batch k"]) -> Float[Array, "*batch dim"]:
    """Style vectors from principal coordinates: `mean + coords · components`.

    Arguments:
        pca: a StylePCA.
        coords: `[..., K]`.

    Returns:
        `[..., D]` (map back to a model with `model_from_style_vector`).
    """
    coords = jnp.asarray(coords)
    k = pca.components.shape[-2]
    if coords.ndim < 1 or coords.shape[-1] != k:
        raise UserError(
            f"pca_reconstruct: `coords` must be [..., {k}] (one per principal component), "
            f"got shape {coords.shape}"
        )
    components = jnp.broadcast_to(pca.components, (*coords.shape[:-1], *pca.components.shape))
    combo = jnp.sum(coords[..., :, None] * components, axis=-2)
    return jnp.broadcast_to(pca.mean, combo.shape) + combo


@filter_jit
def _fit_style_weights(base, chars, target, ridge, include_omega: bool):
    scale = 1.0 / jnp.sqrt(2.0)
    k, c, n, _ = chars.phasor.shape
    tangent = base.representation == "tangent"
    euler, _ = channel_kinds(base)
    # Offsets on one branch, as `superpose` adds them (tangent coordinates have none).
    char_offset = chars.offset if tangent else chars.offset - jnp.where(
        jnp.asarray(euler)[None, :], turns(chars.offset), 0.0)
    # Columns: style-space direction of each characteristic in phasor coordinates; the
    # phasor superposition is linear in w, so least squares is exact and closed form.
    cols = jnp.concatenate([char_offset[:, :, None], jnp.reshape(chars.phasor * scale, (k, c, 2 * n))], axis=2)
    cols = jnp.reshape(cols, (k, -1))
    reference = None
    if tangent:
        # Frames about the base's: superpose puts them at exp(Σ w_k log Δ_k), linear in w.
        reference = base.frames
        cols = jnp.concatenate([cols, jnp.reshape(rotations.expmap_from_quat(chars.frames), (k, -1))], axis=1)
    residual = style_vector_core(target, reference)[:-1] - style_vector_core(base, reference)[:-1]
    if include_omega:
        cols = jnp.concatenate([cols, chars.log_omega[:, None]], axis=1)
        residual = jnp.concatenate([residual, (jnp.log(target.omega) - jnp.log(base.omega))[None]])
    gram = jnp.sum(cols[:, None, :] * cols[None, :, :], axis=-1)
    rhs = jnp.sum(cols * residual[None, :], axis=-1)
    # Relative jitter keeps the elimination defined for collinear characteristics.
    jitter = 10 * jnp.finfo(gram.dtype).eps * jnp.trace(gram) / k + jnp.finfo(gram.dtype).tiny
    return spd_solve(gram + (ridge + jitter) * jnp.eye(k, dtype=gram.dtype), rhs[:, None])[:, 0]


def fit_style_weights(
    base: FourierModel,
    characteristics: Characteristic | Sequence[Characteristic],
    target: FourierModel,
    *,
    ridge: ArrayLike = 0.0,
    include_omega: bool = True,
) -> Float[Array, " k"]:
    """Style weights that best explain `target` as `base + Σ w_k characteristic_k`.

    Least squares in phasor style space (see `style_vector`): minimises
    `|style_vector(superpose(base, chars, w, method="phasor")) − style_vector(target)|²`, which
    (by Parseval) is the mean squared angle error over one cycle, plus `(log ω)²` mismatch when
    `include_omega`. The problem is linear in `w`, so the solution is closed form (normal
    equations, `K × K`, solved without LAPACK); differentiable in every input. Fit the target
    clip first (`fourierjax.fourier`), aligned to the same gait event as the characteristics.
    Tangent models: the frames enter as rotation vectors about the base's
    (`log(M_base⁻¹ M_target)` against `Σ w_k log Δ_k`, what `superpose` composes), so the
    problem stays linear and exact for a phasor superposition.

    Arguments:
        base: FourierModel the characteristics are added to.
        characteristics: one Characteristic, a sequence, or a stacked batch `[K, ...]`.
        target: FourierModel of the motion to explain (same channels and representation).
        ridge: Tikhonov weight `λ ≥ 0` added to the normal matrix (use > 0 when
            characteristics are nearly collinear).
        include_omega: also match `log ω`.

    Returns:
        `[K]` weights.
    """
    check_compatible(base, target, names=("base", "target"))
    chars = stacked_characteristics(characteristics)
    check_compatible(base, chars, names=("base", "characteristics"))
    if base.representation == "tangent" and chars.frames is None:
        raise UserError("fit_style_weights: the tangent characteristics have no `frames`; recompute "
                        "them with style.characteristic(a, b)")
    base, target = check_models_omega("fit_style_weights", base=base, target=target)
    chars = check_log_omega("fit_style_weights", chars)
    n = max(num_harmonics(base), num_harmonics(chars), num_harmonics(target))
    base, chars, target = (pad_harmonics(x, n) for x in (base, chars, target))
    ridge = check_scalar("fit_style_weights", "ridge", ridge)
    r = concrete(ridge)
    message = "fit_style_weights: `ridge` must be >= 0 (a Tikhonov weight)"
    if r is None:
        ridge = eqx.error_if(ridge, ridge < 0, message)
    elif r < 0:
        raise UserError(f"{message}, got {r.item()!r}")
    ridge = jnp.asarray(ridge, dtype=dtype_of(base))
    return _fit_style_weights(base, chars, target, ridge, bool(include_omega))
