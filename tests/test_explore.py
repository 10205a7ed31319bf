"""`fourierjax explore` without a browser: parameter set, TOML config, synth --config, no recompiles, bad input."""

import dataclasses

import numpy as np
import pytest

from fourierjax import data, explore, style
from fourierjax.cli import main
from fourierjax.errors import UserError
from fourierjax.explore import Params

pytest.importorskip("viser", reason="explore needs viser: pip install 'fourierjax[explore]'")


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def library():
    from fourierjax.explore import _engine

    gaits = _engine.fit_clips({n: data.load(n) for n in ("07_01", "02_03")}, {"07_01": "walk", "02_03": "run"})
    return explore.Library(gaits, {"run": style.characteristic(gaits["02_03"].model, gaits["07_01"].model)})


@pytest.fixture(scope="module")
def explorer(library):
    from fourierjax.explore._server import Explorer

    ex = Explorer(library, port=free_port(), stance=False, seconds=1.0, fps=60.0)
    ex.playing = False
    yield ex
    ex.close()


def test_params_refuse_out_of_range():
    Params("a", "b", s=-1.0)
    Params("a", "b", s=2.0)
    for bad in (dict(s=2.01), dict(s=float("nan")), dict(step=-1.0), dict(gait=1.5), dict(hip_rule="x"),
                dict(noise_harmonics=0), dict(fps=0.0), dict(weights=(("w", float("inf")),)),
                dict(path_radius_m=0.1), dict(path_radius_m=-0.2), dict(path_radius_m=float("inf"))):
        with pytest.raises(UserError):
            Params("a", "b", **bad)


def test_edited_model_is_eq3_at_zero_weights(library):
    a, b = library.gait("07_01").model, library.gait("02_03").model
    chars = [library.characteristics["run"]]
    p = Params("07_01", "02_03", s=0.0, weights=(("run", 0.0),))
    m0 = explore.edited_model(a, b, chars, p)
    np.testing.assert_allclose(np.asarray(m0.offset), np.asarray(a.offset), atol=1e-5)
    m1 = explore.edited_model(a, b, chars, dataclasses.replace(p, s=1.0))
    ref = style.interpolate(a, b, 1.0)
    np.testing.assert_allclose(np.asarray(m1.amplitude), np.asarray(ref.amplitude), atol=1e-5)
    # A characteristic weight moves the model (eq. 8).
    m2 = explore.edited_model(a, b, chars, dataclasses.replace(p, weights=(("run", 1.0),)))
    assert np.abs(np.asarray(m2.amplitude) - np.asarray(m0.amplitude)).max() > 1e-2


def test_sliders_do_not_compile_again(explorer):
    from jax import monitoring

    explorer.set(s=0.2, noise_deg=1.0)  # warm: the noise path compiles once
    explorer.set(path_radius_m=2.0)  # and the path
    compiled = []

    def listener(event, duration_secs, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(duration_secs)

    monitoring.register_event_duration_secs_listener(listener)
    try:
        before = explorer.current_positions()
        for change in (dict(s=0.7), dict(s=-0.5), dict(s=1.8), dict(step=1.3), dict(speed=0.6), dict(gait=0.05),
                       dict(jump=0.4), dict(weight_run=0.8), dict(noise_deg=2.5), dict(path_radius_m=4.0),
                       dict(path_radius_m=-2.0), dict(root_motion=False)):
            assert explorer.set(**change), explorer.messages[-1:]
    finally:
        monitoring.unregister_event_duration_listener(listener)
    assert compiled == [], f"{len(compiled)} programs compiled on slider moves"
    assert np.abs(explorer.current_positions() - before).max() > 1e-3
    explorer.set(noise_deg=0.0, root_motion=True, s=0.0, step=1.0, speed=1.0, gait=1.0, jump=0.0, weight_run=0.0,
                 path_radius_m=0.0)


def test_export_equals_synth_config(explorer, tmp_path):
    from fourierjax.io.bvh import read_bvh

    assert explorer.set(s=0.6, step=1.1, weight_run=0.5, noise_deg=1.5, hip_rule="continuous", foot_lock=False,
                        path_radius_m=-2.0)
    bvh, config = explorer.export(tmp_path)
    assert "foot_lock = false" in config.read_text() and "path_radius_m = -2.0" in config.read_text()
    assert main(["synth", "--config", str(config), "--out", str(tmp_path / "again.bvh")]) == 0
    a, b = read_bvh(bvh), read_bvh(tmp_path / "again.bvh")
    assert a.channels.shape == (60, 96)
    np.testing.assert_array_equal(a.channels, b.channels)
    assert a.frame_time_s == b.frame_time_s
    # Another parameter set gives other frames: the config carries the values.
    text = config.read_text().replace("s = 0.6", "s = 0.1")
    (tmp_path / "other.toml").write_text(text)
    assert main(["synth", "--config", str(tmp_path / "other.toml"), "--out", str(tmp_path / "other.bvh")]) == 0
    assert np.abs(read_bvh(tmp_path / "other.bvh").channels - a.channels).max() > 0.1
    explorer.set(s=0.0, step=1.0, weight_run=0.0, noise_deg=0.0, hip_rule="unuma1995", foot_lock=True,
                 path_radius_m=0.0)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('format = "fourierjax.explore_config"', 'format = "x"'), "format"),
    (lambda t: t.replace("version = 1", "version = 9"), "version"),
    (lambda t: t.replace("[gait]", "[gait]\nbogus = 1"), "gait.bogus"),
    (lambda t: t.replace("s = 0.0", "s = 5.0"), "s: must be in"),
    (lambda t: t.replace("root_motion = true", "root_motion = 1"), "root_motion"),
    (lambda t: t.replace("path_radius_m = 0.0", "path_radius_m = 0.1"), "path_radius_m: 0 (straight)"),
    (lambda t: t + "\n[[[", "not a TOML file"),
])
def test_synth_config_refuses_bad_files(explorer, tmp_path, capsys, edit, message):
    _, config = explorer.export(tmp_path)
    config.write_text(edit(config.read_text()))
    capsys.readouterr()
    assert main(["synth", "--config", str(config), "--out", str(tmp_path / "x.bvh")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def test_synth_config_refuses_other_flags(explorer, tmp_path, capsys):
    _, config = explorer.export(tmp_path)
    capsys.readouterr()
    for extra in (["--seconds", "3"], ["--step", "1.2"], ["--add", "x.npz=1"]):
        assert main(["synth", "--config", str(config), "--out", str(tmp_path / "x.bvh"), *extra]) == 2
        assert f"{extra[0]} cannot be combined with --config" in capsys.readouterr().err
    assert not (tmp_path / "x.bvh").exists()


def test_synth_without_model_or_config_is_one_line(capsys, tmp_path):
    assert main(["synth", "--out", str(tmp_path / "x.bvh")]) == 2
    assert "--config" in capsys.readouterr().err


def test_bad_input_is_one_message_and_the_server_keeps_running(explorer, library, tmp_path, capsys):
    from fourierjax import fourier

    count = len(explorer.messages)
    capsys.readouterr()
    assert not explorer.set(s=3.0)
    assert explorer.messages[-1].startswith("s: must be in [-1, 2]")
    assert explorer.params.s == 0.0 and explorer.gui_s.value == 0.0
    assert "Message" in explorer._status.content
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    assert not explorer.load(str(bad))
    assert "broken.bvh" in explorer.messages[-1]
    assert not explorer.load(str(tmp_path / "missing.npz"))
    assert "missing.npz" in explorer.messages[-1]
    # A model that does not fit the skeleton of gait A.
    m = library.gait("02_03").model
    half = fourier.FourierModel(m.offset[:40], m.amplitude[:40], m.phase[:40], m.omega, m.representation,
                                m.channel_names[:40])
    g = library.gait("02_03")
    library.gaits["half"] = explore.Gait("half", half, g.template, g.body_map, "test")
    try:
        assert not explorer.set(b="half")
        assert "half" in explorer.messages[-1]
        assert explorer.params.b == "02_03"
    finally:
        del library.gaits["half"]
    assert len(explorer.messages) == count + 4
    # The same four messages on the console, one line each, no traceback.
    err = capsys.readouterr().err.splitlines()
    assert err == [f"fourierjax explore: {m}" for m in explorer.messages[count:]], err
    assert explorer.set(s=0.5)  # still serving
    assert explorer._status.content == "Ready."
    explorer.set(s=0.0)


def test_binds_localhost_by_default(explorer):
    import argparse

    from fourierjax.cli import explore as cli_explore

    assert explorer.server.get_host() == "127.0.0.1"
    parser = argparse.ArgumentParser()
    cli_explore.add_arguments(parser)
    assert parser.parse_args([]).host == "127.0.0.1"


def test_load_sources_reports_each_bad_source(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("not a bvh")
    lib, messages = explore.load_sources([str(bad), "no_such_clip"], fallback=False)
    assert lib.gaits == {} and len(messages) == 2
    assert "bad.bvh" in messages[0] and "no_such_clip" in messages[1]


def test_foot_lock_toggle_is_the_librarys_locking(explorer):
    from fourierjax import gait

    g = explorer.library.gait(explorer.params.a)
    results = {}
    try:
        for lock in (False, True):
            assert explorer.set(foot_lock=lock)
            results[lock] = explorer.result
            p = explorer.params
            ref = gait.synthesize_gait(explorer.library.gait(p.a).model, g.template.skeleton(), p.num_frames,
                                       p.frame_time_s, body_map=g.body_map, foot_lock=lock)
            # Two float32 programs compiled apart: on the CI machine the root position (26 units)
            # came out 7.9e-5 apart, 3e-6 relative. With the toe hold at toe-off (session 18),
            # 7 of 5,760 locked values (small joint angles) differ by up to 7.2e-5 absolute. Since
            # the lock's denser frames and pre-roll (session 30: root velocities are differences
            # of ~26-unit positions over 1/120 s, one float32 step of which is 2.3e-4 units/s),
            # 2 root velocities differ by up to 1.5e-4.
            np.testing.assert_allclose(np.asarray(explorer.result.features), np.asarray(ref.features),
                                       rtol=2e-5, atol=3e-4)
    finally:
        explorer.set(foot_lock=True)  # the module's explorer is shared: leave it as the default
    skate = {k: float(gait.contact_skating(r.foot_positions, explorer.params.frame_time_s,
                                           body_map=g.body_map).mean_speed) for k, r in results.items()}
    assert skate[True] < 0.7 * skate[False], skate  # planted feet slide less
    assert explorer.params.foot_lock


def test_transition_plays_and_exports_a_bvh_without_config(explorer, tmp_path):
    gait_pos = explorer.positions.copy()
    assert not explorer.transition(5.0)  # longer than the preview after its start
    assert "transition: duration" in explorer.messages[-1]
    assert explorer.transition(0.5)
    assert explorer.mode == "transition"
    assert explorer.positions.shape == gait_pos.shape
    # It starts as gait a (s = 0) and ends as gait b: the last frames differ from a's walk.
    assert np.abs(explorer.positions[-1] - gait_pos[-1]).max() > 0.02
    bvh, config = explorer.export(tmp_path)
    assert config is None and "no config written" in explorer.messages[-1]
    assert list(tmp_path.glob("*.toml")) == []
    from fourierjax.io.bvh import read_bvh

    np.testing.assert_allclose(read_bvh(bvh).channels, explorer.motion.channels, atol=1e-5)  # 6 decimals
    assert explorer.set(s=0.0) and explorer.mode == "gait"


@pytest.mark.parametrize("radius_m", [2.0, -2.0])
def test_path_mode_walks_the_circle(explorer, radius_m):
    g = explorer.library.gait(explorer.params.a)
    straight = explorer.positions[:, g.body_map.pelvis, [0, 2]]
    assert explorer.set(path_radius_m=radius_m) and explorer._sync_gui() is None
    assert explorer.gui_path.value == ("circle r = 2 m, left" if radius_m > 0 else "circle r = 2 m, right")
    ground = explorer.positions[:, g.body_map.pelvis, [0, 2]]
    # The pelvis on the circle through the start, centred on the walker's left (right), at the
    # straight walk's pace; the feet are the library's locked ones.
    r = np.linalg.norm(ground - [radius_m, 0.0], axis=-1)
    np.testing.assert_allclose(r, abs(radius_m), atol=0.02)
    arc = np.abs(radius_m) * np.unwrap(np.arctan2(ground[:, 1], radius_m - ground[:, 0]) * np.sign(radius_m))
    walked = np.linalg.norm(straight[-1] - straight[0])
    assert walked > 0.5 and abs(abs(arc[-1] - arc[0]) - walked) < 0.05 * walked, (arc[-1] - arc[0], walked)
    assert explorer.params.foot_lock and np.isfinite(np.asarray(explorer.result.foot_positions)).all()
    assert explorer.set(path_radius_m=0.0)


def test_crowd_jitters_the_current_style(explorer):
    crowd = explorer.crowd
    crowd.gui_num.value, crowd.gui_jitter.value = 16, 0.0
    crowd.rebuild()
    same = crowd.frame(0.3).astype(np.float64).reshape(16, -1, 3)
    same -= same[:, :1] * [1, 0, 1]  # each walker about its spot
    np.testing.assert_allclose(same, np.broadcast_to(same[:1], same.shape), atol=0.02)
    crowd.gui_jitter.value = 0.5
    crowd.rebuild()
    mixed = crowd.frame(0.3).astype(np.float64).reshape(16, -1, 3)
    mixed -= mixed[:, :1] * [1, 0, 1]
    assert np.abs(mixed - mixed[:1]).max() > 0.05
    crowd.toggle(True)
    try:
        import time

        time.sleep(2.5)
        assert crowd.frames > 2 and crowd.fps > 0 and "frames/s" in crowd.gui_fps.content
    finally:
        crowd.toggle(False)
    assert crowd._thread is None


def test_style_space_point_sets_least_squares_weights(explorer, library):
    panel = explorer.style_space
    assert panel.pca is None  # two gaits: no plane yet
    a, b = library.gait("07_01"), library.gait("02_03")
    library.gaits["mid"] = explore.Gait("mid", style.interpolate(a.model, b.model, 0.5, method="phasor"),
                                        a.template, a.body_map, "test")
    try:
        panel.refresh()
        assert panel.names == ["07_01", "02_03", "mid"]
        # Three models span the plane exactly: the point on the run is the run, whose least-squares
        # weight on the characteristic run - walk, from the walk, is 1.
        assert panel.apply(panel.coords[1])
        (name, w), = explorer.params.weights
        assert name == "run" and abs(w - 1.0) < 0.05, w
        assert explorer.params.s == 0.0 and explorer.gui_weights["run"].value == w
        assert panel.apply(panel.coords[0])
        assert abs(explorer.params.weights[0][1]) < 0.05
    finally:
        del library.gaits["mid"]
        panel.refresh()
    explorer.set(weight_run=0.0)


def test_synth_config_refuses_files_that_are_not_configs(tmp_path, capsys):
    (tmp_path / "model.npz").write_bytes(b"PK\x03\x04\x00\xff\xfe binary")
    (tmp_path / "v.toml").write_text('format = "fourierjax.explore_config"\nversion = true\n')
    (tmp_path / "huge.toml").write_text('format = "fourierjax.explore_config"\nversion = 1\n[models]\na = 1\n')
    for config, message in ((tmp_path, ""), (tmp_path / "model.npz", "not a text file"),
                            (tmp_path / "missing.toml", "missing.toml"), (tmp_path / "v.toml", "version"),
                            (tmp_path / "huge.toml", "models.a")):
        capsys.readouterr()
        assert main(["synth", "--config", str(config), "--out", str(tmp_path / "x.bvh")]) == 2, config
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err, err


def test_view_is_the_fk_of_the_exported_bvh(explorer):
    import jax.numpy as jnp

    from fourierjax import kinematics

    assert explorer.set(s=0.7, step=1.2, weight_run=0.3, path_radius_m=4.0)
    g = explorer.library.gait(explorer.params.a)
    pos = np.asarray(kinematics.joint_positions(g.template.skeleton(), jnp.asarray(explorer.motion.channels)))
    pos = pos * g.body_map.metres_per_unit
    start = pos[0, g.body_map.pelvis] * [1, 0, 1]
    np.testing.assert_allclose(explorer.positions, pos - start, atol=2e-4)  # metres
    explorer.set(s=0.0, step=1.0, weight_run=0.0, path_radius_m=0.0)


def test_no_argument_loads_the_bundled_walks(monkeypatch):
    from fourierjax.explore import _engine

    bundled = explore.Library({}, {})
    monkeypatch.setattr(_engine, "default_library", lambda: bundled)
    assert explore.load_sources([]) == (bundled, [])
    lib, messages = explore.load_sources(["no_such_clip"])
    assert lib is bundled and messages[-1] == "no gait loaded: using the bundled walks and runs"
    assert set(_engine.DEFAULT_GAITS) <= set(data.list())


def test_scrubber_pauses_and_shows_that_frame(explorer):
    from types import SimpleNamespace

    explorer.playing = True
    event = SimpleNamespace(client=object(), target=SimpleNamespace(value=0.5))
    explorer._on_scrub(event)
    assert not explorer.playing and explorer.frame == 30  # 0.5 s at 60 fps
    np.testing.assert_array_equal(explorer.current_positions(), explorer.positions[30])
    explorer._on_scrub(SimpleNamespace(client=None, target=SimpleNamespace(value=0.9)))  # the server's own move
    assert explorer.frame == 30


def test_cli_prints_the_url_and_passes_host_port(monkeypatch, capsys):
    import webbrowser

    from fourierjax import explore as fexplore
    from fourierjax.cli import explore as cli_explore

    seen, opened = {}, []

    class FakeExplorer:
        def __init__(self, library, **kw):
            seen.update(kw, library=library)
            self.url = f"http://{kw['host']}:{kw['port']}"

        def close(self):
            seen["closed"] = True

    def stop():
        raise KeyboardInterrupt

    monkeypatch.setattr(fexplore, "Explorer", FakeExplorer, raising=False)
    monkeypatch.setattr(fexplore, "load_sources", lambda sources: ("lib", [f"read {len(sources)}"]))
    monkeypatch.setattr(cli_explore, "_serve_forever", stop)  # Ctrl-C at once
    monkeypatch.setattr(webbrowser, "open", opened.append)
    from fourierjax import _compile_cache

    monkeypatch.setattr(_compile_cache, "enable_compile_cache", lambda: None)  # in-process: the cache stays off
    assert main(["explore", "--no-browser", "--port", "8123", "a.bvh"]) == 130  # Ctrl-C
    out = capsys.readouterr().out
    assert "open http://127.0.0.1:8123" in out and opened == [] and seen["closed"]
    assert seen["host"] == "127.0.0.1" and seen["messages"] == ["read 1"] and seen["library"] == "lib"
    assert main(["explore", "--host", "0.0.0.0", "--port", "8124"]) == 130
    assert opened == ["http://0.0.0.0:8124"]


@pytest.mark.parametrize("edit", [dict(weights=(("run", 1.0),)), dict(weights=(("run", 1.5),), noise_deg=2.0)])
def test_an_edited_gait_stands_on_the_captured_floor(library, edit):
    """Issue 21's floor defect in the explorer (and `synth --config`, which renders the same): a
    walk plus a characteristic stood on the floor read from its own edited cycle. 07_01 plus the
    run-minus-walk characteristic at 1 and 1.5 floated 5.9 and 8.4 cm over the captured floor
    (02_01 plus its own sank 1.4-1.8 cm under it); the plain walk stands 2.8 cm over it. The
    lowest foot point, by numpy FK of the rendered motion (not the library's)."""
    from fourierjax.body import infer_body_map
    from tests.rigs import world

    src = data.load("07_01")
    bm = infer_body_map(src)
    feet = list(bm.feet[0]) + list(bm.feet[1])

    def lowest(motion):
        P, E, _ = world(motion)
        return np.concatenate([P, E], axis=1)[:, feet, bm.up_axis].min(axis=1) * bm.up_sign

    cm = 100.0 * bm.metres_per_unit
    floor = np.percentile(lowest(src), 2)
    p = Params("07_01", "02_03", s=0.0, seconds=3.0, **edit)
    plain = lowest(explore.render(library, dataclasses.replace(p, weights=(), noise_deg=0.0))[0]).min()
    low = lowest(explore.render(library, p)[0]).min()
    assert (low - floor) * cm >= -0.5  # not under the floor
    assert abs(low - plain) * cm <= 1.0  # nor over it: the plain walk's contact height
    assert explore.edited_ground(library.gait("07_01").model, library.gait("02_03").model,
                                 dataclasses.replace(p, weights=(), noise_deg=0.0)) is None
