"""Issue #20's tables: every bundled walk and run rewritten into each rig convention, and Bandai-1.

Per convention (`tests.conventions`: Mixamo, Daz, 3ds Max, biped, SMPL, LAFAN, Bandai, Z-up,
metres, scrambled; `tests.rigs`: Daz Genesis 8 twist/bend bones, Unreal leaf twist bones and
root, a Blender armature with bones along Y, no toe joints, large rest rotations) each clip is
fitted and synthesized like its CMU original, and the results are compared after the conversion
is undone: heel strikes (frames), omega from steps, aligned phases (cycles), synthesized root
and ankle positions (fraction of the leg length), foot skating and root advance (relative).
The fits use the config's representation: `tangent` by default, as on the command line
(`euler` is Unuma's per-channel series, which depends on the rig's joint frames).
On ``../shared/data/mocap/bandai1`` (when present), per content: strikes, alignment, omega from
steps against the fit, the steady segment, root speed against the captured and its direction,
``fourierjax synth`` and the s = 0.5 interpolation. Usage:
``python -m experiments.any_skeleton [--small] [--out DIR] [--config FILE]``.
"""

from __future__ import annotations

import pathlib
import sys

import numpy as np

from experiments._util import parse, run_main, write_table

ROOT = pathlib.Path(__file__).resolve().parents[1]
BANDAI = ROOT / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"


def _rewrite(motion, name):
    from fourierjax.io.axes import to_y_up
    from tests.conventions import CONVENTIONS, convert
    from tests.rigs import RIGS

    if name in RIGS:
        return RIGS[name](motion)
    assert name in CONVENTIONS, name
    out = convert(motion, name)
    return to_y_up(out, "z") if name == "zup" else out


def _undo_scale(name) -> float:
    from tests.conventions import CMU_METRES_PER_UNIT

    return CMU_METRES_PER_UNIT if name == "metres" else 1.0


def _synth(fit, motion, frames):
    from fourierjax import gait

    sk = motion.skeleton()
    r = gait.synthesize_gait(fit.model, sk, frames, fit.frame_time_s, body_map=gait.model_body_map(fit.model, sk),
                             foot_lock=False)
    return r


def _skating(r, dt, scale):
    from fourierjax import gait

    return float(gait.foot_skating(r.foot_positions, dt, r.floor + r.clearance[None],
                                   height_threshold=0.5 * scale).mean_speed)


def _rel(a, b) -> float:
    return float(abs(a - b) / max(abs(b), 1e-12))


def convention_rows(cfg, log=print) -> list[dict]:
    from fourierjax import data
    from fourierjax.data import detect_rest_frames
    from fourierjax.motion import fit_motions

    clips = cfg["clips"]
    motions = []
    for c in clips:
        m = data.load(c)
        motions.append(m[detect_rest_frames(m):][: cfg["max_frames"]])
    frames = cfg["synth_frames"]
    rep = cfg["representation"]
    ref_fits = fit_motions(motions, cfg["harmonics"], rep)
    ref_synth = [_synth(f, m, frames) for f, m in zip(ref_fits, motions)]
    rows = []
    for conv in cfg["conventions"]:
        log(f"  {conv}", flush=True)
        rigs = [_rewrite(m, conv) for m in motions]
        fits = fit_motions(rigs, cfg["harmonics"], rep, throw=False)
        s = _undo_scale(conv)
        for clip, m, rig, ref, f, rs in zip(clips, motions, rigs, ref_fits, fits, ref_synth):
            row = {"convention": conv, "clip": clip, "alignment": f.alignment}
            if not f.successful:
                rows.append({**row, "error": f.message})
                continue
            ds = [abs(int(a) - int(b)) for got, want in ((f.left_heel_strikes, ref.left_heel_strikes),
                                                          (f.right_heel_strikes, ref.right_heel_strikes))
                  for a, b in zip(got, want)]
            same = (len(f.left_heel_strikes), len(f.right_heel_strikes)) == (len(ref.left_heel_strikes),
                                                                             len(ref.right_heel_strikes))
            row["strikes_max_frames_off"] = max(ds, default=0) if same else "count differs"
            row["omega_steps_rel"] = _rel(f.omega_steps, ref.omega_steps)
            row["omega_fit_rel"] = _rel(f.omega_fit, ref.omega_fit)
            row["phase_cycles"] = float(abs(np.angle(np.exp(1j * (f.phase_shift - ref.phase_shift)))) / (2 * np.pi))
            try:
                r = _synth(f, rig, frames)
            except Exception as err:  # noqa: BLE001 - the table reports it
                rows.append({**row, "error": f"synth: {err}"})
                continue
            root, rroot = _undo(np.asarray(r.root_position, np.float64), conv), np.asarray(rs.root_position, np.float64)
            ank = _undo(np.asarray(r.foot_positions, np.float64)[:, :, 0], conv)
            rank = np.asarray(rs.foot_positions, np.float64)[:, :, 0]
            leg = ref.body_map.leg_length
            row["root_pos_off_legs"] = float(np.abs(root - rroot).max() / leg)
            row["ankle_pos_off_legs"] = float(np.abs(ank - rank).max() / leg)
            dt = f.frame_time_s
            row["skating_rel"] = _rel(_skating(r, dt, s) / s, _skating(rs, dt, 1.0))
            adv = np.linalg.norm(np.delete(root[-1] - root[0], 1))
            radv = np.linalg.norm(np.delete(rroot[-1] - rroot[0], 1))
            row["advance_rel"] = _rel(adv, radv)
            rows.append(row)
    return rows


def _undo(p, conv):
    from tests.conventions import CONVENTIONS, undo

    # A Z-up rewrite is read back Y-up (`to_y_up`, as the CLI reads it): nothing to undo.
    return undo(p, conv) if conv in CONVENTIONS and conv != "zup" else p


def bandai_rows(cfg, out, log=print) -> list[dict]:
    """One row per content: the issue's Done-when figures over its `_001` clips of every style."""
    import jax
    import jax.numpy as jnp

    from fourierjax import fourier, gait, style
    from fourierjax.cli import main as cli
    from fourierjax.features import root_relative_positions
    from fourierjax.io.bvh import read_bvh
    from fourierjax.kinematics import fk_frames
    from fourierjax.motion import fit_motions

    rows = []
    for content in cfg["bandai_contents"]:
        files = sorted(BANDAI.glob(f"dataset-1_{content}_*_001.bvh"))
        files = [p for p in files if p.stem.split("_")[1] == content]
        log(f"  bandai {content}: {len(files)} clips", flush=True)
        motions = [read_bvh(p) for p in files]
        fits = fit_motions(motions, cfg["harmonics"], cfg["representation"], throw=False)
        ok = [f.successful for f in fits]
        strikes = sum(bool(f.successful and len(f.left_heel_strikes) and len(f.right_heel_strikes)) for f in fits)
        aligned = sum(f.alignment == "left_heel_strike" for f in fits)
        om = [abs(f.omega_steps / f.omega_fit - 1) for f in fits if f.successful]
        trimmed = sum(f.frame_start > 0 or f.frame_stop < m.num_frames for f, m in zip(fits, motions))
        # Root speed with root motion over whole cycles, against the captured speed over the segment.
        dt = fits[0].frame_time_s
        n = int(round(3 * 2 * np.pi / min(float(f.model.omega) for f in fits) / dt)) + 1
        ratios, coss = [], []
        for m, f in zip(motions, fits):
            sk = m.skeleton()
            bm = f.body_map
            P = np.asarray(fk_frames(sk, m.channels[[f.frame_start, f.frame_stop - 1]]).positions)
            d = P[1, bm.trajectory] - P[0, bm.trajectory]
            d[bm.up_axis] = 0
            captured = np.linalg.norm(d) / ((f.frame_stop - f.frame_start - 1) * dt)
            r = gait.synthesize_gait(f.model, sk, n, dt, body_map=gait.model_body_map(f.model, sk), foot_lock=False)
            period = 2 * np.pi / float(f.model.omega)
            k = min(int(round(np.floor((n - 1) * dt / period) * period / dt)), n - 1)
            root = np.asarray(r.root_position, np.float64)
            dd = root[k] - root[0]
            dd[bm.up_axis] = 0
            ratios.append(np.linalg.norm(dd) / (k * dt) / captured)
            # Facing: left hip - right hip crossed with up, at the synthesized frames (pelvis frame).
            feats = np.asarray(r.features, np.float64)
            pos = np.asarray(root_relative_positions(sk, jnp.asarray(feats[::8]), f.model.representation))
            up = np.eye(3)[bm.up_axis]
            lat = (pos[:, bm.left.hip] - pos[:, bm.right.hip]).mean(0)
            face = np.cross(lat, up)
            face -= (face @ up) * up
            trav = dd
            c = float(face @ trav / np.linalg.norm(face) / np.linalg.norm(trav))
            coss.append(-c if content == "walk-back" else c)
        # `fourierjax synth` on the normal style's model.
        normal = next(i for i, p in enumerate(files) if "_normal_" in p.name)
        folder = out / "bandai_models"
        folder.mkdir(exist_ok=True)
        rc_fit = cli(["fit", str(files[normal]), "--harmonics", str(cfg["harmonics"]), "--representation",
                      cfg["representation"], "--out", str(folder) + "/"])
        rc_synth = cli(["synth", str(folder / f"{files[normal].stem}.npz"), "--seconds", "3",
                        "--out", str(folder / f"{content}_synth.bvh")]) if rc_fit == 0 else rc_fit
        # s = 0.5 between normal and each other style: distance to each against their distance.
        sk = motions[normal].skeleton()

        def cycle(model, num=48):
            t = jnp.linspace(0.0, 2 * jnp.pi / model.omega, num, endpoint=False)
            return np.asarray(root_relative_positions(sk, fourier.synthesize(model, t), model.representation))

        def dist(p, q):
            return min(float(np.linalg.norm(p - np.roll(q, s, axis=0), axis=-1).mean()) for s in range(len(q)))

        between, worst = 0, 0.0
        a = jax.tree_util.tree_map(jnp.asarray, fits[normal].model)
        pa = cycle(a)
        pairs = 0
        for i, f in enumerate(fits):
            if i == normal or not f.successful or f.model.channel_names != a.channel_names:
                continue
            b = jax.tree_util.tree_map(jnp.asarray, f.model)
            pb, pm = cycle(b), cycle(style.interpolate(a, b, 0.5))
            da, db, dab = dist(pm, pa), dist(pm, pb), dist(pa, pb)
            pairs += 1
            between += da < dab and db < dab
            worst = max(worst, max(da, db) / dab)
        rows.append({
            "content": content, "clips": len(files), "fitted": sum(ok), "with_strikes": strikes,
            "left_heel_strike": aligned, "omega_steps_vs_fit_worst_pct": 100 * max(om),
            "segment_trimmed": trimmed, "root_speed_ratio_min": float(min(ratios)),
            "root_speed_ratio_max": float(max(ratios)), "forward_cos_worst": float(min(coss)),
            "synth_cli": "ok" if rc_synth == 0 else f"exit {rc_synth}",
            "halfway_between": f"{between}/{pairs}", "halfway_worst_dist_ratio": worst,
        })
    return rows


def run(argv=None):
    cfg, out = parse("any_skeleton", __doc__.splitlines()[0], argv)
    if cfg["conventions"]:
        rows = convention_rows(cfg)
        print(write_table(rows, out, "conventions", "Each rig convention against the CMU original"))
    if cfg["bandai_contents"]:
        if not BANDAI.is_dir():
            print(f"Bandai-Namco data not found at {BANDAI}: its table is skipped")
        else:
            rows = bandai_rows(cfg, out)
            print(write_table(rows, out, "bandai", "Bandai-1 per content"))


def main(argv=None) -> int:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))  # tests.conventions / tests.rigs hold the rewrites
    return run_main(run, argv)


if __name__ == "__main__":
    sys.exit(main())
