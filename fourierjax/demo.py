"""The `fourierjax demo` pipeline: fit the bundled CMU clips, synthesize styled gaits, plot, animate.

`run_demo(out_dir)` writes, under ``out_dir``:

* ``models/<clip>.npz``: fitted Fourier models (versioned model files, `fourierjax.model_io`);
* ``bvh/*.bvh``: synthesized motions (normal, brisk and tired walks by inter/extrapolation
  (Unuma 1995 eq. 3), a brisk run by superposition (eq. 8), walk->run and run->walk
  transitions, step/speed/gait/jump variants (Unuma §3.1), a shivering walk (§3.3));
* ``stance/*.bvh``: the expressive-stance gallery (Neff & Fiume 2004), when `fourierjax.stance`
  provides shape sets;
* ``plots/*.png``: spectrum (Tilmanne & Dutoit Fig. 1), decomposition (their Fig. 3), the
  inter/extrapolation strip (Unuma Fig. 3), the style-space PCA scatter, the hip-rule
  comparison, the posture range (Neff & Fiume Fig. 5), a crowd of 10,000 fitted walkers of
  different styles (`motion.channel_model`, `fourierjax.crowd`);
* ``gifs/*.gif``: animated stick figures of the main results;
* ``summary.json``: fit metrics per clip, what was written, what was skipped and why.

A part whose library module is missing is skipped with a printed notice (the rest still runs).
This is an edge module (files, plots); the core never imports it.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
import sys
import time
from collections.abc import Callable

import numpy as np

from fourierjax.errors import UserError
from fourierjax.io.atomic import write_bytes_atomic

__all__ = ["DemoConfig", "run_demo", "WALKS", "RUNS"]

#: The bundled clips the demo fits, with the role each plays (CMU descriptions).
WALKS = {"07_01": "walk", "07_04": "slow walk", "07_12": "brisk walk", "02_01": "walk"}
RUNS = {"02_03": "run/jog", "09_01": "run", "09_02": "run"}


@dataclasses.dataclass(frozen=True)
class DemoConfig:
    """Settings of the demo (defaults: the full demo).

    - ``harmonics``: N of every fitted model (Unuma: 3 to 7; Tilmanne: 2).
    - ``seconds``: length of each synthesized BVH motion.
    - ``clips``: the bundled clips to fit (must include 07_01, 07_04, 07_12, 02_01, 02_03 and
      09_01 for every part to run; others are skipped with a notice when absent).
    - ``gif_frames``, ``gif_dpi``: size of the animations.
    - ``gifs``, ``stance``: switch those parts off.
    - ``crowd``: characters in the crowd of fitted walkers (0: no crowd).
    """

    harmonics: int = 3
    seconds: float = 4.0
    clips: tuple[str, ...] = tuple(WALKS) + tuple(RUNS)
    gif_frames: int = 40
    gif_dpi: int = 64
    gifs: bool = True
    stance: bool = True
    crowd: int = 10_000
    noise_deg: float = 2.0
    seed: int = 0


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
    from fourierjax import __version__, data, model_io
    from fourierjax.motion import fit_motions

    starts = {}
    for c in st.cfg.clips:
        st.motions[c], starts[c] = _crop(data.load(c))
    fits = fit_motions([st.motions[c] for c in st.cfg.clips], st.cfg.harmonics, "euler",
                       segment=False)
    for c, f in zip(st.cfg.clips, fits, strict=True):
        st.fits[c] = f
        rest = data.describe(c)["rest_frames"]
        prov = dict(f.summary(), clip=c, fourierjax_version=__version__, command="demo",
                    file_frames_used=[rest + starts[c] + f.frame_start,
                                      rest + starts[c] + f.frame_stop])
        model_io.save_model(st.path("models", f"{c}.npz"), f.model, motion=st.motions[c],
                            provenance=prov, alignment=f.alignment)


def _ground_of(st: _State, clip: str):
    """(foot points, groin joints, sole clearance [2, P]) of a clip's skeleton."""
    if clip in st.ground:
        return st.ground[clip]
    from fourierjax import contacts, gait
    from fourierjax.motion import foot_positions_of

    m = st.motions[clip]
    pts = contacts.foot_points(m.topology)
    g = contacts.estimate_ground(foot_positions_of(m, pts), m.frame_time_s)
    st.ground[clip] = (pts, gait.groin_joints(m.topology), contacts.sole_clearance(g))
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
    _write_motion(st, name, gait.gait_motion(m[:1], r, model.channel_names, dt))
    lowest = np.asarray(r.lowest).min(axis=1)
    info = {"flight_fraction": float(np.mean(lowest > 1e-3)),
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


# -------------------------------------------------------------------------------------- plots


def _plot_spectrum(st: _State) -> None:
    from fourierjax import viz
    from fourierjax.motion import joint_expmaps
    from fourierjax.spectrum import windowed_amplitude_spectrum

    _need(st, "07_01")
    f = st.fits["07_01"]
    sub = st.motions["07_01"][f.frame_start:f.frame_stop]
    x, names = joint_expmaps(sub)
    moving = np.ptp(x, axis=0) > 1e-4
    freqs, amp = windowed_amplitude_spectrum(x[:, moving], sub.frame_time_s)
    fig = viz.plot_spectrum(freqs, amp, fundamental_hz=f.fundamental_hz, max_hz=8.0,
                            title=f"CMU 07_01 walk: spectra of {int(moving.sum())} exponential-map "
                            "values (cf. Tilmanne & Dutoit Fig. 1)")
    viz.save_figure(fig, st.path("plots", "spectrum_07_01.png"))
    st.extra["expmap_07_01"] = (x, names, sub.frame_time_s)


def _plot_decomposition(st: _State) -> None:
    import jax.numpy as jnp

    from fourierjax import fourier, viz

    if "expmap_07_01" not in st.extra:
        raise _Skip("needs the spectrum step (07_01 expmap features)")
    x, names, dt = st.extra["expmap_07_01"]
    f = st.fits["07_01"]
    idx = [names.index(f"LeftLeg.expmap{k}") for k in range(3)]
    T = x.shape[0]
    t = np.arange(T) * dt
    # Tilmanne's second-order model (N = 2) at the fitted fundamental, for the left knee.
    m = fourier.fit_linear(jnp.asarray(x[:, idx]), jnp.asarray(t), f.omega_fit, 2)
    keep = t <= min(t[-1], 3.0)
    fig = viz.plot_decomposition(
        t[keep], x[keep][:, idx], m.offset, m.amplitude, m.phase, float(m.omega),
        channel_labels=[f"expmap {k + 1}" for k in range(3)],
        title="CMU 07_01 left knee, 2nd-order Fourier decomposition (cf. Tilmanne & Dutoit "
        "Fig. 3)")
    viz.save_figure(fig, st.path("plots", "decomposition_07_01_left_knee.png"))


def _plot_strip(st: _State) -> None:
    from fourierjax import viz
    from fourierjax.motion import model_joint_positions

    normal, tired, style = _style_models(st)
    m = st.motions["07_01"]
    svals = [-0.6, 0.0, 0.5, 1.0, 1.5]
    names = {-0.6: "brisk", 0.0: "normal", 0.5: "a little tired", 1.0: "tired",
             1.5: "very tired"}
    phases = np.linspace(0.0, 0.5 * np.pi, 3)  # a faded trail over a quarter cycle
    poses = []
    for s in svals:
        p = model_joint_positions(style.interpolate(normal, tired, s), m.skeleton(), phases)
        p = p - p[:, :, 1].min() * np.array([0.0, 1.0, 0.0])  # stand on the ground
        poses.append(p)
    labels = [f"s = {s:+.1f}\n{names[s]}" for s in svals]
    fig = viz.plot_stick_strip(poses, m.topology.parents, labels, names=m.topology.names,
                               title="Normal (07_01) to tired (07_04), Unuma eq. 3: "
                               "interpolation 0<s<1, extrapolation outside (cf. Unuma Fig. 3)")
    viz.save_figure(fig, st.path("plots", "interpolation_strip.png"))


def _plot_style_space(st: _State) -> None:
    import jax.numpy as jnp

    from fourierjax import style, viz

    clips = [c for c in st.cfg.clips if c in st.fits]
    if len(clips) < 3:
        raise _Skip("needs at least 3 fitted clips")
    models = [st.fits[c].model for c in clips]
    normal, tired = st.fits.get("07_01"), st.fits.get("07_04")
    labels = [f"{c} {WALKS.get(c) or RUNS.get(c, '')}" for c in clips]
    groups = ["run" if c in RUNS else "walk" for c in clips]
    if normal is not None and tired is not None:
        for s in (-0.6, 1.3):
            models.append(style.interpolate(normal.model, tired.model, s))
            labels.append("brisk (s=-0.6)" if s < 0 else "tired (s=1.3)")
            groups.append("synthesized")
    # Root translation channels (file units/s) would swamp the angles (radians): leave them
    # out; keep the joint angles and log omega.
    n_root = sum(1 for n in models[0].channel_names if n.startswith("root."))
    M = style.style_matrix(models)[:, n_root * (1 + 2 * models[0].num_harmonics):]
    pca = style.style_pca(M[: len(clips)], num_components=min(len(clips) - 1, 3))
    coords = np.asarray(style.pca_project(pca, M))
    fig = viz.plot_style_scatter(coords, labels, groups=groups,
                                 explained=np.asarray(pca.explained_variance_ratio).tolist(),
                                 title=f"Style space: PCA of {len(clips)} fitted CMU clips "
                                 "(joint angles; synthesized styles projected)")
    viz.save_figure(fig, st.path("plots", "style_space_pca.png"))
    st.extra["pca_explained"] = np.asarray(pca.explained_variance_ratio).tolist()
    del jnp


def _plot_hip_rule(st: _State) -> None:
    import jax
    import jax.numpy as jnp

    from fourierjax import contacts, fourier, viz
    from fourierjax.kinematics import forward_kinematics
    from fourierjax.motion import local_pose_from_features

    gait = _import("fourierjax.gait")
    _need(st, "09_01")
    run = st.fits["09_01"].model
    m = st.motions["09_01"]
    pts, groins, clear = _ground_of(st, "09_01")
    phase = jnp.linspace(0.0, 4 * np.pi, 240, dtype=jnp.float32)
    feats = fourier.synthesize_phase(run, phase)
    sk = m.skeleton()

    @jax.jit
    def fk_all(sk, feats):
        def one(f):
            fk = forward_kinematics(sk, *local_pose_from_features(sk, f, run.representation))
            return fk.positions, fk.end_site_positions

        return jax.vmap(one)(feats)

    pos, es = fk_all(sk, feats)
    foot = contacts.gather_foot_positions(pos, es, pts)
    leg = gait.leg_heights(pos[:, jnp.asarray(groins)], foot, jnp.asarray(clear))
    gait_v, jump_v = 0.06, 1.0
    curves = gait.hip_rule_curves(leg, gait_v, jump_v)
    fig = viz.plot_hip_rule(np.asarray(phase), {k: np.asarray(v) for k, v in curves.items()},
                            gait=gait_v, jump=jump_v, unit="CMU units",
                            title="Hip-height rule on the fitted run 09_01 (Unuma eq. 4-5): "
                            "three variants")
    viz.save_figure(fig, st.path("plots", "hip_rule_variants.png"))


def _crowd(st: _State) -> None:
    """A crowd of fitted walkers, from brisk to tired (Unuma Fig. 3's axis), posed per frame."""
    import jax
    import jax.numpy as jnp

    from fourierjax import crowd, viz
    from fourierjax.motion import channel_model

    n = st.cfg.crowd
    if n <= 0:
        raise _Skip("crowd switched off")
    normal, tired, style = _style_models(st)
    rng = np.random.default_rng(st.cfg.seed)
    s = rng.uniform(-0.6, 1.3, n).astype(np.float32)  # s < 0 brisk, s > 1 more tired than tired
    side = int(np.ceil(np.sqrt(n)))
    spacing = 40.0  # file units (~2.3 m)
    row, col = np.divmod(np.arange(n), side)
    spots = spacing * np.stack([col, row], axis=1) + rng.uniform(-8.0, 8.0, (n, 2))
    walkers = jax.vmap(lambda si: style.interpolate(normal, tired, si))(jnp.asarray(s))
    walk = st.motions["07_01"]
    skeleton = walk.skeleton()
    people = crowd.make_crowd(skeleton, channel_model(walk, walkers, jnp.asarray(spots, jnp.float32)))
    t_show = jnp.float32(1.0)
    pos = jax.block_until_ready(crowd.crowd_positions(people, t_show))  # compiles
    frames = 60
    t0 = time.perf_counter()
    for k in range(frames):  # one second of animation at 60 frames/s
        out = crowd.crowd_positions(people, jnp.float32(k / frames))
    jax.block_until_ready(out)
    fps = frames / (time.perf_counter() - t0)
    corner = (row < 7) & (col < 7)  # a 7 x 7 corner of the crowd: the poses stay readable
    fig = viz.plot_crowd(np.asarray(pos)[corner], walk.topology.parents, s[corner],
                         value_label="style s (< 0 brisk, 0 normal 07_01, 1 tired 07_04)",
                         title=f"{int(corner.sum())} of {n:,} fitted walkers, each its own style "
                         f"(all posed at {fps:.0f} frames/s)")
    viz.save_figure(fig, st.path("plots", "crowd.png"))
    st.extra["crowd"] = {"characters": n, "frames_per_s": round(fps, 1),
                         "style_range": [-0.6, 1.3], "spacing_file_units": spacing}


# --------------------------------------------------------------------------------------- gifs


def _gif_frames(st: _State, motion, seconds: float = 2.4) -> np.ndarray:
    n = st.cfg.gif_frames
    F = motion.num_frames
    span = min(F - 1, int(round(seconds / motion.frame_time_s)))
    start = max(0, (F - 1 - span) // 2)
    return np.linspace(start, start + span, n).round().astype(int)


def _gif(st: _State, name: str, clips: list[str], titles: list[str], title: str,
         seconds: float = 2.4) -> None:
    from fourierjax import viz
    from fourierjax.motion import motion_joint_positions

    missing = [c for c in clips if c not in st.bvh_positions]
    if missing:
        raise _Skip(f"needs the synthesized motion(s) {missing}")
    mots = [st.bvh_positions[c] for c in clips]
    frames = _gif_frames(st, mots[0], seconds)
    seqs = [motion_joint_positions(m, frames) for m in mots]
    # Each panel on its own ground: the lowest point of the whole sequence at height 0.
    seqs = [s - s[..., 1].min() * np.array([0.0, 1.0, 0.0]) for s in seqs]
    dt = (frames[1] - frames[0]) * mots[0].frame_time_s if len(frames) > 1 else 0.1
    topo = mots[0].topology
    viz.save_gif(seqs, topo.parents, st.path("gifs", f"{name}.gif"), frame_time_s=dt,
                 names=topo.names, titles=titles, max_frames=st.cfg.gif_frames,
                 dpi=st.cfg.gif_dpi, title=title)


def _gifs(st: _State) -> None:
    if not st.cfg.gifs:
        raise _Skip("GIFs switched off")
    done = 0
    jobs = [
        ("walk_styles", ["walk_brisk_extrapolated", "walk_normal", "walk_tired"],
         ["brisk (s=-0.6)", "normal 07_01", "tired (s=1.3)"], "Unuma inter/extrapolation", 2.4),
        ("run_brisk_superposed", ["run_brisk_superposed"], ["run + 1.37 (brisk - normal)"],
         "", 1.6),
        ("walk_to_run", ["walk_to_run"], ["walk -> run"], "", 4.0),
        ("run_flight", ["run_flight", "run_high_jump"], ["gait 0.06 jump 1", "gait 0.03 jump 2.5"],
         "hip-height rule", 1.6),
        ("walk_shivering", ["walk_shivering"], ["shivering (noise)"], "", 2.4),
    ]
    for name, clips, titles, title, secs in jobs:
        try:
            _gif(st, name, clips, titles, title, secs)
            done += 1
        except _Skip as err:
            st.log(f"notice: gif {name} skipped: {err}")
            st.skipped.append({"part": f"gif {name}", "reason": str(err)})
    if not done:
        raise _Skip("no synthesized motions to animate")


# ------------------------------------------------------------------------------------- stance


#: The stance gallery: (shape set, intensities, object position in metres or None).
STANCE_GALLERY = (
    ("posture", (-1.0, -0.5, 0.0, 0.5, 1.0), None),
    ("strong_recoil", (0.25, 0.5, 0.75, 1.0), (0.4, 1.2, 0.7)),
    ("beauty_line", (-1.0, 1.0), None),
)


def _stance(st: _State) -> None:
    if not st.cfg.stance:
        raise _Skip("stance switched off")
    import jax
    import jax.numpy as jnp

    _import("fourierjax.stance")
    shape_sets = _import("fourierjax.stance.shape_sets")
    from fourierjax import viz
    from fourierjax.io.stance_bvh import pose_to_motion, write_stance_bvh
    from fourierjax.motion import motion_joint_positions
    from fourierjax.stance.skeleton48 import make_body
    from fourierjax.stance.solver import solve_stances, stack_problems

    body = make_body(1.75)
    problems, labels = [], []
    for name, intensities, obj in STANCE_GALLERY:
        ss = shape_sets.get_shape_set(name)
        o = None if obj is None else jnp.asarray(obj)
        for i in intensities:
            problems.append(ss.problem(body, i, o))
            labels.append((name, i))
    # Batched solves in chunks of 3 problems (the last padded by repetition): one compilation
    # serves the gallery, the stance notebook and the stance experiment's small setting
    # (through the persistent compilation cache).
    chunks = []
    for a in range(0, len(problems), 3):
        part = problems[a:a + 3]
        part = part + [part[-1]] * (3 - len(part))
        chunks.append(solve_stances(stack_problems(part)))
    sol = jax.tree.map(lambda *xs: jnp.concatenate(xs)[: len(problems)], *chunks)
    info = []
    for k, (name, i) in enumerate(labels):
        pose = type(sol.pose)(*(np.asarray(leaf[k]) for leaf in (sol.pose.root_position,
                                                                   sol.pose.quats)))
        write_stance_bvh(st.path("stance", f"{name}_{i:+.2f}.bvh"), body, pose)
        info.append({"shape_set": name, "intensity": i, "converged": bool(sol.converged[k]),
                     "iterations": int(sol.iterations[k]),
                     "objective": float(sol.objective[k]),
                     "com_error_m": float(sol.com_error_m[k])})
    st.extra["stance"] = info
    motion = pose_to_motion(body, sol.pose)
    pos = motion_joint_positions(motion)
    topo = motion.topology
    for name, intensities, _ in STANCE_GALLERY:
        idx = [k for k, (n, _) in enumerate(labels) if n == name]
        az = 90.0 if name == "beauty_line" else 15.0  # coronal curves from the front
        fig = viz.plot_posture_range([pos[k] for k in idx], topo.parents, list(intensities),
                                     names=topo.names, azimuth_deg=az,
                                     title=f"Shape set '{name}' (Neff & Fiume 2004"
                                     f"{' Fig. 5' if name == 'posture' else ''}), intensity "
                                     "under each figure")
        viz.save_figure(fig, st.path("plots", f"stance_{name}.png"))


# ---------------------------------------------------------------------------------- pipeline

STEPS: tuple[tuple[str, Callable[[_State], None]], ...] = (
    ("fit models", _fit),
    ("walks (inter/extrapolation)", _synth_walks),
    ("brisk run (superposition)", _synth_run),
    ("transitions", _synth_transitions),
    ("step/gait/jump variants", _synth_steps),
    ("shivering walk", _synth_noise),
    ("spectrum plot", _plot_spectrum),
    ("decomposition plot", _plot_decomposition),
    ("inter/extrapolation strip", _plot_strip),
    ("style-space PCA", _plot_style_space),
    ("hip-rule plot", _plot_hip_rule),
    ("crowd of fitted walkers", _crowd),
    ("stance gallery", _stance),
    ("animated GIFs", _gifs),
)


def run_demo(out_dir, config: DemoConfig | None = None, *, progress: bool = True,
             log: Callable[[str], None] | None = None) -> dict:
    """Run the whole demo and write its outputs under ``out_dir`` (see the module docstring).

    Arguments:
        out_dir: output folder (created); config: a :class:`DemoConfig` (default: full demo);
        progress: show a tqdm progress bar on stderr; log: where notices go (default: stderr,
        through tqdm so the bar stays intact).
    Returns:
        The summary dict also written to ``out_dir/summary.json``.
    """
    from tqdm import tqdm

    cfg = config or DemoConfig()
    from fourierjax._compile_cache import enable_compile_cache

    enable_compile_cache()
    if cfg.harmonics < 1 or cfg.harmonics > 16:
        raise UserError(f"--harmonics: must be between 1 and 16, got {cfg.harmonics}")
    if not (np.isfinite(cfg.seconds) and 0.5 <= cfg.seconds <= 60):
        raise UserError(f"--seconds: must be between 0.5 and 60, got {cfg.seconds}")
    from fourierjax import data

    unknown = [c for c in cfg.clips if c not in data.list()]
    if unknown:  # before the output folder is made: a typo leaves nothing behind
        raise UserError(f"--clips: unknown clip(s) {unknown}; bundled: {', '.join(data.list())}")
    out = pathlib.Path(out_dir)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    bar = tqdm(total=len(STEPS), desc="fourierjax demo", unit="step", disable=not progress,
               file=sys.stderr)
    write = log or (lambda s: tqdm.write(f"fourierjax: {s}", file=sys.stderr))
    st = _State(out=out, cfg=cfg, log=write)
    timings = {}
    t_all = time.perf_counter()
    for name, fn in STEPS:
        bar.set_postfix_str(name)
        t0 = time.perf_counter()
        try:
            fn(st)
        except _Skip as err:
            write(f"notice: {name} skipped: {err}")
            st.skipped.append({"part": name, "reason": str(err)})
        timings[name] = round(time.perf_counter() - t0, 2)
        bar.update(1)
    bar.close()
    summary = {
        "config": dataclasses.asdict(cfg),
        "fits": {c: f.summary() for c, f in st.fits.items()},
        "synthesis": st.extra.get("walk_normal") and {
            k: v for k, v in st.extra.items() if k in ("walk_normal", "run_flight",
                                                        "run_high_jump")},
        "style_pca_explained_variance_ratio": st.extra.get("pca_explained"),
        "stance": st.extra.get("stance"),
        "crowd": st.extra.get("crowd"),
        "written": st.written,
        "skipped": st.skipped,
        "timings_s": timings,
        "total_s": round(time.perf_counter() - t_all, 2),
    }
    write_bytes_atomic(out / "summary.json", json.dumps(summary, indent=2, default=_json_default).encode())
    return summary


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)
