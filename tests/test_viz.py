"""Plots and GIFs of fourierjax.viz on small synthetic inputs (Agg backend, chosen here: no display)."""

import os

import matplotlib
import numpy as np
import pytest
from matplotlib.text import Text
from PIL import Image

from fourierjax import viz

matplotlib.use("Agg")  # viz leaves the backend to its caller; these tests draw to files

# A 6-joint stick figure: pelvis, spine, head, left/right hip-knee chains (Y up, facing +Z).
PARENTS = (-1, 0, 1, 0, 3, 0, 5)
NAMES = ("Hips", "Spine", "Head", "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg")
POSE = np.array([[0, 10, 0], [0, 14, 0], [0, 18, 0], [1, 9, 0], [1, 1, 1], [-1, 9, 0],
                 [-1, 1, -1]], float)


def test_backend_is_agg():
    # The drawing edges (CLI, demo) choose Agg with cli.use_agg; viz itself no longer does.
    from fourierjax.cli import use_agg

    matplotlib.use("svg")
    use_agg()
    assert matplotlib.get_backend().lower() == "agg"


def test_project_side_view_and_oblique():
    p = np.array([[1.0, 2.0, 3.0]])
    np.testing.assert_allclose(viz.project(p, 0.0), [[3.0, 2.0]])
    a = np.radians(30.0)
    np.testing.assert_allclose(viz.project(p, 30.0), [[3 * np.cos(a) - np.sin(a), 2.0]])
    with pytest.raises(ValueError, match=r"\[\.\.\., 3\]"):
        viz.project(np.zeros((2, 2)))


def test_limb_colors_left_right_trunk():
    c = viz.limb_colors(["LeftLeg", "RightArm", "Spine", "LHipJoint", "r_knee", "Head"])
    assert c[0] == c[3] != c[1] == c[4]
    assert c[2] == c[5] not in (c[0], c[1])


def _texts(fig):
    ax = fig.axes[0]
    return ax.get_xlabel(), ax.get_ylabel(), ax.get_title()


def test_stick_figure_labels_and_bones(tmp_path):
    fig = viz.plot_stick_figure(POSE, PARENTS, names=NAMES, title="t")
    x, y, t = _texts(fig)
    assert "(m)" in x and "(m)" in y and t == "t"
    # One line per bone plus the joint markers plus the ground line (axhline).
    ax = fig.axes[0]
    bone_lines = [ln for ln in ax.lines if ln.get_linestyle() == "-" and len(ln.get_xdata()) == 2
                  and ln.get_color() != "#999999"]
    assert len(bone_lines) == len(PARENTS) - 1
    path = viz.save_figure(fig, tmp_path / "stick.png")
    with Image.open(path) as im:
        assert im.size[0] > 100


def test_stick_figure_rejects_wrong_parent_count():
    with pytest.raises(ValueError, match="7 joints but parents has 3"):
        viz.plot_stick_figure(POSE, (-1, 0, 1))


def test_spectrum_finds_the_peak_and_labels(tmp_path):
    dt = 1 / 120
    t = np.arange(600) * dt
    x = np.stack([0.3 * np.sin(2 * np.pi * 1.0 * t), 0.1 * np.sin(2 * np.pi * 2.0 * t)], 1)
    freqs = np.fft.rfftfreq(len(t), dt)
    amp = 2 * np.abs(np.fft.rfft(x, axis=0)) / len(t)
    fig = viz.plot_spectrum(freqs, amp, fundamental_hz=1.0, max_hz=5)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "frequency (Hz)" and "rad" in ax.get_ylabel()
    assert ax.get_legend() is not None
    # The plotted curve peaks at the 1 Hz bin with the sinusoid's amplitude.
    y = ax.lines[0].get_ydata()
    xs = ax.lines[0].get_xdata()
    assert abs(xs[np.argmax(y)] - 1.0) < 1e-9 and abs(y.max() - 0.3) < 1e-6
    viz.save_figure(fig, tmp_path / "s.png")
    fig = viz.plot_spectrum(freqs[:4], amp[:4], stems=True)
    viz.save_figure(fig, tmp_path / "s2.png")
    with pytest.raises(ValueError, match="must be"):
        viz.plot_spectrum(freqs[:5], amp)


def test_decomposition_panels_sum_to_the_approximation(tmp_path):
    t = np.linspace(0, 2, 100)
    off = np.array([0.5, -0.2])
    amp = np.array([[0.3, 0.1], [0.2, 0.05]])
    ph = np.array([[0.1, 0.2], [1.0, -1.0]])
    om = 2 * np.pi
    n = np.arange(1, 3)
    data = off + (amp[None] * np.sin(n * om * t[:, None, None] + ph[None])).sum(-1)
    fig = viz.plot_decomposition(t, data, off, amp, ph, om, channel_labels=["a", "b"])
    axes = fig.axes
    assert len(axes) == 2 + 3  # data, constant, 2 harmonics, sum
    comps = sum(axes[k].lines[0].get_ydata() for k in range(1, 4))
    np.testing.assert_allclose(comps, axes[-1].lines[0].get_ydata(), atol=1e-12)
    np.testing.assert_allclose(axes[-1].lines[0].get_ydata(), data[:, 0], atol=1e-12)
    assert axes[-1].get_xlabel() == "time (s)"
    viz.save_figure(fig, tmp_path / "d.png")


def test_style_scatter_and_hip_rule_and_strip(tmp_path):
    fig = viz.plot_style_scatter(np.array([[0, 0], [1, 2], [3, 1.0]]), ["a", "b", "c"],
                                 explained=[0.7, 0.2], groups=["walk", "walk", "run"],
                                 arrows=[(0, 1)])
    ax = fig.axes[0]
    assert "70%" in ax.get_xlabel() and "20%" in ax.get_ylabel()
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["walk", "run"]
    viz.save_figure(fig, tmp_path / "pca.png")
    ph = np.linspace(0, 2 * np.pi, 50)
    curves = {"L": 15 + np.sin(ph), "N": (16 - (15 + np.sin(ph))) / 16,
              "unuma1995": 15 + np.sin(ph), "continuous": 15 + np.sin(ph), "smooth": 15 + np.sin(ph)}
    fig = viz.plot_hip_rule(ph, curves, gait=0.05, jump=1.0)
    assert len(fig.axes[0].get_legend().get_texts()) == 4
    viz.save_figure(fig, tmp_path / "hip.png")
    fig = viz.plot_stick_strip([POSE, np.stack([POSE, POSE + 1])], PARENTS, ["a", "b"], names=NAMES)
    viz.save_figure(fig, tmp_path / "strip.png")
    fig = viz.plot_posture_range([POSE / 10, POSE / 10], PARENTS, [-1.0, 1.0], names=NAMES)
    assert fig.axes[0].texts[0].get_text() == "-1.00"
    viz.save_figure(fig, tmp_path / "range.png")
    with pytest.raises(ValueError, match="labels"):
        viz.plot_stick_strip([POSE], PARENTS, ["a", "b"])


def test_gif_has_the_requested_frames_and_is_small(tmp_path):
    F = 30
    seq = np.repeat(POSE[None], F, 0)
    seq[:, :, 2] += np.arange(F)[:, None] * 0.5  # walks forward
    seq[:, 4, 2] += np.sin(np.arange(F) / 3)
    path = viz.save_gif([seq, seq], PARENTS, tmp_path / "a.gif", frame_time_s=1 / 30, names=NAMES,
                        titles=["x", "y"], max_frames=10, dpi=40)
    with Image.open(path) as im:
        assert im.n_frames == 10
    assert (tmp_path / "a.gif").stat().st_size < 200_000
    with pytest.raises(ValueError, match="same"):
        viz.save_gif([seq, seq[:5]], PARENTS, tmp_path / "b.gif", frame_time_s=0.1)


def test_crowd_draws_every_bone_coloured_by_value(tmp_path):
    rng = np.random.default_rng(0)
    crowd = POSE[None] + np.stack([rng.uniform(-20, 20, 5), np.zeros(5), rng.uniform(-20, 20, 5)],
                                  axis=1)[:, None]  # [5, J, 3]
    values = np.linspace(-1.0, 1.0, 5)
    fig = viz.plot_crowd(crowd, PARENTS, values, value_label="style", scale=1.0)
    (lc,) = fig.axes[0].collections
    assert len(lc.get_segments()) == 5 * (len(PARENTS) - 1)
    # Colours follow the values (far characters drawn first, each bone its character's value).
    assert sorted(set(np.round(lc.get_array(), 6))) == sorted(np.round(values, 6))
    assert fig.axes[1].get_ylabel() == "style"  # the colour bar
    # One character: the spine -> head bone (straight up) is vertical in the picture, 4 cos(e)
    # long; the left hip -> knee bone goes down and along +Z (to the right at azimuth 0).
    one = viz.plot_crowd(POSE[None], PARENTS, [0.0], scale=1.0, azimuth_deg=0.0, elevation_deg=30.0)
    segs = np.asarray(one.axes[0].collections[0].get_segments())  # bones of joints 1..6
    (u0, w0), (u1, w1) = segs[1]
    assert u0 == pytest.approx(u1) and w1 - w0 == pytest.approx(4 * np.cos(np.radians(30.0)))
    (u0, w0), (u1, w1) = segs[3]  # [1, 9, 0] -> [1, 1, 1]
    assert u1 - u0 == pytest.approx(1.0)
    assert w1 - w0 == pytest.approx(-8 * np.cos(np.radians(30.0)))
    matplotlib.pyplot.close(one)
    viz.save_figure(fig, tmp_path / "crowd.png")
    assert (tmp_path / "crowd.png").stat().st_size > 1000
    with pytest.raises(ValueError, match="values"):
        viz.plot_crowd(crowd, PARENTS, values[:3])
    with pytest.raises(ValueError, match="joints"):
        viz.plot_crowd(crowd, PARENTS[:-1], values)


def test_importing_viz_leaves_the_matplotlib_backend_alone():
    """viz called matplotlib.use("Agg") on import, which replaced Jupyter's inline backend."""
    import os
    import subprocess
    import sys

    code = "import matplotlib; import fourierjax.viz; print(matplotlib.get_backend())"
    env = dict(os.environ, MPLBACKEND="svg", PYTHONPATH=_ROOT)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().lower() == "svg", r.stdout


def test_the_cli_and_the_demo_choose_agg():
    import os
    import subprocess
    import sys

    code = ("import matplotlib; from fourierjax.cli import main\n"
            "main(['plot', 'nope', 'x', '--out', 'x.png']); print(matplotlib.get_backend())")
    env = dict(os.environ, MPLBACKEND="svg", PYTHONPATH=_ROOT)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.stdout.strip().lower() == "agg", (r.stdout, r.stderr)


_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # this tree, for subprocesses


# ---------------------------------------------------------------- pictures a person can read (issue 25)


def _walk(F=30):
    seq = np.repeat(POSE[None], F, 0) * 5.0  # ~1 m tall in CMU units
    seq[:, :, 2] += np.arange(F)[:, None] * 2.0  # walks forward
    seq[:, 4, 2] += 3 * np.sin(np.arange(F) / 3)
    return seq


def test_gif_panels_are_at_least_480_px(tmp_path):
    seq = _walk()
    path = viz.save_gif([seq, seq, seq], PARENTS, tmp_path / "a.gif", frame_time_s=1 / 30,
                        names=NAMES, titles=["a", "b", "c"], max_frames=6, title="three",
                        dpi=64)  # pixel sizes do not depend on dpi
    with Image.open(path) as im:
        w, h = im.size
    assert w >= 3 * 480 and h >= 480, (w, h)  # was 121 x 172 px per panel


def _px(text, dpi):
    return text.get_fontsize() * dpi / 72


def test_gif_text_is_readable_and_ground_ticks_are_labelled():
    dpi = 64
    fig, update, num, _ = viz.gif_figure([_walk(), _walk()], PARENTS, frame_time_s=1 / 30,
                                         names=NAMES, titles=["brisk", "tired"], dpi=dpi,
                                         title="styles", max_frames=10)
    try:
        for i in (0, num - 1):
            update(i)
            fig.canvas.draw()
            renderer = fig.canvas.get_renderer()
            fig_box = fig.bbox
            for ax in fig.axes:
                labels = [t for t in ax.get_xticklabels() if t.get_visible() and t.get_text()]
                visible = [t for t in labels
                           if ax.get_xlim()[0] <= t.get_position()[0] <= ax.get_xlim()[1]]
                assert len(visible) >= 2, [t.get_text() for t in labels]
                for t in visible:
                    float(t.get_text().replace("\u2212", "-"))  # numbers (metres along the ground)
                    assert _px(t, dpi) >= 12
                    bb = t.get_window_extent(renderer)
                    assert fig_box.x0 <= bb.x0 and bb.y0 >= fig_box.y0  # inside the picture
                assert _px(ax.title, dpi) >= 14 and ax.title.get_text()
                assert "(m)" in ax.get_xlabel()
            assert _px(fig._suptitle, dpi) >= 14
        # The camera follows the walker: the ticks under it change from first to last frame.
        update(0)
        x_first = fig.axes[0].get_xlim()
        update(num - 1)
        assert fig.axes[0].get_xlim()[0] > x_first[0]
    finally:
        matplotlib.pyplot.close(fig)


def test_spectrum_colours_channels_by_body_part_with_a_legend(tmp_path):
    from fourierjax import data
    from fourierjax.body import infer_body_map

    motion = data.load("07_01")
    groups = viz.joint_groups(motion.topology.parents, infer_body_map(motion))
    names = motion.topology.names
    assert groups[names.index("LeftFoot")] == "left leg"
    assert groups[names.index("RightHand")] == "right arm"
    assert groups[names.index("Head")] == "trunk and head"
    freqs = np.linspace(0, 8, 50)
    C = len(names)
    amp = np.abs(np.random.default_rng(0).normal(size=(50, C)))
    chans = [f"{n}.expmap0" for n in names] + ["root.vz"]
    assert viz.channel_groups(chans, names, motion.topology.parents, infer_body_map(motion)) == [
        *groups, "trunk and head"]
    assert viz.channel_groups(chans, names, motion.topology.parents, None) is None
    fig = viz.plot_spectrum(freqs, amp, groups=groups, fundamental_hz=1.0)
    ax = fig.axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    for part in ("left leg", "right leg", "left arm", "right arm", "trunk and head"):
        assert any(t.startswith(part + " (") for t in texts), texts
    assert sum(int(t.rsplit("(", 1)[1].rstrip(")")) for t in texts if "(" in t and "Hz" not in t) == C
    curve_colors = {ln.get_color() for ln in ax.lines if ln.get_linestyle() == "-"}
    assert len(curve_colors) == 5  # one colour per body part, not one per channel
    viz.save_figure(fig, tmp_path / "s.png")
    with pytest.raises(ValueError, match="groups"):
        viz.plot_spectrum(freqs, amp, groups=groups[:3])
    fig = viz.plot_spectrum(freqs, amp[:, :3], channel_names=["a", "b", "c"])
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["a", "b", "c"]
    matplotlib.pyplot.close(fig)


def _label_boxes(fig):
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    ax = fig.axes[0]
    # The text's own box (an Annotation's box would include its callout line).
    return ([Text.get_window_extent(t, r) for t in ax.texts if t.get_text()],
            ax.get_window_extent(r))


def test_pca_labels_do_not_overlap():
    # Clusters of nearly equal styles (as the CMU walks of one subject are): the labels used to
    # sit at one fixed offset and pile on top of each other.
    rng = np.random.default_rng(1)
    centres = np.array([[0.0, 0.0], [0.02, 0.01], [-0.01, 0.015], [0.01, -0.02], [1.0, 1.0],
                        [1.01, 0.99], [0.98, 1.02], [-1.0, 0.5], [-0.99, 0.52], [0.5, -1.0]])
    coords = centres + rng.normal(scale=1e-3, size=centres.shape)
    labels = [f"{k:02d}_0{k % 7} walk" for k in range(len(coords))]
    fig = viz.plot_style_scatter(coords, labels, groups=["walk"] * 7 + ["run"] * 3)
    boxes, frame = _label_boxes(fig)
    assert len(boxes) == len(labels)
    for i in range(len(boxes)):
        for j in range(i):
            assert not boxes[i].overlaps(boxes[j]), (labels[i], labels[j])
        assert frame.x0 <= boxes[i].x0 and boxes[i].x1 <= frame.x1  # inside the axes
    matplotlib.pyplot.close(fig)
