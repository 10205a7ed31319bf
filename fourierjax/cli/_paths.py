"""Input files of the subcommands: a path, or the name of a bundled clip (e.g. 07_12)."""

from __future__ import annotations

import pathlib


def resolve_input(text: str, argument: str = "", expected: str = "a BVH file") -> pathlib.Path:
    """The file `text` names: an existing path, else a bundled clip's file (the whole file:
    frame numbers are the file's). Raises a UserError naming `argument` (if given) for a
    folder or a name that is neither."""
    from fourierjax import data
    from fourierjax.errors import UserError

    prefix = f"{argument}: " if argument else ""
    if not text.strip():  # pathlib.Path("") is ".", the current folder
        raise UserError(f"{prefix}an empty name, expected {expected}")
    path = pathlib.Path(text)
    if path.exists():
        if path.is_dir():
            raise UserError(f"{prefix}{text} is a directory, expected {expected}")
        return path
    name = text.removesuffix(".bvh")
    if "/" not in text and name in data.list():
        return data.path(name)
    raise UserError(f"{prefix}{text}: no such file (bundled clips: {', '.join(data.list())})")
