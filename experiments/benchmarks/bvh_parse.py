"""BVH parse speed (MB/s): `fourierjax.io.parse_bvh` against a token-by-token pure-Python parse."""

from __future__ import annotations

import numpy as np

from experiments.benchmarks._common import Record, timeit


def python_parse(text: str):
    """The obvious pure-Python BVH reader: split into tokens, walk them, `float()` each value.

    Returns `(names, parents, channels_per_joint, offsets [J,3], frame_time, values [F, C])`.
    """
    tok = text.split()
    i = 0
    names, parents, chans, offsets = [], [], [], []
    stack: list[int] = []
    assert tok[i].upper() == "HIERARCHY"
    i += 1
    last = -1
    while tok[i].upper() != "MOTION":
        t = tok[i]
        u = t.upper()
        if u in ("ROOT", "JOINT"):
            names.append(tok[i + 1])
            parents.append(stack[-1] if stack else -1)
            last = len(names) - 1
            chans.append([])
            offsets.append([0.0, 0.0, 0.0])
            i += 2
        elif u == "END":
            last = -2  # an End Site: its OFFSET is read and dropped
            i += 2
        elif t == "{":
            stack.append(last)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif u == "OFFSET":
            vals = [float(tok[i + 1]), float(tok[i + 2]), float(tok[i + 3])]
            if stack and stack[-1] >= 0 and last != -2:
                offsets[stack[-1]] = vals
            i += 4
        elif u == "CHANNELS":
            n = int(tok[i + 1])
            chans[stack[-1]] = tok[i + 2 : i + 2 + n]
            i += 2 + n
        else:
            raise ValueError(f"unexpected token {t!r}")
    i += 1  # MOTION
    assert tok[i].lower() == "frames:"
    frames = int(tok[i + 1])
    i += 2
    assert tok[i].lower() == "frame" and tok[i + 1].lower() == "time:"
    frame_time = float(tok[i + 2])
    i += 3
    C = sum(len(c) for c in chans)
    values = []
    for _ in range(frames):
        row = []
        for _ in range(C):
            row.append(float(tok[i]))
            i += 1
        values.append(row)
    return names, parents, chans, np.asarray(offsets), frame_time, np.asarray(values)


def run(size: str) -> list[Record]:
    from fourierjax import data
    from fourierjax.io import parse_bvh

    names = data.list() if size == "full" else ["07_01"]
    texts = [data.path(n).read_text() for n in names]
    total_mb = sum(len(t.encode()) for t in texts) / 1e6
    repeats = 5 if size == "full" else 1

    # Same answer first: the baseline is a real parser, not a tokenizer.
    for t in texts[:1]:
        ref = python_parse(t)
        m = parse_bvh(t)
        np.testing.assert_allclose(m.channels, ref[5])

    ours = timeit(lambda: [parse_bvh(t) for t in texts], repeats=repeats)
    base = timeit(lambda: [python_parse(t) for t in texts], repeats=max(1, repeats // 2))
    rec = Record(
        "bvh_parse",
        total_mb / ours["median"],
        total_mb / base["median"],
        "MB/s",
        description=f"parse {len(texts)} bundled CMU clips from text ({total_mb:.2f} MB)",
        baseline_name="token-by-token pure-Python parse (str.split + float())",
        ours_stats=ours,
        baseline_stats=base,
        details={"megabytes": total_mb, "files": names},
    )
    return [rec]
