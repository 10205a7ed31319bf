"""The demo's plot, crowd, GIF and stance-gallery steps (`fourierjax.demo` runs them)."""

from __future__ import annotations

import time

import numpy as np

from fourierjax._demo_synth import (
    RUNS,
    WALKS,
    _ground_of,
    _import,
    _need,
    _Skip,
    _State,
    _style_models,
)
from fourierjax._jit import filter_jit


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
    groups = viz.channel_groups([n for n, k in zip(names, moving, strict=True) if k],
                                sub.topology.names, sub.topology.parents, f.body_map)
    fig = viz.plot_spectrum(freqs, amp, fundamental_hz=f.fundamental_hz, max_hz=8.0, groups=groups,
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
    knee = f.body_map.name(f.body_map.left.knee)  # the rig's left knee (LeftLeg on CMU rigs)
    idx = [names.index(f"{knee}.expmap{k}") for k in range(3)]
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

    @filter_jit
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
