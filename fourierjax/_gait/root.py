"""Root motion (Unuma 1995 §3.1 step and speed): scaled steps, integrated phase, and the root
path carried by the feet on the ground."""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from fourierjax._math import safe_sqrt

if TYPE_CHECKING:
    from fourierjax.fourier import FourierModel


def apply_step(model: FourierModel, step: Float[ArrayLike, ""]) -> FourierModel:
    """Unuma 1995 §3.1 *step*: replace every `A_n` (n ≥ 1) by `step · A_n`.

    Arguments:
        model: a `FourierModel`.
        step: scalar (≥ 0; 1 leaves the model as is).

    Returns:
        The scaled model (offsets, phases and ω unchanged).
    """
    return eqx.tree_at(lambda m: m.amplitude, model, model.amplitude * step)


def integrate_phase(
    speed: Float[ArrayLike, "*T"],
    omega: Float[ArrayLike, ""],
    num_frames: int,
    frame_time_s: float,
    phase0: Float[ArrayLike, ""] = 0.0,
) -> Float[Array, " T"]:
    """Unuma 1995 §3.1 *speed*: the cycle phase integrated frame by frame.

    Frame `k` is at phase `phase0 + ω · Δt · Σ_{i<k} speed_i`: `speed` scales the time step
    Δτ through the cycle, so changing it (even to 0) never jumps the pose; at `speed = 1` the
    phase is `ω · k Δt` exactly as `synthesize` computes it.

    Arguments:
        speed: scalar or `[T]` schedule (dimensionless; 1 = the captured pace).
        omega: fundamental in rad/s.
        num_frames: T.
        frame_time_s: Δt in seconds.
        phase0: phase of frame 0 (radians).

    Returns:
        `[T]` phases in radians.
    """
    speed = jnp.broadcast_to(jnp.asarray(speed, dtype=jnp.result_type(float)), (num_frames,))
    ticks = jnp.concatenate([jnp.zeros((1,), speed.dtype), jnp.cumsum(speed)[:-1]])
    return phase0 + omega * (ticks * frame_time_s)


#: `root_trajectory` with the model's root velocity: a foot point whose move in the capture's
#: world is below this fraction of the mean captured root move is still (planted).
_SLIP_FRACTION = 0.15
#: ... and its slip at that fraction weighs as much as `_SLIP_PER_TAU` temperatures of height.
_SLIP_PER_TAU = 0.1


def _norm(v: Array) -> Array:
    return safe_sqrt(jnp.sum(v * v, axis=-1), floor=1e-24)


def _slip(xz: Array, flight_step: Array) -> Array:
    """`[T-1, K]` horizontal move of each point in the model's own world per frame."""
    return _norm(xz[1:] - xz[:-1] + flight_step[:, None, :])


#: `root_trajectory` with the model's root velocity: the least fraction of the model's own move
#: (along its direction) that a stance move keeps.
_MIN_ALONG = 0.1


def root_trajectory(
    foot_local: Float[Array, "T 2 P 3"],
    height: Float[Array, " T"],
    phase: Float[Array, " T"],
    clearance: Float[ArrayLike, "2 P"],
    *,
    up_axis: int = 1,
    contact_threshold: Float[ArrayLike, ""] | None = None,
    temperature: Float[ArrayLike, ""] | None = None,
    flight_step: Float[Array, "T-1 2"] | None = None,
    pelvis_height: Float[Array, " T"] | None = None,
    stance: Float[Array, " T"] | None = None,
) -> Float[Array, "T 3"]:
    """Root positions over time from the feet on the ground (the carrying foot point stays put).

    Between two frames the root moves horizontally by minus the displacement of the foot point
    that carries the body: a soft argmin (temperature τ) over both feet's points. A planted
    point therefore stays put, and a rolling foot hands over from heel to toe tip without a
    jump (each move compares the *same* point at both frames).

    - With `flight_step` (the model's own root move, `synthesize_gait`, `ground_features`) the
      carrying point is the one planted in the model's own world, low *and* still: its cost is
      its height over τ plus its move in that world (`flight_step + Δxz_p`) over
      `_SLIP_PER_TAU · _SLIP_FRACTION` of the mean root move. Where no point is still (its
      move is above `_SLIP_FRACTION` of the mean root move: a run's flight, which the walk
      rule's height hides) the root moves with `flight_step`. The lowest point alone carried
      the body on a landing heel still swinging forward and on a run's trailing foot in
      flight: root speeds were 0.72-0.90 of the captured on the bundled walks and runs (02_03
      0.72, 09_01 0.74, 07_01 0.85), 0.96-1.00 with the planted point (measured from the
      models and from the captures' own poses alike).
    - With `stance` too (`[T]` in [0, 1]) the ground weight is at least `stance`: there the
      carrying point moves the root even where it slips in the model's own world. For frames
      whose root velocity does not match their stride: a transition's blend of two models
      (`style.grounded_transition`), where the stance foot of 02_03 -> 02_01 slipped 9-16
      units/s in the blend's own world, the slip test read its stance as flight and the root
      kept the blend's own speed (31 units/s) while that foot slid 8.5 units over its stance.
    - Without it, the carrying point is the lowest, and where even that is above
      `contact_threshold` (flight) the root keeps its last velocity per radian of phase, so it
      comes to rest with the phase.

    Arguments:
        foot_local: `[T, 2, P, 3]` foot points with the pelvis at the origin (root rotation
            applied, translation not).
        height: `[T]` root height above the ground (e.g. `root_height`).
        phase: `[T]` cycle phase of each frame (radians).
        clearance: `[2, P]` sole clearances.
        up_axis: index of the up axis.
        contact_threshold: height (file units) below which the lowest point is on the
            ground; default `0.03 · s`, `s` the mean pelvis height above the ground (CMU:
            ~0.5 units ≈ 3 cm).
        temperature: τ in file units; default `0.003 · s` (CMU: ~0.05 units).
        flight_step: optional `[T - 1, 2]` horizontal root moves to use in flight instead of
            the carried velocity (`synthesize_gait` passes the model's own root velocity);
            it also chooses the carrying point (above). Every stance move keeps at least 10%
            of `flight_step` along its direction (the deficit is added), so the root never
            reverses (a run's landing foot dragged the pelvis back: 09_01, -45 units/s).
        pelvis_height: `[T]` the pelvis's height above the ground, the length scale `s` of
            the defaults; default `height` (the root is the pelvis, as on CMU rigs). The root
            is not always the pelvis: Bandai's `joint_Root` sits below the feet of a model, and
            a negative scale made τ < 0, so the soft argmin picked the highest point, the
            swing foot, which carried the body backwards at twice its speed (a moonwalk).

    Returns:
        `[T, 3]` root positions; horizontal components start at 0, the up component is
        `height`. Where the support hands over (heel to toe, foot to foot) the soft argmin
        mixes points that move differently, and the carrying point slides for a few frames.
    """
    T = foot_local.shape[0]
    # Scale-relative defaults; differentiated like everything else (true derivatives).
    scale = jnp.mean(height if pelvis_height is None else pelvis_height)
    th = 0.03 * scale if contact_threshold is None else contact_threshold
    tau = 0.003 * scale if temperature is None else temperature
    y = foot_local[..., up_axis]
    h = height[:, None, None] + y - jnp.broadcast_to(clearance, y.shape)  # [T, 2, P]
    h_mid = (0.5 * (h[1:] + h[:-1])).reshape(T - 1, -1)
    w = jax.nn.softmax(-h_mid / tau, axis=-1)
    horiz = [k for k in range(3) if k != up_axis]
    xz = foot_local[..., horiz].reshape(T, -1, 2)
    stance_step = -jnp.sum(w[..., None] * (xz[1:] - xz[:-1]), axis=1)  # [T-1, 2]
    low = -tau * jax.nn.logsumexp(-h_mid / tau, axis=-1)  # soft min height
    ground = jax.nn.sigmoid((th - low) / (0.1 * th))  # 1 on the ground, 0 in flight
    dphase = phase[1:] - phase[:-1]

    if flight_step is not None:
        # The carrying point: low and still in the model's own world (see the docstring).
        slip = _slip(xz, flight_step)  # [T-1, 2P], file units per frame
        ref = _SLIP_FRACTION * jnp.mean(_norm(flight_step)) + 1e-3 * tau
        cost = h_mid / tau + slip / (ref * _SLIP_PER_TAU)
        w = jax.nn.softmax(-cost, axis=-1)
        stance_step = -jnp.sum(w[..., None] * (xz[1:] - xz[:-1]), axis=1)
        # Flight also where no point is still (a run's flight under the walk rule): soft min
        # of the slip over the low points, against `_SLIP_FRACTION` of the captured move.
        low_slip = jnp.sum(w * slip, axis=-1)
        # Against the stance baseline: the slip of the stillest 5% of the frames, 0 for a
        # model as fitted, |step - 1| of the root move for stepped amplitudes (`apply_step`:
        # the feet sweep `step` times as far as the root channels move the pelvis; without it
        # a step of 1.3 read as flight and the root kept the model's own speed).
        base = jax.lax.stop_gradient(jnp.quantile(low_slip, 0.05))
        ground = ground * jax.nn.sigmoid((ref + base - low_slip) / (0.2 * ref))
        if stance is not None:
            # Where the caller knows a foot is in stance, its feet carry the root whatever
            # their slip in the model's own world (`stance`, see the docstring).
            ground = jnp.maximum(ground, 0.5 * (stance[1:] + stance[:-1]))
        # A foot may not carry the root backwards against the model's own travel: a run's
        # landing foot, lowest while still swinging forward, dragged the pelvis back (09_01
        # defaults: -45 units/s, 64 of 480 frames). Each stance move keeps at least
        # `_MIN_ALONG` of the model's move along its direction (the deficit is added), so the
        # root never reverses and the landing foot slides only by the deficit.
        f2 = jnp.sum(flight_step * flight_step, axis=-1)
        along = jnp.sum(stance_step * flight_step, axis=-1) / (f2 + 0.01 * jnp.mean(f2) + 1e-30)
        stance_step = stance_step + jnp.maximum(_MIN_ALONG - along, 0.0)[:, None] * flight_step
        moves = ground[:, None] * stance_step + (1.0 - ground[:, None]) * flight_step
    else:

        def body(vel, inputs):
            step, a, dth = inputs
            # Velocity per radian of phase, learned on the ground; shim the 0/0 at rest.
            moving = jnp.abs(dth) > 1e-12
            safe = jnp.where(moving, dth, 1.0)
            vel_new = jnp.where((a > 0.5) & moving, step / safe, vel)
            return vel_new, a * step + (1.0 - a) * vel * dth

        vel0 = jnp.zeros((2,), foot_local.dtype)
        _, moves = jax.lax.scan(body, vel0, (stance_step, ground, dphase))
    path = jnp.concatenate([jnp.zeros((1, 2), moves.dtype), jnp.cumsum(moves, axis=0)])
    out = jnp.zeros((T, 3), foot_local.dtype)
    out = out.at[:, horiz[0]].set(path[:, 0]).at[:, horiz[1]].set(path[:, 1])
    return out.at[:, up_axis].set(height)
