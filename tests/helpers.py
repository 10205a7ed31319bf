"""Shared test helpers: angle samplers and tolerance helpers."""

import numpy as np


def random_angles(rng: np.random.Generator, n: int, kind: str = "uniform") -> np.ndarray:
    """[n, 3] Euler angles in radians: "uniform", "near_zero" or "gimbal" (middle angle ~ pi/2)."""
    if kind == "uniform":
        return rng.uniform(-np.pi, np.pi, size=(n, 3))
    if kind == "near_zero":
        return rng.normal(scale=1e-7, size=(n, 3))
    if kind == "gimbal":
        a = rng.uniform(-np.pi, np.pi, size=(n, 3))
        a[:, 1] = np.pi / 2 + rng.normal(scale=1e-6, size=n) * rng.choice([-1, 1], size=n)
        return a
    raise ValueError(kind)


ORDERS_TB = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


def random_topology(rng: np.random.Generator, num_joints: int = 12, num_end_sites: int = 3):
    """A random tree with mixed rotation orders, some 6-channel and some rotation-free joints."""
    from fourierjax.skeleton import Topology

    parents = [-1] + [int(rng.integers(0, i)) for i in range(1, num_joints)]
    channels = []
    for i in range(num_joints):
        order = ORDERS_TB[int(rng.integers(0, 6))]
        rot = tuple(f"{a}rotation" for a in order)
        kind = rng.uniform()
        if i == 0 or kind < 0.2:
            pos = tuple(rng.permutation(["Xposition", "Yposition", "Zposition"]).tolist())
            chans = pos + rot if rng.uniform() < 0.7 else rot + pos
        elif kind < 0.3:
            chans = ()
        elif kind < 0.4:
            chans = rot[:1] if rng.uniform() < 0.5 else rot[:2]
        else:
            chans = rot
        channels.append(chans)
    end_site_parents = tuple(int(p) for p in rng.integers(0, num_joints, size=num_end_sites))
    return Topology(
        names=tuple(f"j{i}" for i in range(num_joints)),
        parents=tuple(parents),
        channels=tuple(channels),
        end_site_parents=end_site_parents,
    )


def reference_fk(topology, offsets, end_site_offsets, channels):
    """Slow, independent FK: scipy rotations and an explicit loop over joints.

    channels: [F, C] BVH values (degrees). Returns (positions [F, J, 3], end sites [F, E, 3]).
    """
    from scipy.spatial.transform import Rotation

    channels = np.asarray(channels, dtype=np.float64)
    num_frames = channels.shape[0]
    num_joints = len(topology.names)
    world_r = [None] * num_joints
    world_p = np.zeros((num_frames, num_joints, 3))
    col = 0
    for j in range(num_joints):
        t = np.tile(np.array(offsets[j], dtype=np.float64), (num_frames, 1))
        r = Rotation.identity(num_frames)
        for name in topology.channels[j]:
            axis = "XYZ".index(name[0])
            if name.endswith("position"):
                t[:, axis] = channels[:, col]  # replaces the offset component
            else:
                r = r * Rotation.from_euler(name[0], channels[:, col : col + 1], degrees=True)
            col += 1
        p = topology.parents[j]
        if p < 0:
            world_r[j] = r
            world_p[:, j] = t
        else:
            world_r[j] = world_r[p] * r
            world_p[:, j] = world_p[:, p] + world_r[p].apply(t)
    ends = np.zeros((num_frames, len(topology.end_site_parents), 3))
    for k, p in enumerate(topology.end_site_parents):
        ends[:, k] = world_p[:, p] + world_r[p].apply(np.array(end_site_offsets[k], dtype=float))
    return world_p, ends


# --- shared by test_contacts and test_gait: an independent numpy BVH reader and FK (oracles) ---
from pathlib import Path  # noqa: E402 (appended section: helpers.py is append-only)

# The bundled copies of the CMU clips (CI and users have no ../shared).
CMU_BUNDLED = Path(__file__).resolve().parents[1] / "fourierjax" / "data" / "cmu_mb"


def read_bvh_oracle(path):
    """An independent numpy BVH reader (oracle): a dict of names, parents, offsets, channels,
    End Sites (`es_par`, `es_off`), `frames` and `frame_time`."""
    toks = Path(path).read_text().split()
    names, parents, offsets, chans, es_par, es_off = [], [], [], [], [], []
    stack, i, cur = [], 0, None
    while toks[i] != "MOTION":
        t = toks[i]
        if t in ("ROOT", "JOINT"):
            names.append(toks[i + 1])
            parents.append(stack[-1] if stack else -1)
            cur, i = len(names) - 1, i + 2
        elif t == "End":
            es_par.append(stack[-1])
            cur, i = "end", i + 2
        elif t == "{":
            stack.append(cur)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif t == "OFFSET":
            (es_off if cur == "end" else offsets).append([float(x) for x in toks[i + 1 : i + 4]])
            i += 4
        elif t == "CHANNELS":
            n = int(toks[i + 1])
            chans.append(tuple(toks[i + 2 : i + 2 + n]))
            i += 2 + n
        else:
            i += 1
    nf, ft = int(toks[i + 2]), float(toks[i + 5])
    frames = np.array(toks[i + 6 :], float).reshape(nf, -1)
    return dict(names=names, parents=parents, offsets=np.array(offsets), channels=chans,
                es_par=es_par, es_off=np.array(es_off), frames=frames, frame_time=ft)


def _axis_rotation(axis, a):
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    m = {"X": [[o, z, z], [z, c, -s], [z, s, c]], "Y": [[c, z, s], [z, o, z], [-s, z, c]],
         "Z": [[c, -s, z], [s, c, z], [z, z, o]]}[axis]
    return np.moveaxis(np.array(m), (0, 1), (-2, -1))


def fk_oracle(b, frames):
    """Independent numpy FK of `read_bvh_oracle` output: (positions [T, J, 3], End Sites [T, E, 3])."""
    T, J = frames.shape[0], len(b["names"])
    pos, R, k = np.zeros((T, J, 3)), np.zeros((T, J, 3, 3)), 0
    for j in range(J):
        off = np.broadcast_to(b["offsets"][j], (T, 3)).copy()
        Rl = np.broadcast_to(np.eye(3), (T, 3, 3))
        for c in b["channels"][j]:
            v = frames[:, k]
            k += 1
            if c.endswith("position"):
                off[:, "XYZ".index(c[0])] = v
            else:
                Rl = Rl @ _axis_rotation(c[0], np.deg2rad(v))
        p = b["parents"][j]
        if p < 0:
            R[:, j], pos[:, j] = Rl, off
        else:
            R[:, j] = R[:, p] @ Rl
            pos[:, j] = pos[:, p] + np.einsum("tij,tj->ti", R[:, p], off)
    es = np.stack(
        [pos[:, p] + np.einsum("tij,j->ti", R[:, p], o) for p, o in zip(b["es_par"], b["es_off"])],
        1,
    )
    return pos, es


class NamesTopology:
    """The two fields of a Topology that `contacts.foot_points` and `gait.groin_joints` read."""

    def __init__(self, names, es_par):
        self.names, self.end_site_parents = tuple(names), tuple(es_par)


# --- command-line subprocesses: the run's shared compile cache (tests/conftest.py) ---
def cli_env(**extra) -> dict:
    """The environment for a `python -m fourierjax ...` subprocess of a test: this run's shared
    compile-cache folder, so that the second and later commands of the run read the programs
    the first compiled (a fresh folder per run; never the user's ~/.cache). ``extra`` adds or
    replaces variables."""
    import os

    env = dict(os.environ)
    folder = env.get("FOURIERJAX_TEST_RUN_CACHE")
    if folder:
        env.pop("FOURIERJAX_NO_CACHE", None)
        env["FOURIERJAX_CACHE_DIR"] = folder
    env.update(extra)
    return env
