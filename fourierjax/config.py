"""Experiment configurations in TOML (``configs/experiments/*.toml``), validated on load
against each experiment's schema (:data:`SCHEMAS`), with errors that name the file and the key."""

from __future__ import annotations

import dataclasses
import os
import pathlib
import tomllib
from collections.abc import Callable
from typing import Any

from fourierjax.errors import UserError

__all__ = ["ConfigError", "Field", "SCHEMAS", "load_experiment_config", "validate"]

_REQUIRED = object()


class ConfigError(UserError):
    """A configuration file that cannot be used; the message names the file and the key."""


@dataclasses.dataclass(frozen=True)
class Field:
    """One key of a schema: a checker returning an error text (or None), a default, a doc."""

    check: Callable[[Any], str | None]
    default: Any = _REQUIRED
    doc: str = ""


def _is_num(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def number(lo: float | None = None, hi: float | None = None) -> Callable[[Any], str | None]:
    """A real number in ``[lo, hi]``."""

    def check(v):
        rng = f" in [{lo}, {hi}]" if lo is not None and hi is not None else (
            f" >= {lo}" if lo is not None else (f" <= {hi}" if hi is not None else ""))
        if not _is_num(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
            return f"expected a number{rng}, got {v!r}"
        return None

    return check


def integer(lo: int | None = None, hi: int | None = None) -> Callable[[Any], str | None]:
    """An integer in ``[lo, hi]``."""

    def check(v):
        if not isinstance(v, int) or isinstance(v, bool) or (lo is not None and v < lo) or (
                hi is not None and v > hi):
            return f"expected an integer in [{lo}, {hi}], got {v!r}"
        return None

    return check


def list_of(item: Callable[[Any], str | None], what: str, min_len: int = 1):
    """A list of at least ``min_len`` items, each passing ``item``."""

    def check(v):
        if not isinstance(v, list) or len(v) < min_len or any(item(x) for x in v):
            return f"expected a list of {what} (at least {min_len}), got {v!r}"
        return None

    return check


def choice(*options: str) -> Callable[[Any], str | None]:
    """One of the given strings."""

    def check(v):
        if v not in options:
            return f"expected one of {list(options)}, got {v!r}"
        return None

    return check


def boolean(v) -> str | None:
    return None if isinstance(v, bool) else f"expected true or false, got {v!r}"


def _clip(v) -> str | None:
    from fourierjax import data

    if not isinstance(v, str) or v not in data.list():
        return f"unknown clip {v!r} (bundled: {', '.join(data.list())})"
    return None


def clips(min_len: int = 1) -> Callable[[Any], str | None]:
    """A list of bundled clip names."""

    def check(v):
        if not isinstance(v, list) or len(v) < min_len:
            return f"expected a list of bundled clip names (at least {min_len}), got {v!r}"
        for x in v:
            err = _clip(x)
            if err:
                return err
        return None

    return check


def clip(v) -> str | None:
    return _clip(v)


_NUMS = list_of(number(), "numbers")
_N = list_of(integer(1, 32), "integers in [1, 32]")

#: Schema of every experiment: key -> Field. ``experiment`` and ``[small]`` are implicit.
SCHEMAS: dict[str, dict[str, Field]] = {
    "fit_quality": {
        "clips": Field(clips(), doc="bundled clips to fit"),
        "harmonics": Field(_N, doc="numbers of harmonics N to compare"),
        "representation": Field(choice("euler", "expmap", "tangent"), "euler", "rotation channels"),
        "reference_harmonics": Field(integer(1, 32), 3, "N of the fit that finds omega"),
        "troje_variance": Field(number(0, 1), 0.99,
                                "variance of a normal walk carried by 2 harmonics (Troje)"),
    },
    "style": {
        "normal": Field(clip, doc="normal walk"),
        "tired": Field(clip, doc="slow/tired walk (Unuma's Pi)"),
        "brisk": Field(clip, doc="brisk walk (for the characteristic)"),
        "run": Field(clip, doc="run the briskness is added to"),
        "harmonics": Field(integer(1, 16), 3),
        "s_values": Field(_NUMS, doc="inter/extrapolation parameters s (Unuma eq. 3)"),
        "weights": Field(_NUMS, doc="superposition weights of (brisk - normal) on the run"),
        "seconds": Field(number(0.5, 60), 4.0, "length of synthesized motions"),
    },
    "hip_rule": {
        "walk": Field(clip, doc="walk for the step sweep"),
        "run": Field(clip, doc="run for the gait/jump sweep"),
        "harmonics": Field(integer(1, 16), 3),
        "gaits": Field(list_of(number(0, 1), "numbers in [0, 1]"), doc="gait thresholds"),
        "jumps": Field(list_of(number(0, 10), "numbers in [0, 10]"), doc="jump heights"),
        "steps": Field(list_of(number(0.1, 3), "numbers in [0.1, 3]"), doc="step scales"),
        "seconds": Field(number(0.5, 60), 4.0),
        "rules": Field(list_of(choice("unuma1995", "continuous", "smooth"), "rule names"),
                       ["unuma1995", "continuous", "smooth"]),
    },
    "stance": {
        "shape_sets": Field(list_of(lambda v: None if isinstance(v, str) else "str",
                                    "shape-set names"), doc="shape sets to sweep"),
        "intensities": Field(list_of(number(-3, 3), "numbers in [-3, 3]"),
                             doc="intensities of the sweep"),
        "reference": Field(boolean, True, "also run the direction-set reference solver"),
        "reference_max_problems": Field(integer(1, 1000), 100),
    },
}


def _is_str(v) -> str | None:
    return None if isinstance(v, str) and v else f"expected a non-empty string, got {v!r}"


def _pattern(v) -> str | None:
    import re

    try:
        rx = re.compile(v)
    except (re.error, TypeError) as err:
        return f"expected a regular expression, got {v!r} ({err})"
    missing = {"content", "style", "take"} - set(rx.groupindex)
    return f"the pattern needs named groups {sorted(missing)}" if missing else None


def _pairs(v) -> str | None:
    if not isinstance(v, list) or not all(isinstance(p, list) and len(p) == 2 and all(isinstance(s, str) for s in p)
                                          for p in v):
        return f"expected a list of [source, target] content pairs, got {v!r}"
    return None


_STRS = list_of(_is_str, "strings")

SCHEMAS["style_space"] = {
    "folders": Field(_STRS, doc="folders to search, relative to the repository root; the first that exists"),
    "pattern": Field(_pattern, r"dataset-1_(?P<content>[a-z-]+)_(?P<style>[a-z-]+)_(?P<take>\d+)\.bvh$",
                     "file-name regular expression with groups content, style, take"),
    "contents": Field(_STRS, ["walk", "run", "dash", "walk-back", "walk-left", "walk-right"],
                      "locomotion contents to fit"),
    "styles": Field(list_of(_is_str, "strings", min_len=0), [], "styles to use (empty: all)"),
    "normal": Field(_is_str, "normal", "the neutral style"),
    "recognition_content": Field(_is_str, "walk", "the content of the leave-one-take-out recognition"),
    "harmonics": Field(integer(1, 16), 3),
    "representations": Field(list_of(choice("euler", "expmap", "tangent"), "representations"), ["euler", "expmap"],
                             "rotation channels to compare (the first is the main one)"),
    "pca_k": Field(list_of(integer(1, 1000), "integers"), [2, 5, 10, 20]),
    "knn": Field(integer(1, 50), 1, "k of the k-NN classifier"),
    "shrinkage": Field(number(0, 1), 0.5, "LDA covariance shrinkage towards the identity"),
    "l2": Field(number(0, 1e6), 0.01, "L2 penalty of the logistic regression (z-scored features)"),
    "ridge": Field(number(0, 1e6), 30.0, "ridge penalty of the style-space map (z-scored)"),
    "transfer_weight": Field(number(0, 3), 0.5, "weight of the fixed-weight content-mean transfer"),
    "weight_grid": Field(list_of(number(0, 3), "numbers"), [0.25, 0.5, 0.75, 1.0],
                         "weights the cross-validated content-mean transfer chooses from"),
    "transfers": Field(_pairs, [["walk", "run"], ["walk", "dash"], ["walk", "walk-back"], ["run", "walk"]]),
    "weights": Field(list_of(number(0, 3), "numbers"), [0.0, 0.5, 1.0, 1.5], "weights of the limb-flip check"),
    "num_samples": Field(integer(8, 512), 32, "cycle samples of the distance"),
    "cache": Field(_is_str, "/tmp/fourierjax_style_space_cache",
                   "where fitted models are cached (outside the repository)"),
}

SCHEMAS["any_skeleton"] = {
    "clips": Field(clips(), doc="bundled walks and runs to rewrite into each convention"),
    "conventions": Field(list_of(_is_str, "convention names", min_len=0),
                         doc="tests.conventions / tests.rigs rewrites to compare with the CMU clips"),
    "harmonics": Field(integer(1, 16), 3),
    "representation": Field(choice("euler", "expmap", "tangent"), "tangent",
                            "rotation channels of the fits (the command line's default: tangent)"),
    "max_frames": Field(integer(16, 100000), 400, "frames of each clip (after its rest frames)"),
    "synth_frames": Field(integer(16, 10000), 240, "frames of each synthesized gait"),
    "bandai_contents": Field(list_of(_is_str, "contents", min_len=0), ["walk", "run", "dash", "walk-back"],
                             "Bandai-1 contents of the per-content table (skipped when the data is absent)"),
}


def validate(raw: dict, schema: dict[str, Field], where: str) -> dict:
    """Check ``raw`` against ``schema``; return it with defaults filled in.

    Raises:
        ConfigError: naming ``where`` and the offending key.
    """
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a table of keys, got {type(raw).__name__}")
    unknown = sorted(set(raw) - set(schema))
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(schema)})")
    out = {}
    for key, field in schema.items():
        if key not in raw:
            if field.default is _REQUIRED:
                raise ConfigError(f"{where}: missing required key {key!r} ({field.doc})")
            out[key] = field.default
            continue
        err = field.check(raw[key])
        if err:
            raise ConfigError(f"{where}: key {key!r}: {err}")
        out[key] = raw[key]
    return out


def load_experiment_config(path: str | os.PathLike, *, small: bool = False,
                           experiment: str | None = None) -> dict:
    """Read and validate an experiment config (TOML).

    A file names its experiment and sets that experiment's keys; a ``[small]`` table overrides
    some of them for the quick setting CI runs::

        experiment = "fit_quality"
        clips = ["02_01", "07_01"]
        harmonics = [1, 2, 3, 7]

        [small]
        clips = ["07_01"]

    Arguments:
        path: the ``.toml`` file.
        small: apply its ``[small]`` table (the CI setting).
        experiment: if given, the file's ``experiment`` key must equal it.

    Returns:
        The validated settings with defaults, plus ``"experiment"`` and ``"small"``.

    Raises:
        ConfigError: (a UserError) the file is missing, not TOML, or a key is wrong (an unknown
            key, a missing required key, a wrong type or a value out of range:
            ``configs/x.toml: key 'harmonics': expected a list of integers >= 1, got ['a']``).
    """
    p = pathlib.Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such config file")
    try:
        raw = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(f"{p}: not valid TOML: {err}") from None
    name = raw.pop("experiment", None)
    if name not in SCHEMAS:
        raise ConfigError(f"{p}: key 'experiment': expected one of {list(SCHEMAS)}, got {name!r}")
    if experiment is not None and name != experiment:
        raise ConfigError(f"{p}: key 'experiment': this script runs {experiment!r}, the file "
                          f"is for {name!r}")
    overrides = raw.pop("small", {})
    schema = SCHEMAS[name]
    cfg = validate(raw, schema, str(p))
    if not isinstance(overrides, dict):
        raise ConfigError(f"{p}: key 'small': expected a table [small]")
    unknown = sorted(set(overrides) - set(schema))
    if unknown:
        raise ConfigError(f"{p}: [small]: unknown key {unknown[0]!r} (known: {', '.join(schema)})")
    if small:
        cfg = validate({**{k: v for k, v in cfg.items()}, **overrides}, schema, f"{p} [small]")
    else:
        validate({**cfg, **overrides}, schema, f"{p} [small]")  # check it now, not in CI
    return {**cfg, "experiment": name, "small": small}
