"""Implicit differentiation of the eq. 5 optimum, shared by the free and the bounded solver."""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax._linalg import matmul, spd_solve
from fourierjax.stance import _util as u
from fourierjax.stance._objective import objective
from fourierjax.stance._problem import StanceProblem


def solve_spd(H: Float[Array, "n n"], rhs: Float[Array, " n"]) -> Float[Array, " n"]:
    """Solve H x = rhs for the small SPD Hessian with a relative ridge of 1e-10 against a
    singular pivot.

    Not a bare `_linalg.spd_solve(H, rhs)` (which eliminates on `[H | rhs]`): the inverse is
    formed from H alone by `spd_solve(H, I)` and applied to `rhs` by a product. In the implicit
    JVP rules H holds primal values and `rhs` is a tangent: the result is then visibly linear in
    the tangent, which reverse mode must transpose. Eliminating on `[H | rhs]` puts both in one
    loop carry, and `jax.grad` through a solve failed to transpose it.

    Arguments:
        H: `[n, n]` symmetric positive (semi-)definite matrix.
        rhs: `[n]` right-hand side.

    Returns:
        `[n]` solution.
    """
    eye = jnp.eye(H.shape[0], dtype=H.dtype)
    ridge = 1e-10 * (jnp.max(jnp.abs(jnp.diagonal(H))) + 1e-30)
    return matmul(spd_solve(H + ridge * eye, eye), rhs[:, None])[:, 0]


def implicit_terms(y: Float[Array, " n"], problem: StanceProblem, dp) -> tuple[Float[Array, "n n"], Float[Array, " n"]]:
    """`(H, mixed)` at an optimum y of eq. 5: the (symmetrised) Hessian in y and
    `(d grad_y f / dp) dp`, both from one linearisation of grad_y f.

    Arguments:
        y: the optimum's offsets; problem: its `StanceProblem`; dp: a tangent of `problem`.

    Returns:
        `(H [n, n], mixed [n])`; then dy* = -H^-1 mixed (implicit function theorem).
    """
    _, lin = jax.linearize(jax.grad(objective), y, problem)
    zero_p = u.zero_tangent(problem)
    H = jax.vmap(lambda e: lin(e, zero_p))(jnp.eye(y.shape[0], dtype=y.dtype))
    return 0.5 * (H + H.T), lin(jnp.zeros_like(y), dp)
