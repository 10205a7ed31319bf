"""Labelled clips of the style-space experiment: file-name labels, one batched fit, an on-disk cache."""

from __future__ import annotations

import hashlib
import json
import pathlib
import re

import numpy as np


def find_clips(folder: pathlib.Path, pattern: str, contents, styles) -> list[dict]:
    """Labelled clips of a folder: ``{"path", "content", "style", "take"}``, sorted by name."""
    rx = re.compile(pattern)
    out = []
    for p in sorted(folder.iterdir()):
        m = rx.search(p.name)
        if m and m["content"] in contents and (not styles or m["style"] in styles):
            out.append({"path": p, "content": m["content"], "style": m["style"], "take": m["take"]})
    return out


def _save(path: pathlib.Path, ok, models) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, ok=np.asarray(ok), names=np.array(models[0].channel_names),
             offset=np.stack([np.asarray(m.offset) for m in models]),
             amplitude=np.stack([np.asarray(m.amplitude) for m in models]),
             phase=np.stack([np.asarray(m.phase) for m in models]),
             omega=np.stack([np.asarray(m.omega) for m in models]),
             **({"frames": np.stack([np.asarray(m.frames) for m in models])} if models[0].frames is not None else {}))


def _load(path: pathlib.Path, representation: str):
    import jax.numpy as jnp

    from fourierjax import fourier

    z = np.load(path)
    names = tuple(str(s) for s in z["names"])
    models = [fourier.FourierModel(jnp.asarray(z["offset"][i]), jnp.asarray(z["amplitude"][i]),
                                   jnp.asarray(z["phase"][i]), jnp.asarray(z["omega"][i]),
                                   representation=representation, channel_names=names,
                                   frames=jnp.asarray(z["frames"][i]) if "frames" in z else None)
              for i in range(len(z["ok"]))]
    return np.asarray(z["ok"], bool), models


def fit_clips(clips, harmonics: int, representation: str, cache: pathlib.Path):
    """Fit every clip through the body-map pipeline, cached on disk.

    ``motion.fit_motions`` with each clip's inferred body map does the steady segment, the
    root channels (the map's pelvis and trajectory joint) and the phase alignment (left heel
    strike); a clip whose steady stretch holds less than a cycle is refitted on the whole clip.

    Returns:
        ``(models, skeletons, body_maps, motions, failed)``: one entry per clip (failed clips
        keep a meaningless model), and the failed clips' file names.
    """
    from fourierjax.body import infer_body_map
    from fourierjax.io.bvh import read_bvh
    from fourierjax.motion import fit_motions

    motions = [read_bvh(c["path"]) for c in clips]
    maps = [infer_body_map(m) for m in motions]
    key = hashlib.sha256(json.dumps(["bodymap-pipeline-1", harmonics, representation,
                                     [c["path"].name for c in clips]]).encode()).hexdigest()[:12]
    path = cache / f"fits_{representation}_{harmonics}_{key}.npz"
    if path.exists():
        ok, models = _load(path, representation)
        print(f"loaded {len(clips)} fits from {path}", flush=True)
    else:
        fits = fit_motions(motions, harmonics, representation, body_map=maps, throw=False)
        ok = np.array([f.successful for f in fits])
        models = [f.model for f in fits]
        bad = [i for i in range(len(clips)) if not ok[i]]
        if bad:  # a steady stretch shorter than a cycle: fit the whole clip instead
            refit = fit_motions([motions[i] for i in bad], harmonics, representation, segment=False,
                                body_map=[maps[i] for i in bad], throw=False)
            for i, f in zip(bad, refit, strict=True):
                if f.successful:
                    ok[i], models[i] = True, f.model
                    print(f"  {clips[i]['path'].name}: fitted on the whole clip", flush=True)
                else:
                    print(f"  not fitted: {f.message}", flush=True)
        _save(path, ok, models)
    failed = [c["path"].name for c, o in zip(clips, ok, strict=True) if not o]
    return models, [m.skeleton() for m in motions], maps, motions, failed
