"""Full-precision matrix products and small SPD solves in plain jnp (batched LAPACK hangs on 2 CPU cores)."""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

#: Precision of every matrix product fourierjax computes. XLA's default on GPUs with
#: TensorFloat-32 (Ampere, Hopper) rounds float32 operands to 10 mantissa bits: measured on an
#: H100, `fourier.synthesize` (one product) then differed from the elementwise
#: `synthesize_batch` by up to 2.5e-4 on channels of magnitude ~3, and a fit's normal equations
#: lose as much. CPUs compute float32 products in full either way (same results, same program).
PRECISION = jax.lax.Precision.HIGHEST


def matmul(a: Array, b: Array) -> Array:
    """`a @ b` at full float32 (or float64) precision on every backend (`PRECISION`).

    Arguments:
        a: `[..., n, m]` array.
        b: `[..., m, p]` array.

    Returns:
        `[..., n, p]` product.
    """
    return jnp.matmul(a, b, precision=PRECISION)


def spd_solve(G: Float[Array, "P P"], rhs: Float[Array, "P K"]) -> Float[Array, "P K"]:
    """Solve ``G x = rhs`` for symmetric positive definite ``G`` in plain jnp (no LAPACK call).

    Gauss-Jordan elimination on ``[G | rhs]`` without pivoting (the pivots of an SPD matrix
    are its positive Schur complements, clamped at ``tiny`` like a Cholesky diagonal). One
    small fori_loop: it compiles in half the time of a Cholesky factorisation and two
    triangular solves (three loops), and it appears once per call site of every fit.

    Arguments:
        G: `[P, P]` symmetric positive definite matrix.
        rhs: `[P, K]` right-hand sides.

    Returns:
        `[P, K]` solutions.
    """
    P = G.shape[-1]
    M = jnp.concatenate([G, rhs], axis=1)
    is_row = jnp.eye(P, dtype=bool)

    def body(j, M):
        row = M[j] / jnp.maximum(M[j, j], jnp.finfo(M.dtype).tiny)
        return jnp.where(is_row[j][:, None], row[None, :], M - M[:, j][:, None] * row[None, :])

    return jax.lax.fori_loop(0, P, body, M)[:, P:]
