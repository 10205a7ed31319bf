"""`fourierjax plot`: spectrum, decomposition, stick figure or GIF from a BVH clip or a model file."""

from __future__ import annotations

import argparse
import pathlib

HELP = ("Plot a BVH clip or a model file: spectrum, decomposition (Fourier components), stick "
        "figure at a frame, or an animated GIF.")

KINDS = ("spectrum", "decomposition", "stick", "gif")
_IMAGE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("kind", metavar="KIND", help=f"one of: {', '.join(KINDS)}")
    parser.add_argument("input", metavar="INPUT",
                        help="a BVH file, a bundled clip name (e.g. 07_01) or a model file (.npz)")
    parser.add_argument("--out", required=True, metavar="FILE",
                        help="image to write (.png/.pdf/.svg; .gif for KIND gif)")
    parser.add_argument("--frame", default=None, metavar="K",
                        help="stick: frame of a BVH clip, counted in the file (default: its first "
                        "frame after any leading rest/T-pose frames)")
    parser.add_argument("--phase", default="0", metavar="RAD",
                        help="stick: cycle phase of a model, radians (default 0)")
    parser.add_argument("--joint", default=None, metavar="NAME",
                        help="decomposition: joint whose rotation channels are shown "
                        "(default the left knee of the body map, e.g. LeftLeg on CMU rigs)")
    parser.add_argument("--harmonics", default="2", metavar="N",
                        help="decomposition of a BVH clip: harmonics to fit (default 2, Tilmanne)")
    parser.add_argument("--seconds", default="2", metavar="S",
                        help="gif: seconds to animate (default 2)")
    parser.add_argument("--max-frames", default="40", metavar="F",
                        help="gif: at most this many frames (default 40)")


def _num(text: str, name: str, kind=float, lo=None, hi=None):
    import math

    from fourierjax.errors import UserError

    try:
        v = kind(text)
    except ValueError:
        raise UserError(f"{name}: {text!r} is not a{'n integer' if kind is int else ' number'}") from None
    if kind is float and not math.isfinite(v):
        raise UserError(f"{name}: must be finite, got {text!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise UserError(f"{name}: {v:g} is outside [{lo:g}, {hi:g}]")
    return v


def _load(text: str):
    """('bvh', Motion, rest) or ('model', ModelFile, 0) for a path or bundled clip name: a
    BVH file's every frame and the number of its leading rest/T-pose frames."""
    from fourierjax.cli._paths import resolve_input
    from fourierjax.io import model_io
    from fourierjax.io.bvh import read_bvh

    path = resolve_input(text, expected="a BVH or model file")
    if path.suffix.lower() == ".npz":
        import dataclasses

        import jax
        import jax.numpy as jnp

        mf = model_io.load_model(path)
        # Model files hold float64; compute in JAX's default precision.
        return "model", dataclasses.replace(mf, model=jax.tree.map(jnp.asarray, mf.model)), 0
    motion = read_bvh(path)
    import sys

    from fourierjax.body import BodyMapError, infer_body_map
    from fourierjax.data import detect_rest_frames
    from fourierjax.io.axes import to_y_up, up_name

    try:  # A Z-up file (Blender) is drawn standing, as `fit` reads it (issue 20).
        bm = infer_body_map(motion)
    except BodyMapError:
        bm = None  # no legs to tell up by: drawn as the file has it
    if bm is not None and (bm.up_axis, bm.up_sign) != (1, 1):
        axis = up_name(bm.up_axis, bm.up_sign)
        print(f"fourierjax: notice: {path}: {axis} is up; turned Y-up on reading", file=sys.stderr)
        motion = to_y_up(motion, axis)
    return "bvh", motion, detect_rest_frames(motion)


def _model_motion(mf, seconds: float, input_name: str):
    """Synthesize a model file on its stored skeleton: a Motion of ``seconds``."""
    import jax.numpy as jnp
    import numpy as np

    from fourierjax import fourier
    from fourierjax.errors import UserError
    from fourierjax.motion import motion_from_features

    template = mf.template_motion()
    if template is None:
        raise UserError(f"{input_name}: the model file carries no skeleton to draw")
    dt = mf.frame_time_s or 1 / 120
    t = jnp.arange(max(2, int(round(seconds / dt)))) * dt
    x = np.asarray(fourier.synthesize(mf.model, t), np.float64)
    return motion_from_features(template, x, mf.model.channel_names, dt, body_map=mf.body_map)


def _joint_channels(names, joint: str, input_name: str) -> list[int]:
    from fourierjax.errors import UserError

    idx = [i for i, n in enumerate(names) if n.split(".")[0] == joint and not n.startswith("root.")]
    if not idx:
        joints = sorted({n.split(".")[0] for n in names if not n.startswith("root.")})
        raise UserError(f"--joint: {input_name} has no rotation channels for {joint!r}; joints: "
                        f"{', '.join(joints)}")
    return idx


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from fourierjax import viz
    from fourierjax.errors import UserError

    if args.kind not in KINDS:
        raise UserError(f"unknown plot kind {args.kind!r}; choose one of: {', '.join(KINDS)}")
    out = pathlib.Path(args.out)
    want = (".gif",) if args.kind == "gif" else _IMAGE_SUFFIXES
    if out.suffix.lower() not in want:
        raise UserError(f"--out: {args.out}: expected a {' or '.join(want)} file for {args.kind}")
    if not out.parent.exists():
        raise UserError(f"--out: {out.parent}: no such directory")
    what, obj, rest = _load(args.input)
    if what == "bvh" and args.kind != "stick":
        obj = obj[rest:]  # the captured frames (stick's --frame counts the file's)

    if args.kind == "spectrum":
        _spectrum(what, obj, args, out)
    elif args.kind == "decomposition":
        _decomposition(what, obj, args, out)
    elif args.kind == "stick":
        if what == "bvh":
            # --frame counts the file's frames, rest frames included (as `fit` reports them).
            k = rest if args.frame is None else _num(args.frame, "--frame", int)
            if not 0 <= k < obj.num_frames:
                raise UserError(f"--frame: {k} is outside {args.input} (frames 0..{obj.num_frames - 1})")
            from fourierjax.motion import motion_joint_positions

            p = motion_joint_positions(obj, [k])[0]
            title = f"{pathlib.Path(args.input).name}, frame {k}"
            topo = obj.topology
        else:
            import math

            from fourierjax.motion import model_joint_positions

            # Wrapped in float64 (float32 sin of a large phase is imprecise); beyond +-1e6 rad
            # it is a typo (1e308 made NaN poses and a matplotlib ValueError).
            ph = math.remainder(_num(args.phase, "--phase", float, -1e6, 1e6), 2 * math.pi)
            template = obj.template_motion()
            if template is None:
                raise UserError(f"{args.input}: the model file carries no skeleton to draw")
            bmap = obj.body_map
            p = model_joint_positions(obj.model, template.skeleton(), np.array([ph]),
                                      0 if bmap is None else bmap.pelvis)[0]
            if not np.isfinite(p).all():
                raise UserError(f"{args.input}: the pose at phase {ph:g} rad is not finite")
            title = f"{pathlib.Path(args.input).name}, phase {ph:.2f} rad"
            topo = template.topology
        fig = viz.plot_stick_figure(p, topo.parents, names=topo.names, title=title)
        viz.save_figure(fig, out)
    else:
        seconds = _num(args.seconds, "--seconds", float, 0.1, 60)
        max_frames = _num(args.max_frames, "--max-frames", int, 2, 500)
        motion = obj if what == "bvh" else _model_motion(obj, seconds, args.input)
        from fourierjax.motion import motion_joint_positions

        span = min(motion.num_frames - 1, int(round(seconds / motion.frame_time_s)))
        frames = np.unique(np.linspace(0, span, max_frames).round().astype(int))
        seq = motion_joint_positions(motion, frames)
        seq = seq - seq[..., 1].min() * np.array([0.0, 1.0, 0.0])
        dt = (frames[1] - frames[0]) * motion.frame_time_s if len(frames) > 1 else 0.1
        viz.save_gif([seq], motion.topology.parents, out, frame_time_s=dt,
                     names=motion.topology.names, titles=[pathlib.Path(args.input).name],
                     max_frames=max_frames)
    print(f"wrote {out}")
    return 0


def _spectrum(what, obj, args, out) -> None:
    import numpy as np

    from fourierjax import viz

    if what == "bvh":
        from fourierjax.body import BodyMapError, infer_body_map
        from fourierjax.motion import joint_expmaps
        from fourierjax.spectrum import windowed_amplitude_spectrum

        x, names = joint_expmaps(obj)
        moving = np.ptp(x, axis=0) > 1e-4
        freqs, amp = windowed_amplitude_spectrum(x[:, moving], obj.frame_time_s)
        try:
            bmap = infer_body_map(obj)
        except BodyMapError:  # colours by body part need a body map; without one, plain curves
            bmap = None
        groups = viz.channel_groups([n for n, k in zip(names, moving, strict=True) if k],
                                    obj.topology.names, obj.topology.parents, bmap)
        fig = viz.plot_spectrum(freqs, amp, groups=groups, title=f"{pathlib.Path(args.input).name}: spectra of "
                                f"{int(moving.sum())} exponential-map values")
    else:
        m = obj.model
        f0 = float(m.omega) / (2 * np.pi)
        angles = np.array([not n.startswith("root.") for n in m.channel_names] or
                          [True] * m.num_channels)
        amp = np.concatenate([np.abs(np.asarray(m.offset))[None], np.asarray(m.amplitude).T])
        freqs = f0 * np.arange(m.num_harmonics + 1)
        fig = viz.plot_spectrum(freqs, amp[:, angles], fundamental_hz=f0, stems=True,
                                max_hz=max(8.0, f0 * (m.num_harmonics + 0.5)),
                                title=f"{pathlib.Path(args.input).name}: harmonic amplitudes of "
                                f"{int(angles.sum())} rotation channels")
    viz.save_figure(fig, out)


def _left_knee(what, obj) -> str:
    """The left knee's name from the body map (of the clip, or of a model's own poses)."""
    from fourierjax.errors import UserError

    if what == "bvh":
        from fourierjax.body import infer_body_map

        bmap = infer_body_map(obj)
    else:
        template = obj.template_motion()
        if template is None:
            raise UserError("--joint: the model file carries no skeleton to find the knee on; name a joint")
        from fourierjax.gait import model_body_map

        bmap = model_body_map(obj.model, template.skeleton())
    return bmap.name(bmap.left.knee)


def _decomposition(what, obj, args, out) -> None:
    import numpy as np

    from fourierjax import viz
    from fourierjax.errors import UserError

    if args.joint is None:
        args.joint = _left_knee(what, obj)

    if what == "bvh":
        from fourierjax.motion import features_from_motion, fit_motions

        n = _num(args.harmonics, "--harmonics", int, 1, 16)
        if obj.num_frames < 16:
            raise UserError(f"{args.input}: only {obj.num_frames} frames; need at least 16")
        fit = fit_motions([obj], n, "euler", throw=True)[0]
        sub = obj[fit.frame_start:fit.frame_stop]
        x, names = features_from_motion(sub, "euler")
        model = fit.raw_model
        idx = _joint_channels(names, args.joint, args.input)
        t = np.arange(x.shape[0]) * sub.frame_time_s
        data = x[:, idx]
    else:
        model = obj.model
        names = model.channel_names
        idx = _joint_channels(names, args.joint, args.input)
        t = np.linspace(0, 2 * 2 * np.pi / float(model.omega), 240)
        from fourierjax import fourier

        data = np.asarray(fourier.synthesize(model, t))[:, idx]
    fig = viz.plot_decomposition(
        t, data, np.asarray(model.offset)[idx], np.asarray(model.amplitude)[idx],
        np.asarray(model.phase)[idx], float(model.omega),
        channel_labels=[names[i].split(".", 1)[1] for i in idx],
        title=f"{pathlib.Path(args.input).name}: {args.joint}, {model.num_harmonics}-harmonic "
        "Fourier decomposition")
    viz.save_figure(fig, out)
