"""Derivatives of a solved stance w.r.t. the intensity knob and a reach target (Neff & Fiume 2004,
sec. 6; implicit differentiation through the optimum) against central finite differences."""

import jax
import jax.numpy as jnp
import numpy as np

from fourierjax.stance.shape_sets import get_shape_set
from fourierjax.stance.skeleton48 import dof_vector, make_body
from fourierjax.stance.solver import solve_stance

# Right-hand targets (x, y; z is a parameter): one the arm reaches with a lean, one it cannot.
TARGETS_XY = ((-0.35, 1.05), (-0.4, 1.2))
PARAMS = ((0.3, 0.55), (0.3, 2.5))  # (intensity, target z)


def test_solved_pose_derivatives_match_finite_differences(x64):
    body = make_body(1.75)
    posture = get_shape_set("posture")

    def solved(params, xy):
        """The 48 DOF of the solved pose, its objective and reach error, for [intensity, z]."""
        target = jnp.stack([xy[0], xy[1], params[1]])
        prob = posture.problem(body, params[0], target_right=target)
        sol = solve_stance(prob, rtol=1e-11, atol=1e-11)
        return jnp.concatenate([dof_vector(sol.pose), sol.objective[None], sol.reach_error_m[:1]])

    p, xy = jnp.array(PARAMS), jnp.array(TARGETS_XY)
    f = jax.jit(jax.vmap(solved))
    # One compiled program for both targets. Forward mode: the reverse mode of the same
    # implicit rule compiles about 1.5x longer (minutes on 2 cores; see the issue notes).
    jac = np.asarray(jax.jit(jax.vmap(jax.jacfwd(solved)))(p, xy))  # [2, 50, 2]
    assert np.all(np.isfinite(np.asarray(f(p, xy)))) and np.all(np.isfinite(jac))

    def central(k, h):
        return (np.asarray(f(p.at[:, k].add(h), xy)) - np.asarray(f(p.at[:, k].add(-h), xy))) / (2 * h)

    # Richardson-extrapolated central differences (error O(h^4)) from h = 1e-3, 2e-3: smaller steps drown
    # in the solver's stopping noise (~1e-9 in the pose) in the unreachable case (measured: FD of
    # one DOF 0.029212 at h = 1e-3, 0.029274 at 1e-4, 0.02777 at 1e-5, implicit 0.029214), and
    # plain central differences at 1e-3 are off by up to 6e-5 relative where the pose curves.
    fd = np.stack([(4 * central(k, 1e-3) - central(k, 2e-3)) / 3 for k in range(2)], axis=-1)
    scale = np.maximum(np.abs(fd), 1.0)
    np.testing.assert_allclose(jac / scale, fd / scale, atol=2e-5)
    # Not trivially zero: the intensity moves the spine, the target the arm (and the torso).
    assert np.abs(jac[..., 0]).max() > 0.1 and np.abs(jac[..., 1]).max() > 0.1


def test_reverse_mode_through_the_solvers_traces():
    # The implicit JVP rules must be linear in the tangents in a form JAX can transpose:
    # `jax.grad` through `solve_stance` once failed ("AssertionError: ValAccum ...") because
    # the 6x6 solve eliminated on [H | tangent] in one loop. Tracing the reverse pass is
    # enough to catch that (compiling it takes ~100 s on 2 cores, as for jacfwd); the values
    # equal forward mode's (the same linear map, transposed).
    from fourierjax.stance.bounded import solve_stance_bounded

    body = make_body(1.75)
    posture = get_shape_set("posture")

    def f(i, target):
        sol = solve_stance(posture.problem(body, i, target_right=target))
        return sol.objective + jnp.sum(sol.pose.root_position)

    def g(i):
        lo, hi = jnp.full(6, -0.4), jnp.full(6, 0.4)
        return solve_stance_bounded(posture.problem(body, i), lo, hi).objective

    target = jnp.array([-0.3, 1.2, 0.4])
    jax.make_jaxpr(jax.grad(f, argnums=(0, 1)))(0.5, target)
    jax.make_jaxpr(jax.grad(g))(0.5)
