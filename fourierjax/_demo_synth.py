"""The demo's state and its fitting and synthesis steps (`fourierjax.demo` runs them)."""

from __future__ import annotations

import dataclasses
import pathlib
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from fourierjax.demo import DemoConfig

#: The bundled clips the demo fits, with the role each plays (CMU descriptions).
WALKS = {"07_01": "walk", "07_04": "slow walk", "07_12": "brisk walk", "02_01": "walk"}
RUNS = {"02_03": "run/jog", "09_01": "run", "09_02": "run"}

class _Skip(Exception):
    """A demo part cannot run (missing module or input); the message says why."""


@dataclasses.dataclass
class _State:
    out: pathlib.Path
    cfg: DemoConfig
    log: Callable[[str], None]
    motions: dict = dataclasses.field(default_factory=dict)
    fits: dict = dataclasses.field(default_factory=dict)
    ground: dict = dataclasses.field(default_factory=dict)
    written: dict = dataclasses.field(default_factory=lambda: {"models": [], "bvh": [],
                                                                 "stance": [], "plots": [],
                                                                 "gifs": []})
    skipped: list = dataclasses.field(default_factory=list)
    bvh_positions: dict = dataclasses.field(default_factory=dict)
    extra: dict = dataclasses.field(default_factory=dict)

    def path(self, kind: str, name: str) -> pathlib.Path:
        d = self.out / kind
        d.mkdir(parents=True, exist_ok=True)
        p = d / name
        self.written[kind].append(str(p.relative_to(self.out)))
        return p


def _need(st: _State, *clips: str) -> None:
    missing = [c for c in clips if c not in st.fits]
    if missing:
        raise _Skip(f"needs the fitted clip(s) {missing} (not in --clips)")


def _import(name: str):
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError as err:
        raise _Skip(f"module {name} is not available ({err})") from None


# ------------------------------------------------------------------------------------ fitting


def _crop(motion, multiple: int = 64):
    """The middle of a clip, cut to a multiple of ``multiple`` frames.

    Clips of equal length share every compiled function on the fitting path (XLA compiles per
    array shape), which keeps the demo fast; the bundled cmu_mb clips are steady walks and runs
    throughout, so the middle is as good as the whole.
    """
    F = motion.num_frames
    keep = max(multiple, (F // multiple) * multiple) if F >= multiple else F
    a = (F - keep) // 2
    return motion[a : a + keep], a


def _fit(st: _State) -> None:
    from fourierjax import __version__, data
    from fourierjax.io import model_io
    from fourierjax.motion import fit_motions

    starts = {}
    for c in st.cfg.clips:
        st.motions[c], starts[c] = _crop(data.load(c))
    fits = fit_motions([st.motions[c] for c in st.cfg.clips], st.cfg.harmonics, "euler",
                       segment=False, throw=True)
    for c, f in zip(st.cfg.clips, fits, strict=True):
        st.fits[c] = f
        rest = data.describe(c)["rest_frames"]
        prov = dict(f.summary(), clip=c, fourierjax_version=__version__, command="demo",
                    file_frames_used=[rest + starts[c] + f.frame_start,
                                      rest + starts[c] + f.frame_stop])
        model_io.save_model(st.path("models", f"{c}.npz"), f.model, motion=st.motions[c],
                            provenance=prov, alignment=f.alignment)


def _ground_of(st: _State, clip: str):
    """(foot points, groin joints, sole clearance [2, P]) of a clip's skeleton, from its body map."""
    if clip in st.ground:
        return st.ground[clip]
    from fourierjax import contacts, gait
    from fourierjax.motion import foot_positions_of

    m = st.motions[clip]
    bm = st.fits[clip].body_map if clip in st.fits else None
    if bm is None:
        from fourierjax.body import infer_body_map

        bm = infer_body_map(m)
    pts = contacts.foot_points(m.topology, bm)
    g = contacts.estimate_ground(foot_positions_of(m, pts), m.frame_time_s)
    st.ground[clip] = (pts, gait.groin_joints(m.topology, body_map=bm), contacts.sole_clearance(g))
    return st.ground[clip]


# ---------------------------------------------------------------------------------- synthesis


def _num_frames(st: _State, clip: str) -> tuple[int, float]:
    dt = st.fits[clip].frame_time_s
    return max(2, int(round(st.cfg.seconds / dt))), dt


def _padded(st: _State, model):
    """Every synthesized model padded to N + 3 harmonics: one compilation serves them all."""
    from fourierjax import style

    return style.pad_harmonics(model, st.cfg.harmonics + 3)


def _write_motion(st: _State, name: str, motion, *, kind: str = "bvh") -> None:
    from fourierjax.io.bvh import write_bvh

    write_bvh(motion, st.path(kind, f"{name}.bvh"))
    st.bvh_positions[name] = motion


def _gait_bvh(st: _State, name: str, clip: str, model, **kw) -> dict:
    """Synthesize with step constraints and root motion (`fourierjax.gait`) and write a BVH."""
    gait = _import("fourierjax.gait")
    pts, groins, clear = _ground_of(st, clip)
    T, dt = _num_frames(st, clip)
    m = st.motions[clip]
    r = gait.synthesize_gait(_padded(st, model), m.skeleton(), T, dt, feet=pts, groins=groins,
                             clearance=clear, **kw)
    _write_motion(st, name, _import("fourierjax.io.gait_bvh").gait_motion(m[:1], r, model.channel_names, dt))
    lowest = np.asarray(r.lowest).min(axis=1)
    # Flight is the hip rule's (N(t) > gait), as in `synth`'s summary: foot locking may lift a
    # foot that the leg cannot reach, which is not flight (that is `feet_off_floor_fraction`:
    # no foot within the library's contact band, 2% of the body height, of the floor; a fixed
    # 1e-3 units counted a foot 0.06 mm up as off the floor, 0.7 of walk_normal's frames).
    fit = st.fits.get(clip)
    bm = fit.body_map if fit is not None and fit.body_map is not None else None
    if bm is None:
        from fourierjax.body import infer_body_map

        bm = infer_body_map(m)
    info = {"flight_fraction": float(np.mean(np.asarray(r.hip.flight) > 0.5)),
            "feet_off_floor_fraction": float(np.mean(lowest > 0.02 * bm.height)),
            "distance_units": float(np.hypot(*(np.asarray(r.root_position[-1] - r.root_position[0])[[0, 2]])))}
    return info


def _features_bvh(st: _State, name: str, clip: str, features, channel_names, dt) -> None:
    from fourierjax.motion import motion_from_features

    m = st.motions[clip]
    _write_motion(st, name, motion_from_features(m[:1], np.asarray(features, np.float64),
                                                 channel_names, dt))


def _style_models(st: _State):
    from fourierjax import style

    _need(st, "07_01", "07_04")
    normal, tired = st.fits["07_01"].model, st.fits["07_04"].model
    return normal, tired, style


def _synth_walks(st: _State) -> None:
    normal, tired, style = _style_models(st)
    st.extra["walk_normal"] = _gait_bvh(st, "walk_normal", "07_01", normal)
    # Unuma Fig. 3: s < 0 on the normal -> tired axis is "brisk"; s > 1 "more tired than tired".
    _gait_bvh(st, "walk_brisk_extrapolated", "07_01", style.interpolate(normal, tired, -0.6))
    _gait_bvh(st, "walk_tired", "07_01", style.interpolate(normal, tired, 1.3))
    from fourierjax._demo_footprints import footprints  # before/after foot locking (issue 21)

    footprints(st)


def _synth_run(st: _State) -> None:
    from fourierjax import style

    _need(st, "07_01", "07_12", "02_03")
    brisk = style.characteristic(st.fits["07_12"].model, st.fits["07_01"].model)
    run = st.fits["02_03"].model
    # Unuma eq. 8: run + 1.37 (brisk walk - normal walk).
    _gait_bvh(st, "run_brisk_superposed", "02_03", style.superpose(run, [brisk], [1.37]),
              gait=0.06, jump=1.0)


def _synth_transitions(st: _State) -> None:
    import jax.numpy as jnp

    from fourierjax import fourier, style

    _need(st, "02_01", "02_03")
    walk, run = st.fits["02_01"].model, st.fits["02_03"].model
    T, dt = _num_frames(st, "02_01")
    t = jnp.arange(2 * T) * dt
    dur = 0.4 * T * dt
    # Start at a cycle boundary of the first gait (theta a multiple of 2 pi: a left heel strike).
    for name, a, b in (("walk_to_run", walk, run), ("run_to_walk", run, walk)):
        period = 2 * np.pi / float(a.omega)
        start = period * max(1, round(0.6 * T * dt / period))
        x = style.transition(a, b, t, start, dur)
        _features_bvh(st, name, "02_01", x, walk.channel_names, dt)
    del fourier


def _synth_steps(st: _State) -> None:
    _need(st, "07_01", "09_01")
    normal, run = st.fits["07_01"].model, st.fits["09_01"].model
    T, _ = _num_frames(st, "07_01")
    _gait_bvh(st, "walk_long_steps", "07_01", normal, step=1.35)
    _gait_bvh(st, "walk_short_steps", "07_01", normal, step=0.6)
    # speed -> 0 over the second half: the walker comes smoothly to rest.
    u = np.clip((np.arange(T) / T - 0.4) / 0.5, 0, 1)
    _gait_bvh(st, "walk_slowing_to_stop", "07_01", normal, speed=1 - u * u * (3 - 2 * u))
    st.extra["run_flight"] = _gait_bvh(st, "run_flight", "09_01", run, gait=0.06, jump=1.0)
    st.extra["run_high_jump"] = _gait_bvh(st, "run_high_jump", "09_01", run, gait=0.03,
                                          jump=2.5)
    _gait_bvh(st, "run_flight_continuous_rule", "09_01", run, gait=0.06, jump=1.0,
              rule="continuous")


def _synth_noise(st: _State) -> None:
    import jax
    import jax.numpy as jnp

    from fourierjax import fourier, style

    _need(st, "07_01")
    normal = st.fits["07_01"].model
    amp = np.where(fourier.angle_channel_mask(normal.channel_names),
                   np.radians(st.cfg.noise_deg), 0.0)
    shiver = style.add_noise(normal, jax.random.key(st.cfg.seed), jnp.asarray(amp, jnp.float32),
                             harmonics=3)
    _gait_bvh(st, "walk_shivering", "07_01", shiver)
