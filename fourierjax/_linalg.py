"""Small linear solves in plain jnp (no LAPACK: batched LAPACK calls hang on 2 CPU cores, STYLE.md)."""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float


def spd_solve(G: Float[Array, "P P"], rhs: Float[Array, "P K"]) -> Float[Array, "P K"]:
    """Solve ``G x = rhs`` for symmetric positive definite ``G`` in plain jnp (no LAPACK call).

    Gauss-Jordan elimination on ``[G | rhs]`` without pivoting (the pivots of an SPD matrix
    are its positive Schur complements, clamped at ``tiny`` like a Cholesky diagonal). One
    small fori_loop: it compiles in half the time of a Cholesky factorisation and two
    triangular solves (three loops), and it appears once per call site of every fit.
    """
    P = G.shape[-1]
    M = jnp.concatenate([G, rhs], axis=1)
    is_row = jnp.eye(P, dtype=bool)

    def body(j, M):
        row = M[j] / jnp.maximum(M[j, j], jnp.finfo(M.dtype).tiny)
        return jnp.where(is_row[j][:, None], row[None, :], M - M[:, j][:, None] * row[None, :])

    return jax.lax.fori_loop(0, P, body, M)[:, P:]
