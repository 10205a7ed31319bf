"""Walking along a path (issue #21 item 3): `gait.follow_path`, `synth --path`."""

import functools
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import gait, model_io
from fourierjax.errors import UserError
from fourierjax.io.bvh import read_bvh
from fourierjax.motion import motion_joint_positions

CLIP = "07_01"


@functools.cache
def _model(tmp: str):
    from fourierjax.cli import main

    assert main(["fit", CLIP, "--harmonics", "3", "--out", tmp + "/"]) == 0
    return model_io.load_model(f"{tmp}/{CLIP}.npz")


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    mf = _model(str(tmp_path_factory.mktemp("path")))
    t = mf.template_motion()
    bmap = gait.model_body_map(mf.model, t.skeleton())
    r = gait.synthesize_gait(mf.model, t.skeleton(), 480, mf.frame_time_s, body_map=bmap)
    return mf, t, bmap, r


def _bend(walk, path, **kw):
    mf, _, bmap, r = walk
    return gait.follow_path(r.features, r.root_position, path, mf.model.channel_names, bmap.name(bmap.pelvis),
                            mf.frame_time_s, **kw)


def test_circle_keeps_the_root_on_it_at_the_gait_speed(walk):
    mf, _, bmap, r = walk
    R = 3.0 / bmap.metres_per_unit
    _, root, yaw = _bend(walk, gait.circle_path(R))
    root, start = np.asarray(root), np.asarray(r.root_position[0])
    centre = start[[0, 2]] + [R, 0.0]  # a left turn from +Z: the centre on +X
    off = np.abs(np.linalg.norm(root[:, [0, 2]] - centre, axis=1) - R) * bmap.metres_per_unit
    assert off.max() <= 0.02  # metres
    np.testing.assert_allclose(root[:, 1], np.asarray(r.root_position[:, 1]))  # height untouched
    straight = np.asarray(r.root_position)
    length = lambda p: np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1).sum()  # noqa: E731
    assert abs(length(root) / length(straight) - 1) <= 0.01  # the model's speed
    # The heading turns with the tangent: yaw = arc length / R.
    s = np.linalg.norm(root[-1, [0, 2]] - root[0, [0, 2]])
    assert np.all(np.diff(np.asarray(yaw)) > -1e-4)  # left turn: the yaw only grows
    assert np.abs(np.diff(np.asarray(yaw), 2)).max() < 1e-3  # smoothly: no steps at the vertices
    turn = np.asarray(yaw) - float(yaw[0])  # yaw[0] turns the gait's own travel onto +Z
    assert float(turn[-1]) == pytest.approx(length(root) / R, rel=0.02) and s < 2 * R
    # A right turn mirrors it; the gait's own sway keeps the root off the line by up to ~4 cm.
    _, right, yaw_r = _bend(walk, gait.circle_path(R, left=False))
    assert float(yaw_r[-1] - yaw_r[0]) == pytest.approx(-float(turn[-1]), rel=1e-3)
    _, swaying, _ = _bend(walk, gait.circle_path(R), sway=1.0)
    dev = np.abs(np.linalg.norm(np.asarray(swaying)[:, [0, 2]] - centre, axis=1) - R) * bmap.metres_per_unit
    assert 0.02 < dev.max() < 0.06


def test_the_body_turns_with_the_path(walk):
    """World feet of the bent walk: the forward direction of the body follows the tangent."""
    mf, t, bmap, r = walk
    from fourierjax.io.gait_bvh import grounded_motion

    R = 3.0 / bmap.metres_per_unit
    feats, root, yaw = _bend(walk, gait.circle_path(R))
    mot = grounded_motion(t, feats, root, mf.model.channel_names, mf.frame_time_s, body_map=bmap)
    P = motion_joint_positions(mot)
    np.testing.assert_allclose(P[:, bmap.pelvis], np.asarray(root), atol=1e-3)
    left = P[:, bmap.left.hip] - P[:, bmap.right.hip]
    facing = np.arctan2(-left[:, 2], left[:, 0])  # forward = left × up, heading atan2(x, z)
    turn = np.unwrap(facing - facing[0])
    # Pelvis yaw sways a few degrees within the cycle; over the walk it turns as the path does.
    assert abs(turn[-60:].mean() - float(np.asarray(yaw)[-60:].mean())) < np.radians(10)


def test_polyline_follows_segments_and_extends_past_the_end(walk):
    _, _, bmap, r = walk
    L = 1.0 / bmap.metres_per_unit  # a 1 m stretch, then a right angle to the left, 1 m
    path = gait.polyline_path([[0.0, 0.0], [0.0, L], [L, L]])
    _, root, yaw = _bend(walk, path, smoothing=0.05 * L)
    g = np.asarray(root)[:, [0, 2]] - np.asarray(root)[0, [0, 2]]
    travelled = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(g, axis=0), axis=1))])
    first = travelled < 0.9 * L
    np.testing.assert_allclose(g[first, 0], 0.0, atol=1e-3 * L)
    beyond = travelled > 2.2 * L  # past the last point: straight on along +X
    assert beyond.any()
    np.testing.assert_allclose(g[beyond, 1], L, atol=1e-2 * L)
    assert float(np.asarray(yaw)[beyond].mean() - yaw[0]) == pytest.approx(np.pi / 2, abs=0.05)


def test_a_corner_is_rounded_and_the_body_turns_with_the_root(walk):
    """The root walks the path averaged over +-smoothing of arc length: it passes a right angle
    0.354 L inside the corner (the mean of the two half-windows' midpoints, L / (2 sqrt 2)),
    and the body's heading is the root's own direction of travel. Walked as drawn (the heading
    from a chord of at least the mean vertex spacing) the body turned metres before the corner
    while the root walked straight on, then the root's travel turned at once."""
    _, _, bmap, r = walk
    u = 1.0 / bmap.metres_per_unit
    L = 0.25 * float(bmap.leg_length)
    path = gait.polyline_path([[0.0, 0.0], [0.0, 2 * u], [2 * u, 2 * u]])
    _, root, yaw = _bend(walk, path, smoothing=L)
    g = np.asarray(root)[:, [0, 2]] - np.asarray(root)[0, [0, 2]]
    inside = np.linalg.norm(g - [0.0, 2 * u], axis=1).min()
    assert inside == pytest.approx(L / (2 * np.sqrt(2)), rel=0.05), (inside, L)
    # Heading and travel agree (both in the ground plane): yaw about +Y from +Z is atan2(x, z).
    v = np.gradient(g, axis=0)
    moving = np.linalg.norm(v, axis=1) > 1e-3 * np.linalg.norm(v, axis=1).max()
    travel = np.unwrap(np.arctan2(v[moving, 0], v[moving, 1]))
    turn = np.asarray(yaw)[moving] - np.asarray(yaw)[0]
    straight = travel[0]
    # The body keeps the gait's own sway about its heading: compare over the turn, not per frame.
    assert np.abs((travel - straight) - turn).max() < np.radians(8.0)
    assert float(turn[-1]) == pytest.approx(np.pi / 2, abs=0.05)
    # Before the window reaches the corner, the root is on the first segment and faces along it.
    before = np.linalg.norm(g - [0.0, 2 * u], axis=1) > 1.5 * L
    early = before & (g[:, 1] < 2 * u - 1.5 * L)
    np.testing.assert_allclose(g[early, 0], 0.0, atol=1e-3 * u)
    np.testing.assert_allclose(np.asarray(yaw)[early], float(yaw[0]), atol=1e-5)


def test_many_characters_each_with_its_own_path_vmap(walk):
    mf, _, bmap, r = walk
    radii = jnp.asarray([2.0, 3.0, 5.0]) / bmap.metres_per_unit
    paths = jax.vmap(lambda p: gait.GroundPath(p, closed=True))(
        jnp.stack([gait.circle_path(float(R)).points for R in radii]))
    F = jnp.stack([r.features] * 3)
    Rt = jnp.stack([r.root_position] * 3)
    names, pelvis, dt = mf.model.channel_names, bmap.name(bmap.pelvis), mf.frame_time_s
    feats, root, yaw = jax.vmap(lambda f, x, p: gait.follow_path(f, x, p, names, pelvis, dt))(F, Rt, paths)
    for i, R in enumerate(radii):
        one = _bend(walk, gait.circle_path(float(R)))
        np.testing.assert_allclose(np.asarray(root[i]), np.asarray(one[1]), atol=1e-3)
        np.testing.assert_allclose(np.asarray(yaw[i]), np.asarray(one[2]), atol=1e-4)
    assert float(yaw[0, -1] - yaw[0, 0]) > float(yaw[2, -1] - yaw[2, 0])  # a tighter circle turns more


def test_bad_paths_are_refused(walk):
    with pytest.raises(UserError, match="radius"):
        gait.circle_path(0.0)
    with pytest.raises(UserError, match="two distinct points"):
        gait.polyline_path([[1.0, 2.0], [1.0, 2.0]])
    with pytest.raises(UserError, match=r"\[K >= 2, 2\]"):
        gait.GroundPath(jnp.zeros((3, 3)))
    mf, _, bmap, r = walk
    with pytest.raises(UserError, match="pelvis"):
        gait.follow_path(r.features, r.root_position, gait.circle_path(10.0), mf.model.channel_names, "nope",
                         mf.frame_time_s)
    pelvis = bmap.name(bmap.pelvis)
    for bad in (-1, len(r.features), 1.5, True):
        with pytest.raises(UserError, match="start_frame"):
            gait.follow_path(r.features, r.root_position, gait.circle_path(10.0), mf.model.channel_names, pelvis,
                             mf.frame_time_s, start_frame=bad)
    # From frame 10: frame 10 stands at the path's first point, the frames before walk up to it.
    _, root10, _ = gait.follow_path(r.features, r.root_position, gait.circle_path(10.0), mf.model.channel_names,
                                    pelvis, mf.frame_time_s, start_frame=10)
    np.testing.assert_allclose(np.asarray(root10[10])[[0, 2]], np.asarray(r.root_position[10])[[0, 2]], atol=1e-5)
    assert float(jnp.linalg.norm(root10[0, jnp.asarray([0, 2])] - root10[10, jnp.asarray([0, 2])])) > 0.1


def test_synth_path_circle_3(walk, tmp_path, capsys):
    """Issue #21: `synth --path circle:3` keeps the root within 2 cm of the circle (metres,
    with the body map's scale); a TOML polyline and a JSON arc work too."""
    from fourierjax.cli import main

    mf, _, bmap, _ = walk
    src = tmp_path / "m.npz"
    model_io.save_model(src, mf.model, motion=mf.template_motion())
    out = tmp_path / "c.bvh"
    assert main(["synth", str(src), "--seconds", "6", "--path", "circle:3", "--out", str(out)]) == 0
    mot = read_bvh(out)
    from fourierjax import body

    bm = body.infer_body_map(mot)
    root = motion_joint_positions(mot)[:, bm.pelvis]
    R = 3.0 / bmap.metres_per_unit
    # Fit the circle's centre: the file's root starts where the synthesis put it.
    centre = root[0, [0, 2]] + [R, 0.0]
    off = np.abs(np.linalg.norm(root[:, [0, 2]] - centre, axis=1) - R) * bmap.metres_per_unit
    assert off.max() <= 0.02, off.max()
    (tmp_path / "p.toml").write_text("points = [[0, 0], [0, 1.5], [1.5, 1.5]]\n")
    assert main(["synth", str(src), "--seconds", "2", "--path", str(tmp_path / "p.toml"),
                 "--out", str(tmp_path / "p.bvh")]) == 0
    (tmp_path / "a.json").write_text(json.dumps({"arc": {"radius": 2.0, "angle_deg": -90}}))
    assert main(["synth", str(src), "--seconds", "2", "--path", str(tmp_path / "a.json"),
                 "--out", str(tmp_path / "a.bvh")]) == 0
    capsys.readouterr()
    for bad, msg in (("circle:x", "circle:R"), ("circle:0", "non-zero"), (str(tmp_path / "none.toml"), "no such")):
        assert main(["synth", str(src), "--seconds", "1", "--path", bad, "--out", str(tmp_path / "b.bvh")]) == 2
        assert msg in capsys.readouterr().err


def _skating_on_the_circle(walk, result):
    """(skating of the written bent walk, skating of the captured fitted frames, largest distance
    of the root from the circle in m, world foot points), through an independent FK of the
    written motion."""
    from fourierjax import data
    from fourierjax.io.gait_bvh import grounded_motion
    from fourierjax.motion import foot_positions_of

    mf, t, bmap, r = walk
    mot = grounded_motion(t, result.features, result.root_position, mf.model.channel_names, mf.frame_time_s,
                          body_map=bmap)
    dt = mf.frame_time_s
    feet = foot_positions_of(mot, body_map=bmap)
    ours = float(gait.contact_skating(feet, dt, body_map=bmap).mean_speed)
    clip = data.load(CLIP)
    prov = mf.provenance
    clip = clip[prov["frame_start"]:prov["frame_stop"]]
    theirs = float(gait.contact_skating(foot_positions_of(clip, body_map=bmap), dt, body_map=bmap).mean_speed)
    R = 3.0 / bmap.metres_per_unit
    root = motion_joint_positions(mot)[:, bmap.pelvis]
    centre = root[0, [0, 2]] + [R, 0.0]
    off = np.abs(np.linalg.norm(root[:, [0, 2]] - centre, axis=1) - R) * bmap.metres_per_unit
    return ours, theirs, float(off.max()), feet


def test_feet_stay_planted_on_a_circle(walk):
    """Issue #21 item 3: locked after bending (`synthesize_gait(path=...)`), the feet stay planted
    through the turns (skating <= 0.25x the capture's) and the root within 2 cm of the circle;
    bending the already-locked straight walk slides them more."""
    mf, t, bmap, r = walk
    R = 3.0 / bmap.metres_per_unit
    iv = mf.contact_intervals
    on_path = gait.synthesize_gait(mf.model, t.skeleton(), 480, mf.frame_time_s, body_map=bmap,
                                   contact_intervals=iv, path=gait.circle_path(R))
    ours, theirs, off, feet = _skating_on_the_circle(walk, on_path)
    # The walk fixture is the locked straight synthesis: bent after locking.
    feats, root, _ = _bend(walk, gait.circle_path(R), smoothing=0.25 * float(bmap.leg_length))
    bent_after = _skating_on_the_circle(walk, eqx.tree_at(lambda x: (x.features, x.root_position), r,
                                                          (feats, root)))[0]
    print(f"\ncircle:3 skating {ours:.2f} (locked after bending) vs {bent_after:.2f} (bent after locking) vs "
          f"captured {theirs:.2f} units/s; root off the circle {100 * off:.2f} cm")
    assert ours < bent_after
    assert off <= 0.02
    # The result's own feet are the bent, locked ones (what `synth`'s summary measures).
    np.testing.assert_allclose(np.asarray(on_path.foot_positions), feet, atol=2e-3 * R)
    straight_off = gait.synthesize_gait(mf.model, t.skeleton(), 480, mf.frame_time_s, body_map=bmap,
                                        foot_lock=False, path=gait.circle_path(R))
    # The same root: the locked one is integrated from the lock's pre-roll and re-anchored at the
    # path's first point (float32: 6.9e-4 units at most on this circle of radius 53 units).
    np.testing.assert_allclose(np.asarray(straight_off.root_position), np.asarray(on_path.root_position), atol=2e-3)
    # Measured: 0.60 vs 8.94 units/s (0.07x; 0.22x before the pre-roll walked up to the path's
    # first point, 0.26x before the lift of a sliding point became a moving maximum before its
    # easing).
    assert ours <= 0.25 * theirs
    with pytest.raises(UserError, match="GroundPath"):
        gait.synthesize_gait(mf.model, t.skeleton(), 20, mf.frame_time_s, body_map=bmap, path=[[0, 0], [1, 1]])


def test_feet_stay_planted_round_a_corner(walk):
    """A right-angled corner of a polyline, walked with the default smoothing: skating <= 0.25x the
    capture's, as on the circle. Measured 1.57 against 8.94 units/s (0.18x); 3.45 (0.39x) when the
    root walked the corner as drawn."""
    mf, t, bmap, _ = walk
    u = 1.0 / bmap.metres_per_unit
    path = gait.polyline_path([[0.0, 0.0], [0.0, 2 * u], [2 * u, 2 * u]])
    res = gait.synthesize_gait(mf.model, t.skeleton(), 480, mf.frame_time_s, body_map=bmap,
                               contact_intervals=mf.contact_intervals, path=path)
    ours, theirs, _, _ = _skating_on_the_circle(walk, res)
    print(f"\ncorner skating {ours:.2f} vs captured {theirs:.2f} units/s")
    assert ours <= 0.25 * theirs


def test_a_path_at_30_fps_is_every_4th_frame_of_120_fps(walk):
    """Under 100 fps the lock runs on denser frames (`gait.lock_supersampling`), and on a path its
    pre-roll walks up to the path's first point: the 30 fps walk along the circle is the 120 fps
    one at every 4th frame, starting where the path starts."""
    mf, t, bmap, _ = walk
    R = 3.0 / bmap.metres_per_unit
    # A polyline that starts off the origin: re-anchored at its first frame, the root left the path.
    for path in (gait.circle_path(R), gait.polyline_path([[0.5 * R, 0.3 * R], [0.5 * R, 3 * R], [2 * R, 4 * R]])):
        kw = dict(body_map=bmap, contact_intervals=mf.contact_intervals, path=path)
        at30 = gait.synthesize_gait(mf.model, t.skeleton(), 41, 1 / 30, **kw)
        at120 = gait.synthesize_gait(mf.model, t.skeleton(), 161, 1 / 120, **kw)
        np.testing.assert_allclose(np.asarray(at30.root_position), np.asarray(at120.root_position)[::4], atol=1e-3)
        np.testing.assert_allclose(np.asarray(at30.foot_positions), np.asarray(at120.foot_positions)[::4],
                                   atol=1e-3)
