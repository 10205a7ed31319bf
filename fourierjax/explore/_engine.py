"""The explorer's computations, shared with `synth --config`: gait library, edited model, synthesis."""

from __future__ import annotations

import dataclasses
import functools
import pathlib

import numpy as np
from jaxtyping import Float

from fourierjax._jit import filter_jit
from fourierjax.errors import UserError
from fourierjax.explore._params import Params

#: The walks and runs loaded when `fourierjax explore` gets no argument (bundled CMU clips, one
#: fit), and the characteristics taken from them: name -> (gait, minus gait).
DEFAULT_GAITS = ("07_01", "07_12", "07_04", "02_01", "02_03")
DEFAULT_CHARACTERISTICS = {"brisk": ("07_12", "07_01"), "tired": ("07_04", "07_01"), "run": ("02_03", "02_01")}
DEFAULT_PAIR = ("07_01", "02_03")
NUM_HARMONICS = 5


@dataclasses.dataclass(frozen=True, eq=False)
class Gait:
    """A gait of the library: its model, the skeleton's template motion and body map."""

    name: str
    model: object
    template: object
    body_map: object
    source: str


@dataclasses.dataclass(frozen=True, eq=False)
class Library:
    """The gaits and characteristics an explorer can pick from (names unique)."""

    gaits: dict
    characteristics: dict  # name -> style.Characteristic

    def gait(self, name: str) -> Gait:
        try:
            return self.gaits[name]
        except KeyError:
            raise UserError(f"no gait named {name!r} (loaded: {', '.join(self.gaits)})") from None


def _gait_of(name, model, template, source, body_map=None) -> Gait:
    from fourierjax import gait

    if template is None:
        raise UserError(f"{source}: the model file carries no skeleton to animate")
    # One body map per gait, from its own poses: a map inferred from the edited model would
    # change with every slider (and it is a static argument: each change would compile again).
    bmap = body_map if body_map is not None else gait.model_body_map(model, template.skeleton())
    return Gait(name, model, template, bmap, source)


def fit_clips(named_motions: dict, source: dict) -> dict:
    """Fit clips in one batched call (`motion.fit_motions`, 5 harmonics, Euler): name -> Gait."""
    from fourierjax import motion as fmotion

    names = list(named_motions)
    fits = fmotion.fit_motions([named_motions[n] for n in names], NUM_HARMONICS, "euler", throw=True)
    return {n: _gait_of(n, f.model, named_motions[n], source[n]) for n, f in zip(names, fits, strict=True)}


def default_library() -> Library:
    """The bundled CMU walks and runs (`DEFAULT_GAITS`) and their characteristics."""
    from fourierjax import data, style

    gaits = fit_clips({n: data.load(n) for n in DEFAULT_GAITS}, {n: f"bundled CMU clip {n}" for n in DEFAULT_GAITS})
    chars = {k: style.characteristic(gaits[p].model, gaits[q].model) for k, (p, q) in DEFAULT_CHARACTERISTICS.items()}
    return Library(gaits, chars)


def load_sources(sources, *, fallback: bool = True) -> tuple[Library, list[str]]:
    """A library from command-line arguments: BVH clips, model or characteristic files, bundled
    clip names. A source that cannot be read is one message; the others load.

    Arguments:
        sources: paths or bundled clip names.
        fallback: with no gait loaded, return the default library (else an empty one).

    Returns:
        `(library, messages)`.
    """
    from fourierjax import data
    from fourierjax.io import model_io

    messages, clips, where, gaits, chars = [], {}, {}, {}, {}
    for text in sources:
        path = pathlib.Path(text)
        name = path.stem if path.suffix else text
        try:
            if path.suffix.lower() == ".bvh":
                from fourierjax.io.bvh import read_bvh

                clips[name], where[name] = _drop_rest(read_bvh(path), text), text
            elif path.suffix.lower() == ".npz":
                try:
                    mf = model_io.load_model(path)
                except model_io.ModelFileError as err:
                    if "characteristic" not in str(err):
                        raise
                    chars[name] = model_io.load_characteristic(path)[0]
                    continue
                gaits[name] = _gait_of(name, mf.model, mf.template_motion(), text, mf.stored_body_map)
            elif text in data.list():
                clips[name], where[name] = data.load(text), f"bundled CMU clip {text}"
            else:
                raise UserError(f"{text}: not a .bvh clip, a .npz model file or a bundled clip "
                                f"({', '.join(data.list())})")
        except (UserError, OSError) as err:
            messages.append(str(err))
    if clips:
        try:
            gaits.update(fit_clips(clips, where))
        except UserError as err:
            messages.append(str(err))
    if not gaits and fallback:
        if sources:
            messages.append("no gait loaded: using the bundled walks and runs")
        return default_library(), messages
    return Library(gaits, chars), messages


def _drop_rest(motion, text):
    from fourierjax.data import detect_rest_frames

    motion = motion[detect_rest_frames(motion):]
    if motion.num_frames < 16:
        raise UserError(f"{text}: only {motion.num_frames} motion frames, too short to fit")
    return motion


def check_pair(library: Library, p: Params) -> None:
    """Refuse (one `UserError`) gaits or characteristics that do not fit gait `a`'s channels."""
    from fourierjax import style

    a, b = library.gait(p.a), library.gait(p.b)
    style.check_compatible(a.model, b.model, names=(f"gait {p.a}", f"gait {p.b}"))
    if a.template.topology != b.template.topology:
        raise UserError(f"gait {p.b} is on another skeleton than gait {p.a}")
    for name, _ in p.weights:
        if name not in library.characteristics:
            raise UserError(f"no characteristic named {name!r}")
        style.check_compatible(a.model, library.characteristics[name], names=(f"gait {p.a}", f"characteristic {name}"))


def edited_model(a, b, characteristics, p: Params):
    """The model the panel shows: Unuma eq. 3 between `a` and `b` at `p.s`, plus the weighted
    characteristics (eq. 8) and the noise harmonics (§3.3).

    Arguments:
        a, b: `FourierModel`s on one channel layout.
        characteristics: one `style.Characteristic` per entry of `p.weights`, in that order.
        p: the parameter set.

    Returns:
        A `FourierModel`. Every number of `p` enters as an array: a new value runs the
        already-compiled functions.
    """
    import jax
    import jax.numpy as jnp

    from fourierjax import fourier, style

    dtype = jnp.asarray(a.offset).dtype
    model = style.interpolate(a, b, jnp.asarray(p.s, dtype))
    if characteristics:
        model = style.superpose(model, list(characteristics), jnp.asarray([w for _, w in p.weights], dtype))
    if p.noise_deg > 0:
        amp = np.where(fourier.angle_channel_mask(model.channel_names), np.radians(p.noise_deg), 0.0)
        model = style.add_noise(model, jax.random.key(p.seed), jnp.asarray(amp, dtype), harmonics=p.noise_harmonics)
    return model


def ground_path(gait_a: Gait, radius_m: float):
    """The circle a walk of gait a follows (`gait.circle_path`, file units; None for 0: straight on).

    Arguments:
        gait_a: the gait whose body map gives the units.
        radius_m: `Params.path_radius_m`: > 0 turns left, < 0 right, 0 straight.

    Returns:
        A `gait.GroundPath` or None. The same radius gives the same points: a new radius is a new
        array of one shape, so it runs the already-compiled program.
    """
    if radius_m == 0:
        return None
    return _circle(float(radius_m) / float(gait_a.body_map.metres_per_unit or 1.0))


@functools.lru_cache(maxsize=16)
def _circle(radius_units: float):
    from fourierjax import gait

    return gait.circle_path(abs(radius_units), left=radius_units > 0)


def edited_ground(a, b, p: Params):
    """The model an edited model stands on (`synthesize_result(ground=)`): Unuma eq. 3 alone,
    `style.interpolate(a, b, p.s)`, when characteristics or noise edit it; None otherwise (the
    model's own ground).

    The synthesis reads the floor under a model's own root height and the soles' clearances
    from its own stance (`gait.model_ground`). Eq. 3 between two fitted gaits keeps both with
    the legs; an added characteristic does not (`synth --add`, issue 21: the CMU walk plus half of
    the run-minus-walk characteristic stood 1.9 cm under the captured floor).
    """
    if not p.weights and p.noise_deg <= 0:
        return None
    import jax.numpy as jnp

    from fourierjax import style

    return style.interpolate(a, b, jnp.asarray(p.s, jnp.asarray(a.offset).dtype))


def synthesize_result(gait_a: Gait, model, p: Params, *, ground=None):
    """`gait.synthesize_gait` of `model` for `p.seconds` on gait a's skeleton and body map: the
    step constraints, the library's foot locking (`p.foot_lock`) and the path (`p.path_radius_m`:
    the straight walk is bent onto the circle before the feet are locked, as `synth --path`).

    Arguments:
        ground: the model whose floor and sole clearances the synthesis stands on
            (`edited_ground`), or None for `model`'s own.

    Returns:
        The `gait.GaitResult`.
    """
    from fourierjax import gait

    skeleton = gait_a.template.skeleton()
    floor = clearance = None
    if ground is not None:
        floor, clearance = gait.model_ground(ground, skeleton, body_map=gait_a.body_map)
    return gait.synthesize_gait(
        model, skeleton, p.num_frames, p.frame_time_s, body_map=gait_a.body_map,
        step=p.step, speed=p.speed, gait=p.gait, jump=p.jump, rule=p.hip_rule, root_motion=p.root_motion,
        foot_lock=bool(p.foot_lock), path=ground_path(gait_a, p.path_radius_m), floor=floor, clearance=clearance,
    )


def result_motion(gait_a: Gait, channel_names, result, p: Params):
    """The writeable `io.bvh.Motion` of a `synthesize_result` (`io.gait_bvh.gait_motion`)."""
    from fourierjax.io.gait_bvh import gait_motion

    return gait_motion(gait_a.template, result, channel_names, p.frame_time_s, body_map=gait_a.body_map)


def synthesize_motion(gait_a: Gait, model, p: Params, *, ground=None):
    """Synthesize `p.seconds` of `model` on gait `a`'s skeleton under the step constraints.

    Arguments:
        gait_a: the library gait whose skeleton, template and body map are used.
        model: the edited model (`edited_model`).
        p: the parameter set.
        ground: the model it stands on (`edited_ground`), or None for its own.

    Returns:
        `(motion, result)`: a writeable `io.bvh.Motion` and the `gait.GaitResult`.
    """
    result = synthesize_result(gait_a, model, p, ground=ground)
    return result_motion(gait_a, model.channel_names, result, p), result


@filter_jit
def _view_positions(skeleton, features, root_position, *, representation, pelvis):
    from fourierjax.features import root_relative_positions

    return root_relative_positions(skeleton, features, representation, pelvis) + root_position[:, None, :]


def view_positions(gait_a: Gait, representation: str, result) -> Float[np.ndarray, "T J 3"]:
    """`[T, J, 3]` joint positions (file units) of a `synthesize_result`, straight from its features
    (one jitted FK; the BVH channels are only built for an export).

    Arguments:
        gait_a: the gait whose skeleton and body map were synthesized on.
        representation: the model's representation.
        result: the `gait.GaitResult`.

    Returns:
        The positions FK of the exported BVH gives, up to float32 rounding.
    """
    return np.asarray(_view_positions(gait_a.template.skeleton(), result.features, result.root_position,
                                      representation=representation, pelvis=int(gait_a.body_map.pelvis)))


def render(library: Library, p: Params):
    """`synthesize_motion` of `edited_model` for a parameter set (checked first)."""
    check_pair(library, p)
    a, b = library.gait(p.a), library.gait(p.b)
    chars = [library.characteristics[n] for n, _ in p.weights]
    return synthesize_motion(a, edited_model(a.model, b.model, chars, p), p,
                             ground=edited_ground(a.model, b.model, p))


def transition_motion(library: Library, p: Params, start_s: float, duration_s: float):
    """Gait a → gait b over `duration_s` from `start_s` (Unuma §2.3, `style.transition`), grounded by
    the stance feet (`gait.ground_features`), `p.seconds` long.

    Returns:
        A writeable `io.bvh.Motion`.
    """
    import jax.numpy as jnp

    from fourierjax import gait, style
    from fourierjax.io.gait_bvh import grounded_motion

    check_pair(library, p)
    a, b = library.gait(p.a), library.gait(p.b)
    dtype = jnp.asarray(a.model.offset).dtype
    t = jnp.arange(p.num_frames, dtype=dtype) * p.frame_time_s
    feats = style.transition(a.model, b.model, t, jnp.asarray(start_s, dtype), jnp.asarray(duration_s, dtype))
    feats, root, _, _ = gait.ground_features(feats, a.template.skeleton(), a.model.representation, p.frame_time_s,
                                             body_map=a.body_map)
    return grounded_motion(a.template, feats, root, a.model.channel_names, p.frame_time_s, body_map=a.body_map)
