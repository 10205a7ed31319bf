"""`fourierjax explore` in a real browser: headless Debian chromium driven by playwright (issue 23)."""

import io
import os
import pathlib
import re
import shutil
import time

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
try:
    from playwright.sync_api import sync_playwright
except ImportError:
    sync_playwright = None
if CHROMIUM is None or sync_playwright is None:
    pytest.skip("no browser: apt-get install chromium (Debian) and pip install playwright==1.65.2",
                allow_module_level=True)
pytest.importorskip("viser", reason="explore needs viser: pip install 'fourierjax[explore]'")

from fourierjax import data, explore, style  # noqa: E402
from fourierjax.cli import main  # noqa: E402

#: Set to write the README's screenshot (docs/explore.png) from this test.
SCREENSHOT_ENV = "FOURIERJAX_README_SCREENSHOT"
#: The 3D view, left of the GUI panel and below the page's notifications.
VIEW = {"x": 0, "y": 160, "width": 620, "height": 540}


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def explorer(tmp_path_factory):
    from fourierjax.explore import _engine
    from fourierjax.explore._server import Explorer

    gaits = _engine.fit_clips({n: data.load(n) for n in ("07_01", "02_03")}, {"07_01": "walk", "02_03": "run"})
    lib = explore.Library(gaits, {"run": style.characteristic(gaits["02_03"].model, gaits["07_01"].model)})
    ex = Explorer(lib, port=free_port(), out_dir=tmp_path_factory.mktemp("export"), seconds=2.0, fps=60.0)
    assert ex.stance.wait(600), "the first stance solve did not finish"
    yield ex
    ex.close()


def _pixels(page) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot(clip=VIEW))).convert("L"), dtype=np.int16)


def _changed(page, before: np.ndarray, timeout_s: float = 20.0) -> float:
    """Fraction of view pixels that differ from `before`, once the view has changed."""
    end = time.monotonic() + timeout_s
    while True:
        frac = float(np.mean(np.abs(_pixels(page) - before) > 24))
        if frac > 0.002 or time.monotonic() > end:
            return frac
        page.wait_for_timeout(200)


def _until(cond, timeout_s: float = 60.0) -> bool:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            return False
        time.sleep(0.1)
    return True


def _check_gif(path, num_frames: int) -> None:
    from PIL import Image, ImageSequence

    with Image.open(path) as im:
        frames = [np.asarray(f.convert("L"), dtype=np.int16) for f in ImageSequence.Iterator(im)]
    # Pillow merges a frame equal to the one before into it (a longer duration).
    assert num_frames // 2 <= len(frames) <= num_frames and frames[0].shape == (360, 480)
    assert max(float(np.mean(np.abs(f - frames[0]) > 24)) for f in frames) > 0.001, "the GIF does not move"


def _slider(page, handle):
    return page.locator(f'[id="{handle._impl.uuid}"] [role="slider"]')


def _control(page, handle):
    return page.locator(f'[id="{handle._impl.uuid}"]')


def _not_converged(real):
    """`solve_stance` whose result says it did not converge (the pose is the real solve's)."""
    import equinox as eqx
    import jax.numpy as jnp

    from fourierjax.stance import StanceResult

    def solve(problem, **kw):
        sol = real(problem, **kw)
        return eqx.tree_at(lambda s: (s.converged, s.result), sol, (jnp.asarray(False), StanceResult.max_steps_reached))
    return solve


def test_browser_slider_shape_set_export_two_tabs(explorer, tmp_path, monkeypatch):
    from fourierjax import stance as fstance
    from fourierjax.io.bvh import read_bvh

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--use-gl=swiftshader"])
        try:
            page = browser.new_page(viewport={"width": 1000, "height": 700})
            page.goto(explorer.url)
            page.get_by_text("Connected").wait_for(timeout=60_000)
            page.get_by_role("button", name="Pause").click()
            assert _until(lambda: not explorer.playing, 10)
            page.wait_for_timeout(1500)
            # The interpolation slider: the pose on screen and the server's joints change.
            joints0, shot0 = explorer.current_positions(), _pixels(page)
            thumb = _slider(page, explorer.gui_s)
            thumb.focus()
            thumb.press("End")  # s = 2: extrapolated past the run
            assert _until(lambda: explorer.params.s == 2.0, 30), explorer.messages[-3:]
            assert np.abs(explorer.current_positions() - joints0).max() > 0.02
            assert _changed(page, shot0) > 0.002, "the character on screen did not change"
            # Foot locking off and on again: the library's locked and unlocked frames.
            joints1 = explorer.current_positions()
            _control(page, explorer.gui_lock).click()
            assert _until(lambda: explorer.params.foot_lock is False, 30), explorer.messages[-3:]
            assert np.abs(explorer.current_positions() - joints1).max() > 1e-3
            _control(page, explorer.gui_lock).click()
            assert _until(lambda: explorer.params.foot_lock is True, 30), explorer.messages[-3:]
            # The path: the walk follows a circle of 2 m (and the export below reproduces it).
            end0 = explorer.positions[-1].copy()
            _control(page, explorer.gui_path).click()
            page.get_by_role("option", name="circle r = 2 m, left").click()
            assert _until(lambda: explorer.params.path_radius_m == 2.0, 60), explorer.messages[-3:]
            assert np.abs(explorer.positions[-1] - end0).max() > 0.1
            # The shape set: the stance changes.
            stance0, solves, shot1 = explorer.stance.positions.copy(), explorer.stance.solves, _pixels(page)
            page.locator(f'[id="{explorer.stance.gui_set._impl.uuid}"]').click()
            page.get_by_role("option", name="weak_recoil").click()
            assert _until(lambda: explorer.stance.solves > solves, 120), explorer.messages[-3:]
            assert np.abs(explorer.stance.positions - stance0).max() > 0.02
            assert _changed(page, shot1) > 0.002, "the stance on screen did not change"
            # A solve that does not converge says so, in the panel and as the page's message.
            solves = explorer.stance.solves
            monkeypatch.setattr(fstance, "solve_stance", _not_converged(fstance.solve_stance))
            explorer.stance.request(delay=0.0)
            assert explorer.stance.wait(60) and explorer.stance.solves == solves + 1
            page.get_by_text(re.compile("^Did not converge$")).wait_for(timeout=20_000)  # the panel, bold
            assert "did not converge: the stance solver ran out of steps" in explorer.messages[-1], explorer.messages
            monkeypatch.undo()
            explorer.stance.request(delay=0.0)
            assert explorer.stance.wait(60) and explorer.stance.solves == solves + 2
            assert not explorer.stance.gui_result.content.startswith("**Did not")
            # Export: the BVH equals `synth --config` of the exported config.
            page.get_by_role("button", name="Export BVH + config").click()
            assert _until(lambda: list(explorer.out_dir.glob("*.toml")), 60)
            config = sorted(explorer.out_dir.glob("*.toml"))[-1]
            bvh = config.with_suffix(".bvh")
            assert _until(bvh.exists, 30)
            assert "path_radius_m = 2.0" in config.read_text() and "foot_lock = true" in config.read_text()
            assert main(["synth", "--config", str(config), "--out", str(tmp_path / "synth.bvh")]) == 0
            np.testing.assert_array_equal(read_bvh(bvh).channels, read_bvh(tmp_path / "synth.bvh").channels)
            # A GIF of the view: one pass of the preview, frames that move.
            page.get_by_role("button", name="Export GIF of this view").click()
            assert _until(lambda: list(explorer.out_dir.glob("*.gif")), 240), explorer.messages[-3:]
            gif = sorted(explorer.out_dir.glob("*.gif"))[-1]
            assert _until(lambda: "frames)" in explorer._status.content, 60)
            _check_gif(gif, explorer.params.num_frames // 4)
            # A BVH that cannot be read: one message in the page, and the server goes on (next step).
            (tmp_path / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
            page.locator('xpath=//label[normalize-space()="BVH or model file"]/ancestor::div[.//input][1]//input'
                         ).fill(str(tmp_path / "broken.bvh"))
            page.get_by_role("button", name="Load").click()
            page.get_by_text("broken.bvh").first.wait_for(timeout=30_000)
            assert "broken.bvh" in explorer.messages[-1], explorer.messages[-3:]
            # A second tab: both are connected, a slider in one moves the other.
            page2 = browser.new_page(viewport={"width": 1000, "height": 700})
            page2.goto(explorer.url)
            page2.get_by_text("Connected").wait_for(timeout=60_000)
            assert _until(lambda: len(explorer.server.get_clients()) == 2, 30)
            thumb2 = _slider(page2, explorer.gui_s)
            thumb2.focus()
            thumb2.press("Home")  # s = -1
            assert _until(lambda: explorer.params.s == -1.0, 30), explorer.messages[-3:]
            assert _until(lambda: _slider(page, explorer.gui_s).get_attribute("aria-valuenow") == "-1", 30)
            if os.environ.get(SCREENSHOT_ENV):
                assert explorer.set(s=0.4, path_radius_m=0.0)
                explorer.gui_file.value = ""
                explorer._sync_gui()  # the path dropdown back to straight
                explorer._send_frame(explorer.params.num_frames // 4)  # the walker near its start
                page.get_by_text("Model A").scroll_into_view_if_needed()  # the gait panel at the top
                for close in page.locator(".mantine-Notification-closeButton").all():
                    close.click()  # the "software WebGL" notice of a headless browser
                page.wait_for_timeout(2000)
                page.screenshot(path=str(pathlib.Path(__file__).resolve().parents[1] / "docs" / "explore.png"))
        finally:
            browser.close()


def test_stance_gizmo_solves_on_release_only(explorer):
    from types import SimpleNamespace

    from fourierjax.explore._stance import SETTLE_S

    panel = explorer.stance
    assert panel.wait(120)
    solves = panel.solves
    gizmo = panel.gizmo_object
    gizmo.position = (0.35, 1.25, 0.75)
    for _ in range(3):  # drag events: no solve
        panel._on_gizmo(SimpleNamespace(phase="update", target=gizmo))
    time.sleep(SETTLE_S + 0.5)
    assert panel.solves == solves
    panel._on_gizmo(SimpleNamespace(phase="end", target=gizmo))  # release
    assert panel.wait(60) and panel.solves == solves + 1
