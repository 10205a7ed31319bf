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
