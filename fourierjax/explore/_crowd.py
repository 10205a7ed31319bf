"""The explorer's crowd mode: N walkers in place, styles jittered around the current one (`fourierjax.crowd`)."""

from __future__ import annotations

import threading
import time

import numpy as np

#: Most characters the crowd mode takes (the issue's 10,000).
MAX_CHARACTERS = 10_000
#: Metres between two walkers of the crowd's square grid.
SPACING_M = 1.2


def crowd_models(gait_a, b_model, characteristics, p, num: int, jitter: float, seed: int = 0):
    """`num` walkers' models of gait a's BVH channels: eq. 3 at `s + jitter * z_i` (z standard
    normal), the panel's characteristics, each on its spot of a square grid behind the origin.

    Returns:
        A `FourierModel` with a leading character axis (`crowd.make_crowd` takes it).
    """
    import jax
    import jax.numpy as jnp

    from fourierjax import motion, style

    a = gait_a.model
    dtype = jnp.asarray(a.offset).dtype
    rng = np.random.default_rng(seed)
    s = jnp.asarray(p.s + jitter * rng.standard_normal(num), dtype)
    models = jax.vmap(lambda si: style.interpolate(a, b_model, si))(s)
    if characteristics:
        w = jnp.asarray([wi for _, wi in p.weights], dtype)
        models = jax.vmap(lambda m: style.superpose(m, list(characteristics), w))(models)
    side = int(np.ceil(np.sqrt(num)))
    unit = float(gait_a.body_map.metres_per_unit or 1.0)
    k = np.arange(num)
    spots = np.stack([(k % side - (side - 1) / 2) * SPACING_M, -2.0 - (k // side) * SPACING_M], axis=-1) / unit
    return motion.channel_model(gait_a.template, models, jnp.asarray(spots, dtype))


class CrowdPanel:
    """The crowd folder: on/off, character count, style jitter, and the frame rate it runs at.

    Arguments:
        server: the `viser.ViserServer`.
        explorer: the `Explorer` whose current style the crowd jitters.
    """

    def __init__(self, server, explorer):
        self.server, self.explorer = server, explorer
        self.crowd = None
        self.fps = 0.0
        self.frames = 0
        self._stop = threading.Event()
        self._thread = None
        self._points = None
        gui = server.gui
        with gui.add_folder("Crowd", expand_by_default=False):
            self.gui_on = gui.add_checkbox("crowd mode", False)
            self.gui_num = gui.add_number("characters", 100, min=1, max=MAX_CHARACTERS, step=1)
            self.gui_jitter = gui.add_slider("style jitter (s)", 0.0, 1.0, 0.01, 0.2)
            self.gui_fps = gui.add_markdown("")
        self.gui_on.on_update(lambda _: self.toggle(bool(self.gui_on.value)))
        for h in (self.gui_num, self.gui_jitter):
            h.on_update(lambda _: self.rebuild() if self.gui_on.value else None)

    def rebuild(self) -> None:
        """Make the crowd from the current style (a new count compiles once; a new jitter does not)."""
        from fourierjax import crowd
        from fourierjax.errors import UserError

        ex = self.explorer
        try:
            num = int(self.gui_num.value)
            if not 1 <= num <= MAX_CHARACTERS:
                raise UserError(f"crowd: characters must be in [1, {MAX_CHARACTERS}], got {num}")
            with ex._lock:
                p, lib = ex.params, ex.library
                a = lib.gait(p.a)
                chars = [lib.characteristics[n] for n, _ in p.weights]
                models = crowd_models(a, lib.gait(p.b).model, chars, p, num, float(self.gui_jitter.value))
            self.crowd = crowd.make_crowd(a.template.skeleton(), models)
            self._unit = float(a.body_map.metres_per_unit or 1.0)
        except (UserError, ValueError) as err:
            ex.show_message(str(err))

    def frame(self, t_s: float) -> np.ndarray:
        """`[B * J, 3]` joint positions (m) of the crowd at time `t_s`, as sent to the page."""
        import jax.numpy as jnp

        from fourierjax import crowd

        pos = np.asarray(crowd.crowd_positions(self.crowd, jnp.float32(t_s)))
        return (pos.reshape(-1, 3) * self._unit).astype(np.float16)

    def toggle(self, on: bool) -> None:
        if on and self._thread is None:
            self.rebuild()
            self._stop.clear()
            self._thread = threading.Thread(target=self._loop, daemon=True)
            self._thread.start()
        elif not on:
            self.close()
            if self._points is not None:
                self._points.visible = False

    def _loop(self) -> None:
        t0 = last = time.perf_counter()
        count = 0
        while not self._stop.is_set() and self.crowd is not None:
            pts = self.frame(time.perf_counter() - t0)
            if self._points is None:
                self._points = self.server.scene.add_point_cloud("/crowd", pts, (90, 90, 110), point_size=0.04,
                                                                 precision="float16")
            else:
                self._points.points = pts
                self._points.visible = True
            count += 1
            self.frames += 1
            now = time.perf_counter()
            if now - last >= 1.0:
                self.fps = count / (now - last)
                self.gui_fps.content = f"{self.crowd.omega.shape[0]} characters at {self.fps:.1f} frames/s"
                count, last = 0, now

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
