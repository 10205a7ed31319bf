"""The pose a stance problem builds (sec. 5) and its balance solve, with implicit derivatives."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax import rotations
from fourierjax._linalg import PRECISION, matmul
from fourierjax.stance import _util as u
from fourierjax.stance._problem import NUM_AMPLITUDES, P, StanceProblem, desired_balance_point
from fourierjax.stance.arms import arm_free, arm_to_target
from fourierjax.stance.balance import inverse_2x2, newton_2d_with_tangents
from fourierjax.stance.gaze import gaze_rotation
from fourierjax.stance.ik import lower_body_ik
from fourierjax.stance.skeleton48 import (
    ANKLE,
    COLLAR,
    ELBOW,
    HIP,
    JOINT_NAMES,
    KNEE,
    LEFT,
    RIGHT,
    SHOULDER,
    SPINE,
    WRIST,
    J,
    StancePose,
    center_of_mass_matrices,
)
from fourierjax.stance.torso import collar_quats, spine_quats


def _pair(x, joints: tuple[int, int]):
    """`x[joints]` for a (right, left) pair of joint indices, stacked."""
    return jnp.stack([x[joints[RIGHT]], x[joints[LEFT]]])


class PoseInfo(eqx.Module):
    """What `build_pose` measures on the way (all world, metres)."""

    com: Float[Array, "3"]
    shoulders: Float[Array, "2 3"]
    wrists: Float[Array, "2 3"]
    reach_gaps: Float[Array, "2"]
    free_foot_gap: Float[Array, ""]


def build_rotations(
    problem: StanceProblem, amplitudes: Float[Array, "6"], balance_xz: Float[Array, "2"]
) -> tuple[Float[Array, "3"], Float[Array, "joints 3 3"], PoseInfo]:
    """`build_pose` on rotation matrices: `(root_position, local rotations [J, 3, 3], info)`."""
    body, s = problem.body, problem.shape
    sag, cor, trans, cy, cz, abx = (amplitudes[i] for i in range(NUM_AMPLITUDES))
    lb = lower_body_ik(
        body,
        problem.feet,
        jnp.stack([s[P["knee_right"]], s[P["knee_left"]]]),
        balance_xz,
        jnp.stack([s[P["pelvis_x"]], s[P["pelvis_y"]], s[P["pelvis_z"]]]),
        problem.dominant,
    )
    off = body.offsets
    L = [None] * len(JOINT_NAMES)
    L[0] = lb.pelvis
    for k in (RIGHT, LEFT):
        L[HIP[k]], L[KNEE[k]], L[ANKLE[k]] = lb.hips[k], lb.knees[k], lb.ankles[k]
    spine = spine_quats(sag, cor, trans, abx, problem.sagittal_weights, problem.coronal_weights)
    for i, j in enumerate(SPINE):
        L[j] = spine[i]
    collars = collar_quats(cy, cz, problem.collar_signs)
    # World frames are built along the way (the arm IK and gaze need some of them), so the
    # pose needs no separate forward kinematics: fewer XLA kernels in the solver's loop.
    Rw, Pw = [lb.pelvis], [lb.root_position]  # pelvis, abdomen, chest, neck, head
    for j in SPINE[:3]:  # abdomen, chest, neck
        Rw.append(u.mm(Rw[-1], L[j]))
        Pw.append(Pw[-1] + u.mv(Rw[-2], off[j]))
    R_chest, p_chest, R_neck = Rw[2], Pw[2], Rw[3]
    p_head = Pw[3] + u.mv(R_neck, off[J["head"]])
    # Legs: world frames from the IK (the feet keep their planted orientation); the ankles
    # by forward kinematics, as a free foot the leg cannot reach is not on its mark.
    R_thigh, R_shin, R_foot = lb.thighs, lb.shins, lb.feet
    p_hip = lb.hip_positions
    p_knee = p_hip + u.mv(R_thigh, _pair(off, KNEE))
    p_ankle = p_knee + u.mv(R_shin, _pair(off, ANKLE))
    # Both arms at once (a leading axis of 2: right, left): one copy of the arm IK in the graph.
    L[COLLAR[RIGHT]], L[COLLAR[LEFT]] = collars[RIGHT], collars[LEFT]
    R_collars = u.mm(R_chest[None], collars)
    arm_off = {name: _pair(off, idx) for name, idx in (("collar", COLLAR), ("shoulder", SHOULDER),
                                                        ("elbow", ELBOW), ("wrist", WRIST))}  # fmt: skip
    p_collars = p_chest[None] + u.mv(R_chest[None], arm_off["collar"])
    shoulders = p_collars + u.mv(R_collars, arm_off["shoulder"])
    sides = jnp.array([-1.0, 1.0], off.dtype)  # the arm's outside is -X (right), +X (left)

    def arm_params(*names):
        return jnp.stack([s[P[n]] for n in names])

    R_sh_t, R_el_t, gap = jax.vmap(arm_to_target)(
        shoulders,
        R_collars,
        u.safe_norm(arm_off["elbow"]),
        u.safe_norm(arm_off["wrist"]),
        problem.targets,
        arm_params("swivel_right", "swivel_left"),
        lb.pelvis[None, :, 0] * sides[:, None],
    )
    R_sh_f, R_el_f = jax.vmap(arm_free)(
        arm_params("elbow_right", "elbow_left"), arm_params("arm_out_right", "arm_out_left"), sides
    )
    on = problem.target_active > 0.5
    R_sh = u.where(on[:, None, None], R_sh_t, R_sh_f)
    R_el = u.where(on[:, None, None], R_el_t, R_el_f)
    R_upper = u.mm(R_collars, R_sh)
    R_fore = u.mm(R_upper, R_el)
    p_elbow = shoulders + u.mv(R_upper, arm_off["elbow"])
    wrists = p_elbow + u.mv(R_fore, arm_off["wrist"])
    for k in (RIGHT, LEFT):
        L[SHOULDER[k]], L[ELBOW[k]] = R_sh[k], R_el[k]
        L[WRIST[k]] = jnp.eye(3, dtype=off.dtype)
    L[J["head"]] = gaze_rotation(
        spine[3], R_neck, p_head, problem.gaze_point, s[P["gaze_weight"]]
    )
    Rw.append(u.mm(R_neck, L[J["head"]]))
    Pw.append(p_head)
    local = jnp.stack(L)
    # The COM by blocks of joints that are contiguous in the skeleton, each block one batched
    # product (`center_of_mass_matrices` with `first`): world frames [side, joint] of the arms
    # (collar, shoulder, elbow, wrist) and legs (hip, knee, ankle), and pelvis..head. Neither
    # the 19 frames stacked into one array (40 more XLA kernels in the solver's loop) nor
    # summed one by one (~250 traced operations).
    stack = functools.partial(jnp.stack, axis=1)
    blocks = (
        (jnp.stack(Rw), jnp.stack(Pw), J["pelvis"]),
        (stack([R_collars, R_upper, R_fore, R_fore]), stack([p_collars, shoulders, p_elbow, wrists]), COLLAR[RIGHT]),
        (stack([R_thigh, R_shin, R_foot]), stack([p_hip, p_knee, p_ankle]), HIP[RIGHT]),
    )
    info = PoseInfo(
        com=sum(center_of_mass_matrices(body, R, pos, first) for R, pos, first in blocks),
        shoulders=shoulders,
        wrists=wrists,
        reach_gaps=u.where(on, gap, 0.0),
        free_foot_gap=lb.free_foot_gap_m,
    )
    return lb.root_position, local, info


# `build_rotations` sums the COM by blocks of joints that must be contiguous, row-major.
assert [J[n] for n in ("pelvis", "abdomen", "chest", "neck", "head")] == list(range(5))
assert [c + i for c in (COLLAR[RIGHT], COLLAR[LEFT]) for i in range(4)] == [
    idx[k] for k in (RIGHT, LEFT) for idx in (COLLAR, SHOULDER, ELBOW, WRIST)
] == list(range(COLLAR[RIGHT], COLLAR[RIGHT] + 8))
assert [idx[k] for k in (RIGHT, LEFT) for idx in (HIP, KNEE, ANKLE)] == list(range(HIP[RIGHT], HIP[RIGHT] + 6))

def build_pose(
    problem: StanceProblem, amplitudes: Float[Array, "6"], balance_xz: Float[Array, "2"]
) -> tuple[StancePose, PoseInfo]:
    """The pose for given torso amplitudes and dominant-ankle balance offsets (sec. 5).

    Lower body by the analytic IK (`ik`), spine and collars from the shape classes
    (`torso`), arms by the analytic arm IK or elbow angle and arm-out without a target
    (`arms`), head by gaze (`gaze`).

    Returns:
        `(pose, info)`.
    """
    root, local, info = build_rotations(problem, amplitudes, balance_xz)
    return StancePose(root, rotations.quat_from_matrix(local)), info

class BalancedBuild(eqx.Module):
    """A pose built with its balance solved (`balanced_rotations`), on rotation matrices.

    - `balance_xz`: `[2]` dominant-ankle X/Z offsets (rad).
    - `root_position`: `[3]`; `local`: `[J, 3, 3]` local rotations; `info`: `PoseInfo`.
    """

    balance_xz: Float[Array, "2"]
    root_position: Float[Array, "3"]
    local: Float[Array, "joints 3 3"]
    info: PoseInfo

    def pose(self) -> StancePose:
        """The `StancePose` (quaternions)."""
        return StancePose(self.root_position, rotations.quat_from_matrix(self.local))


def build_with_residual(problem: StanceProblem, amplitudes, balance_xz):
    """`(com_xz - goal, (root, local, info))` for given amplitudes and balance offsets.

    The builder is traced with jit disabled: most `jax.numpy` functions (the array operators
    included) are small jitted functions, and inside the solver's loop each one would be traced,
    differentiated and batched as a nested program before being inlined. Traced as bare
    primitives the program is the same (identical optimised HLO) and its trace ~15% shorter
    (stance benchmark: 0.98 -> 0.83 s of the single solve's first call). The builder holds no
    `lax` loop, which disabled jit would unroll (guarded by a test in tests/test_stance_ik.py).
    """
    with jax.disable_jit():
        root, local, info = build_rotations(problem, amplitudes, balance_xz)
    r = jnp.stack([info.com[0], info.com[2]]) - desired_balance_point(problem)
    return r, (root, local, info)


def build_output_like(dtype):
    """Zeros shaped like `build_with_residual`'s output (saves tracing the builder for it)."""
    def z(*shape):
        return jnp.zeros(shape, dtype)

    info = PoseInfo(com=z(3), shoulders=z(2, 3), wrists=z(2, 3), reach_gaps=z(2), free_foot_gap=z())
    return z(2), (z(3), z(len(JOINT_NAMES), 3, 3), info)


#: Most Newton evaluations of the balance solve (`balance.newton_2d_with_tangents`, which
#: stops earlier at float32 round-off).
BALANCE_EVALUATIONS = 12


def balanced_rotations_with_tangents(
    problem: StanceProblem, amplitudes: Float[Array, "6"], directions: Float[Array, "m 6"]
) -> tuple[BalancedBuild, BalancedBuild]:
    """`balanced_rotations` and its derivatives along `m` directions in the amplitudes.

    One traced copy of the pose builder serves the balance solve and the derivatives (see
    `balance.newton_2d_with_tangents`): the solver's objective gets its gradient from this
    in forward mode with `directions` = the 6x6 identity. The tangents follow the implicit
    function theorem: along a direction da the balance offsets move by db = -J_b^-1 dr and
    the pose by its partial derivative plus J_pose,b db.

    Returns:
        `(built, d_built)`: `d_built` has a leading `m` axis on every leaf.
    """
    m = directions.shape[0]
    b0 = jnp.zeros(2, amplitudes.dtype)
    b, (_, out), (dr, dout) = newton_2d_with_tangents(
        lambda a, x: build_with_residual(problem, a, x),
        amplitudes, b0, directions, BALANCE_EVALUATIONS,
        out_like=build_output_like(amplitudes.dtype),
    )
    db = -matmul(inverse_2x2(dr[m:].T), dr[:m].T).T  # [m, 2]
    dout = jax.tree.map(lambda t: t[:m] + jnp.tensordot(db, t[m:], axes=1, precision=PRECISION), dout)
    return BalancedBuild(b, *out), BalancedBuild(db, *dout)


@jax.custom_jvp
def balanced_rotations(problem: StanceProblem, amplitudes: Float[Array, "6"]) -> BalancedBuild:
    """The pose (`build_rotations`) with the balance offsets solved (sec. 4).

    For a static pose the paper searches for the dominant-ankle offsets; we solve
    `com_xz(offsets) = goal` by Newton's method from zero offsets, with the exact 2x2
    Jacobian from forward-mode derivatives (`balance.newton_2d_with_tangents`). Derivatives
    come from the implicit function theorem in a custom JVP: one linearisation of the pose
    at the solution gives both the exact 2x2 Jacobian J_b of the residual in the offsets
    and the tangents of the pose, d offsets = -J_b^-1 dr, so no derivative runs through the
    iterations. Reverse mode and higher orders work.
    """
    none = jnp.zeros((0, NUM_AMPLITUDES), amplitudes.dtype)
    return balanced_rotations_with_tangents(problem, amplitudes, none)[0]


@balanced_rotations.defjvp
def _balanced_rotations_jvp(primals, tangents):
    problem, amplitudes = primals
    dp, da = tangents
    # Through the custom JVP itself, so that a second derivative (the implicit adjoint of
    # the solver) uses this rule again instead of differentiating Newton's iterations.
    b = balanced_rotations(problem, amplitudes).balance_xz
    (_, out), lin = jax.linearize(build_with_residual, problem, amplitudes, b)
    zp, za = u.zero_tangent(problem), u.zero_tangent(amplitudes)
    dr_b, dout_b = jax.vmap(lambda e: lin(zp, za, e))(jnp.eye(2, dtype=b.dtype))
    dr, dout = lin(dp, da, jnp.zeros_like(b))
    db = -matmul(inverse_2x2(dr_b.T), dr)
    dout = jax.tree.map(lambda t, tb: t + jnp.tensordot(db, tb, axes=1, precision=PRECISION), dout, dout_b)
    return BalancedBuild(b, *out), BalancedBuild(db, *dout)


def balance_offsets(problem: StanceProblem, amplitudes: Float[Array, "6"]) -> Float[Array, "2"]:
    """Dominant-ankle X/Z offsets (rad) that put the COM projection on the desired point."""
    return balanced_rotations(problem, amplitudes).balance_xz


def balanced_pose(
    problem: StanceProblem, amplitudes: Float[Array, "6"]
) -> tuple[StancePose, PoseInfo, Float[Array, "2"]]:
    """`build_pose` with the balance offsets solved (`balanced_rotations`).

    Returns:
        `(pose, info, balance_xz)`.
    """
    built = balanced_rotations(problem, amplitudes)
    return built.pose(), built.info, built.balance_xz
