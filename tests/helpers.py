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
