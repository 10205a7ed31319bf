"""`fourierjax synth --config`: read an explore parameter set (TOML) and redo its synthesis."""

from __future__ import annotations

import pathlib

_SECTIONS = {
    "models": {"a", "b"},
    "gait": {"s", "step", "speed", "gait", "jump", "hip_rule", "root_motion", "foot_lock", "path_radius_m",
             "seconds", "fps"},
    "noise": {"degrees", "harmonics", "seed"},
}


def load_config(path):
    """Read an explore config: `(library, params)` for `fourierjax.explore.render`.

    Arguments:
        path: a TOML file written by `fourierjax explore` (its model and characteristic files
            are read relative to its folder).

    Returns:
        `(explore.Library, explore.Params)`.

    Raises:
        UserError: one line naming the file and the key: not TOML, another format or version,
            an unknown or missing key, a value of the wrong type or out of range, a model file
            that cannot be read.
    """
    import tomllib

    from fourierjax import explore
    from fourierjax.errors import UserError
    from fourierjax.io import model_io

    path = pathlib.Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as err:
        raise UserError(f"--config {path}: not a TOML file ({err})") from None
    except UnicodeDecodeError:
        raise UserError(f"--config {path}: not a text file") from None
    if doc.get("format") != explore.CONFIG_FORMAT:
        raise UserError(f"--config {path}: format must be {explore.CONFIG_FORMAT!r}, got {doc.get('format')!r}")
    if type(doc.get("version")) is not int or doc["version"] != explore.CONFIG_VERSION:
        raise UserError(f"--config {path}: version {doc.get('version')!r} is not supported "
                        f"(this fourierjax reads version {explore.CONFIG_VERSION})")
    unknown = set(doc) - {"format", "version", "characteristics", *_SECTIONS}
    if unknown:
        raise UserError(f"--config {path}: unknown key {sorted(unknown)[0]!r}")
    for section, keys in _SECTIONS.items():
        table = doc.get(section, {})
        if not isinstance(table, dict):
            raise UserError(f"--config {path}: [{section}] must be a table")
        extra = set(table) - keys
        if extra:
            raise UserError(f"--config {path}: unknown key {section}.{sorted(extra)[0]}")
    models = doc.get("models", {})
    for key in ("a", "b"):
        if not isinstance(models.get(key), str):
            raise UserError(f"--config {path}: models.{key} must be a model file name")
    here = path.parent
    gaits = {}
    for key in ("a", "b"):
        mf = model_io.load_model(here / models[key])
        gaits[key] = explore.Gait(key, mf.model, mf.template_motion(), mf.body_map, str(here / models[key]))
        if gaits[key].template is None:
            raise UserError(f"--config {path}: {models[key]}: the model file carries no skeleton")
    chars, weights = {}, []
    table = doc.get("characteristics", {})
    if not isinstance(table, dict):
        raise UserError(f"--config {path}: [characteristics] must be a table")
    for name, entry in table.items():
        if not isinstance(entry, dict) or set(entry) != {"file", "weight"} or not isinstance(entry["file"], str):
            raise UserError(f"--config {path}: characteristics.{name} needs exactly `file` (a name) and `weight`")
        chars[name] = model_io.load_characteristic(here / entry["file"])[0]
        weights.append((name, entry["weight"]))
    g, n = doc.get("gait", {}), doc.get("noise", {})
    fields = {k: g[k] for k in _SECTIONS["gait"] if k in g}
    fields.update({f: n[k] for f, k in (("noise_deg", "degrees"), ("noise_harmonics", "harmonics"),
                                         ("seed", "seed")) if k in n})
    for key in ("root_motion", "foot_lock"):
        if key in fields and not isinstance(fields[key], bool):
            raise UserError(f"--config {path}: gait.{key} must be true or false")
    try:
        params = explore.Params(a="a", b="b", weights=tuple(weights), **fields)
    except UserError as err:
        raise UserError(f"--config {path}: {err}") from None
    return explore.Library(gaits, chars), params


#: `synth` flags the config replaces, with their defaults: given with --config, they are refused
#: (the config says everything; a flag silently ignored would mislead).
_REPLACED = {"model": None, "seconds": None, "fps": None, "add": [], "noise": 0.0, "noise_harmonics": 3,
             "seed": 0, "step": 1.0, "speed": 1.0, "gait": 1.0, "jump": 0.0, "hip_rule": "unuma1995",
             "body_map": None, "root_motion": True, "foot_lock": True, "path": None}


def run_config(args) -> int:
    """`synth --config FILE --out OUT.bvh`: the explorer's export, frame for frame."""
    from fourierjax import explore
    from fourierjax.cli._outputs import write_bvh_as_source
    from fourierjax.errors import UserError

    given = [k for k, v in _REPLACED.items() if hasattr(args, k) and getattr(args, k) != v]
    if given:
        flag = "MODEL" if given[0] == "model" else "--" + given[0].replace("_", "-")
        raise UserError(f"--config: {flag} cannot be combined with --config (the config sets it)")

    out = pathlib.Path(args.out)
    if out.suffix.lower() != ".bvh":
        raise UserError(f"--out: {args.out}: expected a .bvh file")
    if not out.parent.exists():
        raise UserError(f"--out: {out.parent}: no such directory")
    library, params = load_config(args.config)
    from fourierjax import _memory

    model = library.gait("a").model
    from fourierjax import gait

    dense = params.num_frames * (gait.lock_supersampling(params.frame_time_s) if params.foot_lock else 1)
    _memory.check_synthesis(f"--config {args.config}: {params.seconds:g} s at {params.fps:g} fps", dense,
                            model.num_channels, model.num_harmonics)
    motion, _ = explore.render(library, params)
    write_bvh_as_source(motion, out, "y", getattr(args, "out_up", None))  # the explorer's models: Y-up
    print(f"wrote {out}: {params.num_frames} frames at {params.fps:g} fps (config {args.config})")
    return 0
