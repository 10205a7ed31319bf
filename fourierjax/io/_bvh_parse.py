"""BVH reading: the hierarchy parsed in Python, the MOTION block in bulk by NumPy."""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Iterator

import numpy as np

from fourierjax.io._bvh_motion import (
    MAX_ABS_VALUE,
    MAX_FRAME_TIME_S,
    MIN_FRAME_TIME_S,
    BVHError,
    Motion,
    _owned_arrays,
    _show,
)
from fourierjax.skeleton import CHANNEL_NAMES, Topology

_CHANNEL_BY_LOWER = {c.lower(): c for c in CHANNEL_NAMES}
_FRAMES_RE = re.compile(r"\s*frames\s*:\s*(\S*)\s*", re.IGNORECASE | re.ASCII)
_FRAME_TIME_RE = re.compile(r"\s*frame\s*time\s*:\s*(\S*)\s*", re.IGNORECASE | re.ASCII)
_INT_RE = re.compile(r"\+?[0-9]{1,9}", re.ASCII)  # counts; int() of 4300+ digits raises
# What a BVH number may look like: ASCII decimals with an optional exponent, or nan/inf (which
# are then rejected as non-finite). Python's float() is laxer: it reads "1_0" as 10 and
# non-ASCII digits ("١٢") as numbers, which no BVH writer produces.
_FLOAT_RE = re.compile(
    r"[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|nan|inf|infinity)",
    re.ASCII | re.IGNORECASE,
)


def read_bvh(path: str | os.PathLike) -> Motion:
    """Read a BVH file.

    Joint names may hold spaces (3ds Max Biped writes ``JOINT Bip01 L Thigh``): every word after
    ``ROOT`` / ``JOINT`` (up to a ``{``) is part of the name, and each word needs a letter or a
    digit, so that junk on the line (``JOINT Neck @@``) is an error rather than a name.

    Arguments:
        path: the file. UTF-8 (a BOM is allowed); LF, CRLF or CR line endings.

    Returns:
        A `Motion` (channel values as in the file: degrees and file units).

    Raises:
        BVHError: for anything wrong, naming the file and the 1-based line: a missing or
            unreadable file (line None), bytes that are not UTF-8, a malformed hierarchy,
            unknown channel names, junk in a joint name, a frame count that does not match the
            rows, rows with the wrong number of values, non-numeric, NaN or infinite values,
            values or OFFSETs beyond +-`MAX_ABS_VALUE` (1e6), zero frames, a frame time outside
            [`MIN_FRAME_TIME_S`, `MAX_FRAME_TIME_S`] (1e-6 s to 60 s), not enough memory for
            the frames. Numbers (OFFSET, Frame Time, frame data) must be ASCII decimals with an
            optional exponent: Python's laxer `float()` spellings (``1_0``, non-ASCII digits)
            are errors.
    """
    name = os.fspath(path)
    try:
        with open(name, "rb") as f:
            raw = f.read()
    except FileNotFoundError:
        raise BVHError(name, None, "no such file") from None
    except IsADirectoryError:
        raise BVHError(name, None, "is a directory, not a BVH file") from None
    except OSError as err:
        raise BVHError(name, None, f"cannot read file: {err.strerror or err}") from None
    except MemoryError:
        raise BVHError(name, None, "not enough memory to read the file") from None
    try:
        # "utf-8-sig" drops a BOM here: `text[1:]` in `parse_bvh` would copy the whole file.
        text = raw.decode("utf-8-sig")
    except MemoryError:
        raise BVHError(name, None, "not enough memory to decode the file") from None
    except UnicodeDecodeError as err:
        line = raw.count(b"\n", 0, err.start) + 1
        raise BVHError(
            name, line, f"not UTF-8 text (byte 0x{raw[err.start]:02x} cannot be decoded)"
        ) from None
    del raw  # the bytes and the text are not both kept while the frames are parsed
    return parse_bvh(text, source=name)


def _lines(text: str, pos: int, lineno: int) -> Iterator[tuple[int, int, str]]:
    """Yields (line number, offset of the next line, line) from `pos`, one line at a time."""
    n = len(text)
    while pos < n:
        end = text.find("\n", pos)
        if end < 0:
            end = n
        yield lineno, end + 1, text[pos:end]
        pos = end + 1
        lineno += 1


class _Joint:
    __slots__ = ("name", "parent", "line", "offset", "channels")

    def __init__(self, name, parent, line):
        self.name, self.parent, self.line = name, parent, line
        self.offset: list[float] | None = None
        self.channels: tuple[str, ...] | None = None


def _strict_float(tok: str) -> float | None:
    """`float(tok)` for a token spelled as a BVH number (`_FLOAT_RE`), else None."""
    return float(tok) if _FLOAT_RE.fullmatch(tok) else None


def _number(tok: str, what: str, err) -> float:
    v = _strict_float(tok)
    if v is None:
        raise err(f"{what}: {_show(tok)} is not a number")
    if not math.isfinite(v):
        raise err(f"{what}: {_show(tok)} is not a finite number")
    if abs(v) > MAX_ABS_VALUE:
        raise err(f"{what}: {_show(tok)} is beyond +-{MAX_ABS_VALUE:g}")
    return v


def parse_bvh(text: str, source: str = "<string>") -> Motion:
    """Parse the text of a BVH file (see `read_bvh`); `source` names it in errors.

    The hierarchy (a few hundred lines) is parsed in Python; the MOTION block is parsed in
    bulk by NumPy (vectorised byte tests for the row structure, a vectorised exact decimal
    parser for the values, with a generic fallback); a bad row is reported with its line.

    Arguments:
        text: the whole file as a string.
        source: the name used in errors and stored in `Motion.source` (None if left default).

    Returns:
        a `Motion`.
    """
    if not isinstance(text, str):
        raise TypeError(f"parse_bvh expects str, got {type(text).__name__}; use read_bvh(path)")
    src = str(source)

    def error(line, message):
        return BVHError(src, line, message)

    if text.startswith("\ufeff"):
        text = text[1:]
    # CRLF needs no rewriting: "\r" is whitespace to every tokenizer here, and lines are
    # counted by "\n". Only old Mac files (CR alone) are converted.
    if "\n" not in text and "\r" in text:
        text = text.replace("\r", "\n")

    lines = _lines(text, 0, 1)
    # -- HIERARCHY keyword
    last_line = 0
    for lineno, _, line in lines:
        last_line = lineno
        toks = line.split()
        if not toks:
            continue
        if toks[0].upper() != "HIERARCHY":
            raise error(lineno, f"expected HIERARCHY, found {_show(toks[0])}")
        if len(toks) > 1:
            raise error(lineno, f"unexpected {_show(toks[1])} after HIERARCHY")
        break
    else:
        raise error(None, "missing HIERARCHY: the file is empty")

    # -- hierarchy: a small state machine over tokens, with an explicit stack (no recursion)
    joints: list[_Joint] = []
    end_parents: list[int] = []
    end_offsets: list[list[float] | None] = []
    seen: dict[str, int] = {}
    stack: list[tuple[str, int]] = []  # ("joint", index) or ("end", index)
    pending: tuple[str, int] | None = None  # a node whose "{" has not been read yet
    motion_line = None
    data_pos = len(text)
    for lineno, next_pos, line in lines:
        last_line = lineno
        toks = line.split()
        if not toks:
            continue
        if toks[0].upper() == "MOTION":
            if pending is not None:
                raise error(lineno, "expected '{' before MOTION")
            if stack:
                kind, k = stack[-1]
                what = f"joint {joints[k].name!r}" if kind == "joint" else "End Site"
                opened = joints[k].line if kind == "joint" else None
                where = f" (opened at line {opened})" if opened else ""
                raise error(lineno, f"unbalanced braces: {what}{where} is not closed by '}}'")
            if not joints:
                raise error(lineno, "the hierarchy has no ROOT joint")
            if len(toks) > 1:
                raise error(lineno, f"unexpected {_show(toks[1])} after MOTION")
            motion_line = lineno
            data_pos = next_pos
            break

        def err(message, _lineno=lineno):
            return error(_lineno, message)

        k = 0
        while k < len(toks):
            tok = toks[k]
            if pending is not None:
                if tok != "{":
                    raise err(f"expected '{{', found {_show(tok)}")
                stack.append(pending)
                pending = None
                k += 1
                continue
            up = tok.upper()
            if up in ("ROOT", "JOINT"):
                if (up == "ROOT") != (not stack):
                    raise err(
                        "ROOT must be at the top level" if up == "ROOT"
                        else "JOINT outside of a ROOT: expected ROOT or MOTION"
                    )
                if stack and stack[-1][0] == "end":
                    raise err("an End Site cannot have child joints")
                rest = toks[k + 1 :]
                brace = bool(rest) and rest[-1] == "{"
                if brace:
                    rest = rest[:-1]
                name = " ".join(rest)
                if not name:
                    raise err(f"{tok} without a name")
                if "{" in name or "}" in name:
                    raise err(f"invalid joint name {_show(name)}")
                # Names may hold spaces (3ds Max Biped writes "Bip01 L Thigh"), so every word
                # after the keyword is part of the name; a word without a letter or digit is
                # junk, not a name ("JOINT Neck @@" made a joint named "Neck @@").
                junk = [w for w in rest if not any(ch.isalnum() for ch in w)]
                if junk:
                    raise err(f"unexpected {_show(junk[0])} in the joint name {_show(name)} "
                              "(every word of a name needs a letter or digit)")
                if name in seen:
                    raise err(f"duplicate joint name {_show(name)} (first at line {seen[name]})")
                seen[name] = lineno
                parent = stack[-1][1] if stack else -1
                joints.append(_Joint(name, parent, lineno))
                node = ("joint", len(joints) - 1)
                if brace:
                    stack.append(node)
                else:
                    pending = node
                break  # the name used the rest of the line
            if up == "END":
                if not stack or stack[-1][0] != "joint":
                    raise err("End Site outside of a joint")
                if k + 1 >= len(toks) or toks[k + 1].upper() != "SITE":
                    raise err("expected 'End Site'")
                end_parents.append(stack[-1][1])
                end_offsets.append(None)
                pending = ("end", len(end_parents) - 1)
                k += 2
                continue
            if not stack:
                raise err(f"expected ROOT or MOTION, found {_show(tok)}")
            kind, idx = stack[-1]
            if up == "OFFSET":
                vals = toks[k + 1 : k + 4]
                if len(vals) != 3:
                    raise err(f"OFFSET needs 3 numbers, found {len(vals)}")
                offset = [_number(v, "OFFSET", err) for v in vals]
                if kind == "joint":
                    if joints[idx].offset is not None:
                        raise err(f"joint {joints[idx].name!r} has a second OFFSET")
                    joints[idx].offset = offset
                else:
                    if end_offsets[idx] is not None:
                        raise err("End Site has a second OFFSET")
                    end_offsets[idx] = offset
                k += 4
                continue
            if up == "CHANNELS":
                if kind != "joint":
                    raise err("an End Site cannot have CHANNELS")
                joint = joints[idx]
                if joint.channels is not None:
                    raise err(f"joint {joint.name!r} has a second CHANNELS line")
                if k + 1 >= len(toks) or not _INT_RE.fullmatch(toks[k + 1]):
                    raise err("CHANNELS must be followed by the number of channels")
                count = int(toks[k + 1])
                names = toks[k + 2 :]
                if len(names) != count:
                    raise err(f"CHANNELS declares {count} channels but lists {len(names)}")
                canon = []
                for c in names:
                    name = _CHANNEL_BY_LOWER.get(c.lower())
                    if name is None:
                        valid = ", ".join(CHANNEL_NAMES)
                        raise err(f"unknown channel name {_show(c)}; expected one of {valid}")
                    if name in canon:
                        raise err(f"channel {name} listed twice for joint {joint.name!r}")
                    canon.append(name)
                joint.channels = tuple(canon)
                break
            if tok == "}":
                if kind == "joint":
                    if joints[idx].offset is None:
                        raise err(f"joint {joints[idx].name!r} has no OFFSET")
                elif end_offsets[idx] is None:
                    raise err("End Site has no OFFSET")
                stack.pop()
                k += 1
                continue
            if tok == "{":
                raise err("unbalanced braces: unexpected '{'")
            raise err(f"unexpected {_show(tok)} in the hierarchy")
    if motion_line is None:
        if pending is not None or stack:
            raise error(last_line, "unexpected end of file inside the hierarchy (missing '}')")
        raise error(last_line, "missing MOTION section after the hierarchy")

    # -- Frames: / Frame Time:
    header: list[tuple[int, str]] = []
    for lineno, next_pos, line in lines:
        last_line = lineno
        if line.strip():
            header.append((lineno, line))
            if len(header) == 2:
                data_pos, data_line = next_pos, lineno + 1
                break
    else:
        raise error(last_line, "MOTION must be followed by 'Frames:' and 'Frame Time:' lines")
    (frames_line, l1), (time_line, l2) = header
    m = _FRAMES_RE.fullmatch(l1)
    if m is None:
        raise error(frames_line, f"expected 'Frames: <count>', found {_show(l1.strip())}")
    if not _INT_RE.fullmatch(m.group(1)):
        raise error(frames_line, f"frame count {_show(m.group(1))} is not a valid count")
    num_frames = int(m.group(1))
    if num_frames == 0:
        raise error(frames_line, "the clip has zero frames")
    m = _FRAME_TIME_RE.fullmatch(l2)
    if m is None:
        raise error(time_line, f"expected 'Frame Time: <seconds>', found {_show(l2.strip())}")
    frame_time = _strict_float(m.group(1))
    if frame_time is None:
        raise error(time_line, f"frame time {_show(m.group(1))} is not a number")
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise error(time_line, f"frame time must be positive, got {_show(m.group(1))}")
    if frame_time < MIN_FRAME_TIME_S:
        raise error(
            time_line, f"frame time {_show(m.group(1))} s is below the minimum "
            f"{MIN_FRAME_TIME_S:g} s (1 MHz); the header is probably corrupt"
        )
    if frame_time > MAX_FRAME_TIME_S:
        raise error(
            time_line, f"frame time {_show(m.group(1))} s is above the maximum "
            f"{MAX_FRAME_TIME_S:g} s (one frame a minute); the header is probably corrupt"
        )

    # -- the skeleton
    try:
        topology = Topology(
            names=tuple(j.name for j in joints),
            parents=tuple(j.parent for j in joints),
            channels=tuple(j.channels or () for j in joints),
            end_site_parents=tuple(end_parents),
        )
    except ValueError as err:  # pragma: no cover - the parser checks all of this first
        raise error(None, f"invalid hierarchy: {err}") from None
    num_channels = topology.num_channels
    if num_channels == 0:
        raise error(motion_line, "the hierarchy declares no channels, so frames carry no data")

    try:
        values = _parse_motion_block(
            text, data_pos, data_line, num_channels, num_frames, frames_line, error,
            topology.flat_channel_names,
        )
        with _owned_arrays():  # `values` is ours: the Motion keeps it instead of a copy
            return Motion(
                topology=topology,
                offsets=np.array([j.offset for j in joints], dtype=np.float64).reshape(-1, 3),
                end_site_offsets=np.array(end_offsets, dtype=np.float64).reshape(-1, 3),
                channels=values,
                frame_time_s=frame_time,
                source=None if source == "<string>" else src,
            )
    except MemoryError:
        raise error(frames_line, f"not enough memory to read {num_frames} frames of "
                                 f"{num_channels} channels") from None


_POW10 = 10.0 ** np.arange(23)  # exact doubles
_MAX_DIGITS = 15  # integers below 1e15 < 2**53 are exact doubles


def _parse_decimals(data: bytes, a, start_pos, end_pos):
    """Values of tokens that are all plain decimals (`[+-]digits[.digits]`), else None.

    The dots are deleted and NumPy's C integer parser reads the mantissas; each value is then
    `mantissa / 10**decimals`, one correctly rounded division of two exact doubles (at most 15
    digits), so it equals `float(token)` bit for bit, -0.0 included. About 3x faster than
    converting the tokens one by one; anything unusual (exponents, nan, junk) returns None and
    the generic path decides. The caller has checked that only digits, '.', '+', '-' and
    whitespace occur.
    """
    num = start_pos.size
    first = a[start_pos]
    signed = (first == 43) | (first == 45)
    if data.count(b"-") + data.count(b"+") != np.count_nonzero(signed):
        return None  # a sign inside a token
    dot_pos = np.flatnonzero(a == 46)
    if dot_pos.size == num and (dot_pos >= start_pos).all() and (dot_pos < end_pos).all():
        dot_tok = np.arange(num)  # the usual case: one dot in every token
    else:
        dot_tok = np.searchsorted(start_pos, dot_pos, side="right") - 1
        if dot_tok.size > 1 and not (np.diff(dot_tok) > 0).all():
            return None  # two dots in a token
    decimals = np.zeros(num, dtype=np.int64)
    decimals[dot_tok] = end_pos[dot_tok] - dot_pos - 1
    has_dot = np.zeros(num, dtype=bool)
    has_dot[dot_tok] = True
    digits = end_pos - start_pos - signed - has_dot
    if digits.min(initial=1) < 1 or digits.max(initial=0) > _MAX_DIGITS:
        return None
    try:
        with warnings.catch_warnings():
            # Older NumPy warned instead of raising on unparsable text; either means "no".
            warnings.simplefilter("error", DeprecationWarning)
            mantissa = np.fromstring(data.translate(None, b"."), dtype=np.int64, sep=" ")
    except (ValueError, DeprecationWarning):  # pragma: no cover - the checks above rule it out
        return None
    if mantissa.size != num:  # pragma: no cover
        return None
    values = np.abs(mantissa).astype(np.float64) / _POW10[decimals]
    return np.where(first == 45, -values, values)


_DECIMAL_BYTES = b"0123456789.+-\t\n\x0b\x0c\r "  # whitespace: what bytes.split() splits on

#: Most bytes of motion text converted at a time (whole lines). The vectorised parser needs
#: ~15 bytes of temporaries per byte of text; in pieces, only one piece's are alive at once.
#: A piece is a 32nd of the block (temporaries under half the file's size), at least
#: `_MIN_CHUNK_BYTES` (fewer, larger NumPy calls) and at most `_CHUNK_BYTES`.
_CHUNK_BYTES = 1 << 21
_MIN_CHUNK_BYTES = 1 << 18


def _pieces(text: str, pos: int, first_line: int):
    """Yields (line number of its first line, piece) of `text[pos:]`: whole lines, pieces sized
    as `_CHUNK_BYTES` says (read at each call, so that a test can make them small)."""
    n = len(text)
    size = max(1, min(_CHUNK_BYTES, max(_MIN_CHUNK_BYTES, (n - pos) // 32)))
    line = first_line
    while pos < n:
        end = pos + size
        if end >= n:
            end = n
        else:
            nl = text.find("\n", end - 1)
            end = n if nl < 0 else nl + 1
        piece = text[pos:end]
        yield line, piece
        line += piece.count("\n")
        pos = end


class _Tokens:
    """The token layout of one piece of motion text (ASCII bytes, no control characters)."""

    __slots__ = ("data", "a", "others", "start_pos", "end_pos", "counts", "rows")

    def __init__(self, piece: str, first_line: int, error):
        if not piece.isascii():
            for lineno, _, line in _lines(piece, 0, first_line):
                if not line.isascii():
                    bad = next(ch for ch in line if ord(ch) > 127)
                    raise error(lineno, f"unexpected character {bad!r} in the motion data")
        data = self.data = piece.encode("ascii")
        a = self.a = np.frombuffer(data, dtype=np.uint8)
        others = self.others = data.translate(None, _DECIMAL_BYTES)  # usually empty
        if min(others, default=32) < 32:  # control bytes other than whitespace
            pos = int(np.argmax((a < 32) & ((a < 9) | (a > 13))))
            raise error(
                first_line + data.count(b"\n", 0, pos),
                f"unexpected control character {chr(a[pos])!r} in the motion data",
            )
        # Tokens are the runs of non-blank bytes; their starts and ends alternate in `edges`.
        blank = np.empty(a.size + 2, dtype=bool)
        blank[0] = blank[-1] = True
        np.less_equal(a, 32, out=blank[1:-1])
        edges = np.flatnonzero(blank[1:] != blank[:-1])
        del blank
        self.start_pos, self.end_pos = edges[0::2], edges[1::2]
        newline_pos = np.flatnonzero(a == 10)
        row_of_token = np.searchsorted(newline_pos, self.start_pos)  # 0-based line in the piece
        self.counts = np.bincount(row_of_token, minlength=newline_pos.size + 1)
        self.rows = np.flatnonzero(self.counts)  # lines that hold data; blank lines are skipped


def _parse_motion_block(text: str, pos: int, first_line, num_channels, num_frames, frames_line,
                        error, channel_names=()):
    """[F, C] float64 from `text[pos:]` (the text after 'Frame Time:'); BVHError naming the
    first bad line.

    The text is read in pieces of whole lines (at most `_CHUNK_BYTES`, 2 MB), twice: the
    first pass checks the row structure (values per line, the frame count) with vectorised
    byte tests, the second converts the values in bulk (`_parse_decimals`, or one
    `np.array(tokens, float)` call per piece) into the one output array. Working memory is the
    output plus one piece's temporaries: with the text, under 4x the file's size (plus ~4 MB
    for files under 8 MB). The errors, and which one is reported first, are those of a single
    pass over the whole block: the first line with a wrong number of values, then a wrong
    frame count, then the first token that is not a number, then the first
    non-finite value, then the first value beyond +-`MAX_ABS_VALUE`.
    """
    frames = 0
    for line0, piece in _pieces(text, pos, first_line):
        tok = _Tokens(piece, line0, error)
        bad = np.flatnonzero(tok.counts[tok.rows] != num_channels)
        if bad.size:
            r = int(tok.rows[bad[0]])
            raise error(
                line0 + r,
                f"frame {frames + int(bad[0])} has {int(tok.counts[r])} values, expected "
                f"{num_channels} (one per channel)",
            )
        frames += tok.rows.size
    if frames != num_frames:
        raise error(frames_line, f"'Frames: {num_frames}' but the file has {frames} rows of frame data")
    out = np.empty(num_frames * num_channels, dtype=np.float64)
    done = 0
    non_finite = big = None  # (line, message) of the first such value, raised after the pass
    for line0, piece in _pieces(text, pos, first_line):
        tok = _Tokens(piece, line0, error)
        values = _piece_values(tok, line0, error)
        if non_finite is None:
            finite = np.isfinite(values)
            if not finite.all():
                i = int(np.argmin(finite))
                f, c = divmod(done + i, num_channels)
                non_finite = (line0 + int(tok.rows[i // num_channels]),
                              f"non-finite value {values[i]} in frame {f} (channel {c})")
            elif big is None:
                over = np.abs(values) > MAX_ABS_VALUE
                if over.any():
                    i = int(np.argmax(over))
                    f, c = divmod(done + i, num_channels)
                    name = f" {channel_names[c]}" if c < len(channel_names) else ""
                    big = (line0 + int(tok.rows[i // num_channels]),
                           f"value {values[i]:g} in frame {f} (channel {c}{name}) is beyond "
                           f"+-{MAX_ABS_VALUE:g}: float32 forward kinematics would overflow; the "
                           "file is probably corrupt")
        out[done : done + values.size] = values
        done += values.size
    if non_finite is not None or big is not None:
        raise error(*(non_finite or big))
    return out.reshape(num_frames, num_channels)


def _piece_values(tok: _Tokens, first_line: int, error) -> np.ndarray:
    """The values of one piece's tokens, in order; BVHError naming the first non-number."""
    values = None if tok.others else _parse_decimals(tok.data, tok.a, tok.start_pos, tok.end_pos)
    if values is not None:
        return values
    data = tok.data
    try:
        if b"_" in tok.others:  # NumPy, like float(), reads "1_0" as 10: not a BVH number
            raise ValueError
        return np.array(data.split(), dtype=np.float64)
    except ValueError:
        lines = data.split(b"\n")
        for r in tok.rows:
            for t in lines[r].split():
                if not _is_float(t):
                    raise error(first_line + int(r), f"{_show(t.decode('ascii'))} is not a number") from None
        raise error(None, "could not parse the motion data") from None  # pragma: no cover


def _is_float(tok: bytes) -> bool:
    if b"_" in tok:
        return False
    try:
        np.array([tok], dtype=np.float64)
    except ValueError:
        return False
    return True
