"""MuJoCo MJX as an FK baseline: the same BVH skeleton as an MJCF model, `mjx.kinematics` positions.

Needs the `bench` extra (`pip install -e '.[bench]'`, kept out of the shared venv); without it
`available()` says why in one line and the FK benchmark skips MJX.
"""

from __future__ import annotations

import numpy as np


def available() -> str | None:
    """None when MJX can be imported, else the one-line reason."""
    try:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import mujoco  # noqa: F401
            from mujoco import mjx  # noqa: F401
    except Exception as err:  # ImportError, or a broken optional install
        return f"MJX not importable ({type(err).__name__}: {err}); install the bench extra"
    return None


def mjcf(topology, offsets) -> str:
    """An MJCF model of a BVH skeleton: one body per joint at its OFFSET, one joint per channel
    in file order (slide for positions, hinge for rotations, about the channel's axis). MuJoCo
    applies a body's joints in order, which is BVH's translate-then-rotate in channel order.
    A position channel replaces its OFFSET component, so that component of the body's `pos` is 0.
    """
    children: dict[int, list[int]] = {}
    for j, p in enumerate(topology.parents):
        children.setdefault(p, []).append(j)
    axis = {"X": "1 0 0", "Y": "0 1 0", "Z": "0 0 1"}

    def body(j: int, indent: str) -> str:
        pos = np.asarray(offsets[j], np.float64).copy()
        for c in topology.channels[j]:
            if c.endswith("position"):
                pos["XYZ".index(c[0])] = 0.0
        lines = [f'{indent}<body name="b{j}" pos="{pos[0]:.9g} {pos[1]:.9g} {pos[2]:.9g}">',
                 f'{indent}  <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>']
        for k, c in enumerate(topology.channels[j]):
            kind = "slide" if c.endswith("position") else "hinge"
            lines.append(f'{indent}  <joint name="j{j}_{k}" type="{kind}" axis="{axis[c[0]]}" limited="false"/>')
        lines.extend(body(ch, indent + "  ") for ch in children.get(j, []))
        lines.append(f"{indent}</body>")
        return "\n".join(lines)

    roots = "\n".join(body(r, "    ") for r in children.get(-1, []))
    return f'<mujoco>\n  <option gravity="0 0 0"/>\n  <worldbody>\n{roots}\n  </worldbody>\n</mujoco>\n'


def mjx_positions_fn(topology, offsets):
    """`(fn, qpos_of)`: `fn(qpos [M, nq]) -> [M, J, 3]` jitted MJX positions (only `xpos` kept),
    and `qpos_of(channels [M, C]) -> qpos` (degrees to radians; channel order is qpos order)."""
    import warnings

    import jax
    import jax.numpy as jnp

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import mujoco
        from mujoco import mjx

    model = mujoco.MjModel.from_xml_string(mjcf(topology, offsets))
    mx = mjx.put_model(model, impl="jax")  # MJX's pure-JAX implementation (not warp, not C)
    data = mjx.make_data(mx, impl="jax")
    is_rot = np.asarray([c.endswith("rotation") for c in topology.flat_channel_names])
    body_of = np.asarray([model.body(f"b{j}").id for j in range(topology.num_joints)])

    # Model and data are arguments, not closure constants: as constants XLA folds through them
    # and a call grows faster than linearly in the batch (measured: 9 s for 960 frames
    # instead of 0.3 s).
    @jax.jit
    def run(mx, data, qpos):
        return jax.vmap(lambda q: mjx.kinematics(mx, data.replace(qpos=q)).xpos[body_of])(qpos)

    def fn(qpos):
        return run(mx, data, qpos)

    def qpos_of(channels):
        ch = jnp.asarray(channels, jnp.float32)
        return jnp.where(jnp.asarray(is_rot), jnp.deg2rad(ch), ch)

    return fn, qpos_of
