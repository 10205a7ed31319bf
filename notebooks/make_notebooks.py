"""Write the tutorial notebooks (outputs stripped) from the cells below: run
``python notebooks/make_notebooks.py`` after editing, commit the .ipynb files without outputs."""

from __future__ import annotations

import pathlib

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = pathlib.Path(__file__).resolve().parent

def gait_cells() -> list[tuple[str, str]]:
    """Notebook 01: fitting, spectrum, decomposition and style algebra (Unuma 1995; Tilmanne)."""
    return [
        ("md", r"""# Gait fitting and style algebra (Unuma 1995; Tilmanne & Dutoit)

A walk is periodic, so each joint angle $\Theta_m(t)$ of a captured walk is well described by a
few harmonics of one fundamental frequency. Unuma et al. (1995, eq. 1) write the *rescaled
Fourier functional model*

$$\Theta_m(t) = A_{m0} + \sum_{n \ge 1} A_{mn} \sin(n\,\omega t + \phi_{mn}),$$

with the time rescaled so that one gait cycle is $2\pi$ (here $\omega$ is kept explicit, in
rad/s). Three harmonics are usually enough, seven at most. This notebook fits such models to
bundled CMU clips, looks at their spectrum and decomposition, then plays with Unuma's style
algebra: inter/extrapolation (eq. 3), a Fourier characteristic and its superposition onto a
run (eq. 7-8), a walk → run transition, and a style-space PCA."""),
        ("code", """import numpy as np
import jax.numpy as jnp
import matplotlib.pyplot as plt
from fourierjax import data, fourier, style, viz
from fourierjax.motion import fit_motions

clips = ["07_01", "07_04", "07_12", "09_01"]   # normal, slow ('tired'), brisk walk; a run
# Cut to 256 frames each: equal shapes share compiled functions (faster on a small CPU).
motions = [data.load(c)[:256] for c in clips]
fits = dict(zip(clips, fit_motions(motions, num_harmonics=3, segment=False, throw=True)))
for c, f in fits.items():
    print(f"{c}: f0 = {f.fundamental_hz:.3f} Hz, RMS {f.rms_deg:.2f} deg, "
          f"variance explained {100 * f.variance_explained_positions:.1f}% (positions)")"""),
        ("md", r"""## The spectrum: why a few harmonics suffice

Tilmanne & Dutoit (Fig. 1) plot the amplitude spectra of every exponential-map channel of a
walk on top of each other. Each curve below is one channel's single-sided amplitude
spectrum (windowed DFT) of the normal walk 07_01; the colour says which body part the joint
belongs to, taken from the clip's body map (not from joint names), and the legend counts the
channels of each part. The dashed lines mark the fitted gait-cycle frequency
$f_0 = \omega / 2\pi$ and its multiples. Almost all the energy sits at $f_0$ and $2 f_0$,
and there is little above $4 f_0$: the reason a model of $N = 2$ or $3$ harmonics reproduces
a walk (Tilmanne & Dutoit keep two)."""),
        ("code", """from fourierjax.motion import joint_expmaps
from fourierjax.spectrum import windowed_amplitude_spectrum

f = fits["07_01"]
sub = motions[0][f.frame_start:f.frame_stop]
xe, enames = joint_expmaps(sub)
moving = np.ptp(xe, axis=0) > 1e-4
freqs, amp = windowed_amplitude_spectrum(xe[:, moving], sub.frame_time_s)
groups = viz.channel_groups([n for n, k in zip(enames, moving) if k], sub.topology.names,
                            sub.topology.parents, f.body_map)
fig = viz.plot_spectrum(freqs, amp, groups=groups, fundamental_hz=f.fundamental_hz,
                        title="07_01: spectra of the exponential-map channels")"""),
        ("md", r"""## One channel, decomposed

The model of one channel is a constant plus a sum of sinusoids. Tilmanne & Dutoit (eq. 1)
use the second-order series

$$P_i(t) = p_{i,0} + p_{i,1}\cos(\omega_0 t + \phi_{i,1}) + p_{i,2}\cos(2\omega_0 t + \phi_{i,2}),$$

whose coefficients are the DFT of the channel at $\omega_0$ and $2\omega_0$ (eq. 2-6). The top
row is the captured left knee and hip flexion of 07_01 (degrees) with the 3-harmonic fit laid
over it; the rows below are the constant $A_{m0}$, each harmonic
$A_{mn}\sin(n\omega t + \phi_{mn})$, and their sum (cf. Tilmanne Fig. 3). The first harmonic
carries the stride; the second and third shape the knee's double bump (loading response,
then swing)."""),
        ("code", """from fourierjax.motion import features_from_motion
x, names = features_from_motion(sub, "euler")
idx = [names.index(n) for n in ("LeftLeg.Xrotation", "LeftUpLeg.Xrotation")]
m = f.raw_model
t = np.arange(len(x)) * f.frame_time_s
fig = viz.plot_decomposition(t, x[:, idx], np.asarray(m.offset)[idx], np.asarray(m.amplitude)[idx],
                             np.asarray(m.phase)[idx], float(m.omega),
                             channel_labels=["knee X", "hip X"], title="07_01 left knee and hip")
print(f"omega = {float(m.omega):.2f} rad/s, amplitudes (deg): {np.degrees(np.asarray(m.amplitude)[idx]).round(1)}")"""),
        ("md", r"""## Interpolation and extrapolation (Unuma eq. 3)

Given the models $\Theta_m$ (normal walk 07_01) and $\Pi_m$ (slow, 'tired' walk 07_04),
Unuma's eq. 3 blends every coefficient and phase with one parameter $s$:

$$\Xi_m(s, t) = \{(1-s)A_{m0} + sB_{m0}\} + \sum_{n \ge 1} \{(1-s)A_{mn} + sB_{mn}\}
\sin\{n t + (1-s)\phi_{mn} + s\psi_{mn}\}.$$

$0 < s < 1$ interpolates (a little tired), $s > 1$ extrapolates beyond the tired walk, and
$s < 0$ goes the other way, towards brisk. Because the time is rescaled to the gait cycle, the
cadence blends too."""),
        ("code", """normal, tired = fits["07_01"].model, fits["07_04"].model
for s in (-0.6, 0.0, 0.5, 1.0, 1.5):
    xi = style.interpolate(normal, tired, s)
    print(f"s = {s:+.1f}: cadence {float(xi.fundamental_hz):.2f} Hz")
np.testing.assert_allclose(style.style_vector(style.interpolate(normal, tired, 0.0)),
                           style.style_vector(normal), atol=1e-5)"""),
        ("md", r"""## Fourier characteristics and superposition (Unuma eq. 7-8)

The difference of two models, $A^{12}_{mn} = A^1_{mn} - A^2_{mn}$ and
$\phi^{12}_{mn} = \phi^1_{mn} - \phi^2_{mn}$ (eq. 7), is a *Fourier characteristic*: here
'briskness' = brisk walk − normal walk. Its characteristic function (eq. 8)

$$\Psi_m(t) = A^{12}_{m0} + \sum_{n \ge 1} A^{12}_{mn}\sin(n t + \phi^{12}_{mn})$$

can be added, with a weight, to another model: a brisk *run* from a run and the briskness of
walks."""),
        ("code", """brisk = style.characteristic(fits["07_12"].model, normal)
run = fits["09_01"].model
brisk_run = style.superpose(run, [brisk], [1.37])
print(f"run {float(run.fundamental_hz):.2f} Hz -> brisk run {float(brisk_run.fundamental_hz):.2f} Hz")
w = style.fit_style_weights(normal, [style.characteristic(tired, normal)], fits["07_12"].model)
print(f"the brisk walk = normal + {float(w[0]):.2f} x (tired - normal): an extrapolation")"""),
        ("md", r"""## A walk → run transition

A transition moves $s$ in eq. 3 from 0 to 1 over a time window (here from 1 s to 2.5 s,
smoothstep). Blending the phases directly would make the motion jump when the cadence
changes; instead the cycle phase $\theta(t) = \int \omega(s(\tau))\,d\tau$ is integrated, so
it always increases. The curve is the left knee's flexion (degrees) against time: walk
amplitude and cadence on the left, the run's larger, faster swing on the right, and no jump
in between."""),
        ("code", """t = jnp.arange(480) / 120.0
y, s, theta = style.transition(normal, run, t, 1.0, 1.5, return_schedule=True)
plt.figure(figsize=(6, 2.5))
plt.plot(t, np.degrees(y[:, names.index("LeftLeg.Xrotation")]))
plt.axvspan(1.0, 2.5, color="#dddddd", zorder=0, label="transition window")
plt.xlabel("time (s)"); plt.ylabel("left knee X (deg)"); plt.title("walk -> run"); plt.legend()
assert np.all(np.diff(np.asarray(theta)) > 0)"""),
        ("md", r"""## Style space

Each model becomes one *style vector*: per channel the offset, each harmonic as a phasor
$(A_{mn}\cos\phi_{mn}, A_{mn}\sin\phi_{mn})$ (so phases near $\pm\pi$ do not tear apart), and
$\log\omega$. A PCA of these vectors (Troje's style space; Tilmanne's 271 numbers per style)
places similar gaits close together: the three walks of subject 07 sit near each other and the
run far away along the first component, whose share of the variance is in the axis label.
Labels are placed so that they do not cover each other."""),
        ("code", """models = [fits[c].model for c in clips]
M = style.style_matrix(models)[:, 3 * 7:]   # joint angles and log(omega); root channels left out
pca = style.style_pca(M, num_components=2)
coords = np.asarray(style.pca_project(pca, M))
fig = viz.plot_style_scatter(coords, clips, explained=np.asarray(pca.explained_variance_ratio),
                             groups=["walk", "walk", "walk", "run"])"""),
    ]


def hip_cells() -> list[tuple[str, str]]:
    """Notebook 02: the step constraints and the hip-height rule (Unuma 1995 §3.1)."""
    return [
        ("md", r"""# Step constraints and the hip-height rule (Unuma 1995 §3.1)

A fitted model gives joint angles only; where the body is comes from constraints. Unuma's
step parameters are `step` (scales the amplitudes $A_{mn}$: longer strides), `speed`, `gait`
and `jump`. The root height comes from the hip-height rule (eq. 4-5) and the root's advance
from the stance foot, which stays where it was put down."""),
        ("code", """import numpy as np
import jax.numpy as jnp
from fourierjax import contacts, data, gait, viz
from fourierjax.motion import fit_motions, foot_positions_of

clips = ["07_01", "09_01"]
motions = {c: data.load(c)[:128] for c in clips}
fits = dict(zip(clips, fit_motions([motions[c] for c in clips], 3, segment=False, throw=True)))

def ground(m):
    pts = contacts.foot_points(m.topology)
    g = contacts.estimate_ground(foot_positions_of(m, pts), m.frame_time_s)
    return pts, gait.groin_joints(m.topology), contacts.sole_clearance(g)

def synth(clip, **kw):
    m = motions[clip]
    pts, groins, clear = ground(m)
    kw.setdefault("foot_lock", False)  # the step constraints alone (foot locking is shown last)
    return gait.synthesize_gait(fits[clip].model, m.skeleton(), 240, m.frame_time_s, feet=pts,
                                groins=groins, clearance=clear, **kw)"""),
        ("md", r"""In a walk one foot is always on the ground, so the hip height is the longer of the two legs'
vertical groin heights (eq. 4):

$$L(t) = \max(L_L(t), L_R(t)).$$

With the root placed at $L(t)$ the lowest foot point touches the ground on every frame:"""),
        ("code", """walk = synth("07_01")
lowest = np.asarray(walk.lowest).min(axis=1)
print("walk: max |lowest foot point| =", float(np.abs(lowest).max()), "units (on the ground)")
assert np.abs(lowest).max() < 1e-3"""),
        ("md", r"""A run has a flight phase, where $L(t)$ no longer is the hip height. With
$N(t) = (L_{max} - L(t)) / L_{max}$, Unuma keeps $L_{Run} = L$ while $N(t) \le gait$ and
otherwise lifts the body (eq. 5):

$$L_{Run}(t) = L(t) + jump\,\sqrt{L_{max} - L(t)}.$$

A smaller `gait` gives more flight, a larger `jump` a higher one:"""),
        ("code", """for g, j in ((1.0, 0.0), (0.06, 1.0), (0.03, 2.5)):
    r = synth("09_01", gait=g, jump=j)
    frac = float(np.mean(np.asarray(r.lowest).min(axis=1) > 1e-3))
    print(f"run gait={g} jump={j}: flight fraction {frac:.2f}")"""),
        ("md", r"""## The three variants of the rule, over two cycles of the fitted run

Top: the leg heights $L_L$, $L_R$ and $L = \max(L_L, L_R)$ against the cycle phase (file
units), with the hip height of each variant of the rule. Bottom: $N(t)$ and the threshold
`gait`. The faithful rule (`unuma1995`) jumps where $N(t)$ crosses `gait`, because
$jump\sqrt{L_{max} - L}$ is not zero there; `continuous` subtracts that step so the hip is
continuous, and `smooth` also blends it over a soft threshold, so velocities stay continuous
too."""),
        ("code", """import jax
from fourierjax import fourier
from fourierjax.kinematics import forward_kinematics
from fourierjax.motion import local_pose_from_features

m = motions["09_01"]; run = fits["09_01"].model
pts, groins, clear = ground(m)
phase = jnp.linspace(0, 2 * np.pi, 200)
feats = fourier.synthesize_phase(run, phase)
sk = m.skeleton()
fk = jax.jit(jax.vmap(lambda f: forward_kinematics(sk, *local_pose_from_features(sk, f, "euler"))))(feats)
foot = contacts.gather_foot_positions(fk.positions, fk.end_site_positions, pts)
leg = gait.leg_heights(fk.positions[:, jnp.asarray(groins)], foot, jnp.asarray(clear))
curves = gait.hip_rule_curves(leg, 0.06, 1.0)
fig = viz.plot_hip_rule(np.asarray(phase), {k: np.asarray(v) for k, v in curves.items()},
                        gait=0.06, jump=1.0)"""),
        ("md", r"""`step` multiplies every $A_{mn}$ ($n \ge 1$): the legs swing farther, and since the stance
foot stays planted the body travels farther in the same time."""),
        ("code", """for s in (0.7, 1.0, 1.3):
    r = synth("07_01", step=s)
    d = float(r.root_position[-1, 2] - r.root_position[0, 2])
    print(f"step {s}: {d * 0.0564:.2f} m in 2 s")"""),
    ]


def stance_cells() -> list[tuple[str, str]]:
    """Notebook 03: expressive stance and shape sets (Neff & Fiume 2004)."""
    return [
        ("md", r"""# Expressive stance and shape sets (Neff & Fiume 2004)

Neff & Fiume solve a standing pose from a few *amplitudes* (sagittal, coronal and transverse
bend of the spine, collar-bone movement, an abdominal offset), spread over the spine's joints
by *shape classes* (e.g. $AbX = sagittalAmplitude \cdot LargeSWeight_{AbX}$), while balance
feedback keeps the centre of mass over the support. The amplitudes minimise a weighted sum
of penalty functions (eq. 5),

$$obj = \sum_i w_i f_i,$$

each $f_i$ made of cubic Hermite segments around a desired value. A *shape set* fixes the
shape classes and maps one *intensity* to the desired values: 0 is neutral, 1 the full
shape, and values beyond extrapolate. Here the poses are solved in one batched call."""),
        ("code", """import numpy as np
import jax
import jax.numpy as jnp
import fourierjax
# The solver takes a while to compile: keep compilations across sessions (as `fourierjax stance`).
fourierjax.enable_compile_cache()
from fourierjax import viz
from fourierjax.motion import motion_joint_positions
from fourierjax.io.stance_bvh import pose_to_motion
from fourierjax.stance.shape_sets import builtin_shape_sets, get_shape_set
from fourierjax.stance.skeleton48 import make_body
from fourierjax.stance.solver import solve_stances, stack_problems

for name, s in builtin_shape_sets().items():
    print(f"{name:14s} {s.description}")"""),
        ("md", r"""Every pose is solved to balance: the centre of mass ends within a fraction of a millimetre of
its target over the feet."""),
        ("code", """body = make_body(1.75)
posture = get_shape_set("posture")
intensities = [-1.0, 0.0, 1.0]
sol = solve_stances(stack_problems([posture.problem(body, i) for i in intensities]))
print("converged", np.asarray(sol.converged), "iterations", np.asarray(sol.iterations))
print("COM error (mm)", 1000 * np.asarray(sol.com_error_m))
assert np.all(np.asarray(sol.converged))"""),
        ("md", r"""## The posture range (Neff & Fiume Fig. 5)

The `posture` shape set follows Alberts' posture scale. Each figure is one solved pose seen
from the side (facing +Z, to the right), with its intensity below it: at −1 the over-erect
officer (chest lifted, spine arched back), at 0 the neutral stance, at +1 the hunched,
dejected posture (the spine curls forward). Whatever the shape, the balance feedback moves
the body so that the centre of mass stays over the feet."""),
        ("code", """motion = pose_to_motion(body, sol.pose)
pos = motion_joint_positions(motion)
fig = viz.plot_posture_range(list(pos), motion.topology.parents, intensities,
                             names=motion.topology.names,
                             title="Alberts' posture scale: over-erect (-1), neutral, hunched (+1)")"""),
        ("md", r"""Recoil from an object 0.7 m ahead and 0.4 m to the left: the same solver, another shape set,
whose desired amplitudes depend on where the object is (shape sets are procedures, not just
vectors). The printed amplitudes grow with the intensity."""),
        ("code", """recoil = get_shape_set("strong_recoil")
obj = jnp.array([0.4, 1.2, 0.7])
sol2 = solve_stances(stack_problems([recoil.problem(body, i, obj) for i in (0.0, 0.5, 1.0)]))
print("amplitudes (rad):\\n", np.round(np.asarray(sol2.amplitudes), 3))"""),
    ]


def build(cells) -> nbformat.NotebookNode:
    nb = new_notebook()
    nb.cells = [new_markdown_cell(src) if kind == "md" else new_code_cell(src) for kind, src in cells]
    # Ids by position (nbformat draws random ones): regenerating changes only the edited cells.
    for i, cell in enumerate(nb.cells):
        cell.id = f"cell-{i:02d}"
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata["language_info"] = {"name": "python"}
    return nb


#: Notebook file -> the function that makes its cells.
NOTEBOOKS = {"01_gait_fitting_and_style.ipynb": gait_cells,
             "02_step_constraints_and_hip_rule.ipynb": hip_cells,
             "03_expressive_stance.ipynb": stance_cells}


def style_on_real_data() -> list[tuple[str, str]]:
    """Cells of notebook 04: recognising and transferring a style on Bandai-1 (issue #22).

    Every cell runs without the data: it then says so, and the figures say so too.
    """
    return [
        ("md", """# Style on real labelled data: recognise it, transfer it (Bandai-1)

Bandai-Namco Research Motion Dataset 1 (CC BY-NC 4.0; never copied into the repository) has 15 acted
styles of walks and runs. We fit a few styles through the body-map pipeline, recognise the style of a
held-out walk take, and put a walk's style on a run two ways: Unuma's eq. 8 (relative to the normal
clips) and relative to each content's mean (`style.transfer(..., method="content_mean")`). The full
study is `python -m experiments style_space` and `docs/findings.md`."""),
        ("code", """import pathlib
import numpy as np
import matplotlib.pyplot as plt
import fourierjax
from fourierjax import style

ROOT = pathlib.Path(fourierjax.__file__).resolve().parent.parent
BANDAI = ROOT / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
HAVE = BANDAI.is_dir()
print("Bandai-1:", BANDAI.resolve() if HAVE else "not found; the cells below skip and say so")

def no_data_figure(title):
    from matplotlib import pyplot
    fig, ax = pyplot.subplots(figsize=(5, 1.5))
    ax.text(0.5, 0.5, "Bandai-1 not found at ../shared/data/mocap/bandai1", ha="center", va="center")
    ax.set_title(title)
    ax.set_axis_off()
    return fig"""),
        ("md", "Fit walks (two takes) and runs of five styles; the fits are cached under /tmp."),
        ("code", """STYLES = ["normal", "happy", "sad", "old", "proud"]
if HAVE:
    from experiments._style_data import find_clips, fit_clips
    pattern = r"dataset-1_(?P<content>[a-z-]+)_(?P<style>[a-z-]+)_(?P<take>\\d+)\\.bvh$"
    clips = find_clips(BANDAI, pattern, ["walk", "run"], STYLES)
    models, skels, maps, motions, failed = fit_clips(clips, 3, "euler",
                                                     pathlib.Path("/tmp/fourierjax_style_space_cache"))
    lab = {(c["content"], c["style"], c["take"]): i for i, c in enumerate(clips)}
    print(len(clips), "clips fitted; failed:", failed)"""),
        ("md", """Recognition, leaving one walk take out: the classifier is trained on the other walk take and on
the runs (each content centred on its training mean), and tested on the held-out take."""),
        ("code", """if HAVE:
    from experiments._style_features import feature_matrix, features
    from experiments.style_space import FEATURE_SETS, loto
    feats = [features(m, s, b) for m, s, b in zip(models, skels, maps)]
    x, cw = feature_matrix(feats, FEATURE_SETS["angles+positions"])
    y = np.array([c["style"] for c in clips], object)
    content = np.array([c["content"] for c in clips])
    take = np.array([c["take"] for c in clips])
    idx, preds = loto(x, cw, y, content, take, "walk", pooled=True, kw={"k": 1, "shrinkage": 0.5, "l2": 0.01})
    for name, p in preds.items():
        print(f"{name}: {np.mean(p == y[idx]):.0%} (chance {1 / len(STYLES):.0%})")"""),
        ("code", """if HAVE:
    cm = np.zeros((len(STYLES), len(STYLES)), int)
    for t, p in zip(y[idx], preds["lda"]):
        cm[STYLES.index(t), STYLES.index(p)] += 1
    fig, ax = plt.subplots(figsize=(4, 3.5))
    ax.imshow(cm, cmap="Blues")
    ax.set_xticks(range(len(STYLES)), STYLES, rotation=45)
    ax.set_yticks(range(len(STYLES)), STYLES)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title("walks, leave one take out (LDA)")
else:
    fig = no_data_figure("recognition")
plt.show()"""),
        ("md", """Transfer walk -> run for each non-normal style S, leaving S out of the content means. The score is
`style.cycle_distance` (root-relative joint positions over one cycle, best cyclic shift) to the real run
in style S, as a ratio to the normal run's distance (1 = no better than not transferring at all)."""),
        ("code", """if HAVE:
    g = lambda c, s: models[lab[(c, s, "001")]]
    skel = skels[lab[("run", "normal", "001")]]
    ratios = {"eq8": [], "content_mean (w=0.5)": []}
    for s in STYLES[1:]:
        target, base = g("run", s), g("run", "normal")
        d0 = float(style.cycle_distance(base, target, skel))
        others = [o for o in STYLES if o != s]
        eq8 = style.transfer(g("walk", s), g("walk", "normal"), base)
        cmt = style.transfer(g("walk", s), [g("walk", o) for o in others], [g("run", o) for o in others],
                            method="content_mean", weight=0.5)
        ratios["eq8"].append(float(style.cycle_distance(eq8, target, skel)) / d0)
        ratios["content_mean (w=0.5)"].append(float(style.cycle_distance(cmt, target, skel)) / d0)
    for k, v in ratios.items():
        print(f"{k}: median distance ratio {np.median(v):.2f}", np.round(v, 2))"""),
        ("code", """if HAVE:
    fig, ax = plt.subplots(figsize=(6, 3))
    xs = np.arange(len(STYLES) - 1)
    for k, (name, v) in enumerate(ratios.items()):
        ax.bar(xs + 0.4 * k - 0.2, v, 0.4, label=name)
    ax.axhline(1.0, color="k", lw=1)
    ax.axhline(0.8, color="k", lw=1, ls=":")
    ax.set_xticks(xs, STYLES[1:])
    ax.set_ylabel("distance / normal run's")
    ax.set_title("walk -> run: lower is closer to the real styled run")
    ax.legend()
else:
    fig = no_data_figure("transfer")
plt.show()"""),
    ]


NOTEBOOKS["04_style_on_real_data.ipynb"] = style_on_real_data


def main() -> None:
    for name, cells in NOTEBOOKS.items():
        nbformat.write(build(cells()), HERE / name)


if __name__ == "__main__":
    main()
