"""The explorer's stance panel (Neff & Fiume 2004): shape set, intensity, object and reach gizmos."""

from __future__ import annotations

import threading

import numpy as np

from fourierjax.errors import UserError

#: Where the stance character stands (m), beside the walker's start.
STANCE_ORIGIN = np.array([-1.5, 0.0, 0.0])
#: Seconds without a new value before a solve starts: the solve runs on release, not per drag event.
SETTLE_S = 0.35


class StancePanel:
    """The stance folder of the GUI and its solves (one at a time, in a worker thread).

    Arguments:
        server: the `viser.ViserServer`.
        show_message: callable taking one message for the page and the console.
    """

    def __init__(self, server, show_message, *, height_m: float = 1.75):
        from fourierjax.stance import builtin_shape_sets, make_body

        self.server, self._message = server, show_message
        self.sets = builtin_shape_sets()
        self.body = make_body(height_m)
        self.positions = None  # [J, 3] joints of the last solved pose (m, stance frame)
        self.solution = None
        self.solves = 0
        self._timer = None
        self._lock = threading.Lock()
        self._done = threading.Event()
        gui = server.gui
        names = tuple(self.sets)
        with gui.add_folder("Stance"):
            self.gui_set = gui.add_dropdown("shape set", names, initial_value=names[0])
            self.gui_intensity = gui.add_slider("intensity", -1.0, 2.0, 0.01, 1.0)
            self.gui_reach = gui.add_checkbox("reach (right hand)", False)
            self.gui_result = gui.add_markdown("")
        root = server.scene.add_frame("/stance", show_axes=False, position=STANCE_ORIGIN)
        del root
        self.gizmo_object = server.scene.add_transform_controls(
            "/stance/object", scale=0.25, disable_rotations=True, position=(0.3, 1.3, 0.8))
        server.scene.add_icosphere("/stance/object/ball", radius=0.06, color=(220, 120, 30))
        self.gizmo_target = server.scene.add_transform_controls(
            "/stance/target", scale=0.2, disable_rotations=True, position=(-0.35, 1.1, 0.45))
        server.scene.add_icosphere("/stance/target/ball", radius=0.04, color=(30, 170, 90))
        for handle in (self.gui_set, self.gui_intensity, self.gui_reach):
            handle.on_update(lambda _: self.request())
        for gizmo in (self.gizmo_object, self.gizmo_target):
            gizmo.on_update(self._on_gizmo)
        self._bones = None
        self.request(delay=0.0)

    def _on_gizmo(self, event) -> None:
        if event.phase == "end":  # on release, not on every drag event
            self.request()

    def request(self, delay: float = SETTLE_S) -> None:
        """Solve once the controls have been still for `delay` seconds."""
        with self._lock:
            self._done.clear()
            if self._timer is not None:
                self._timer.cancel()
            self._timer = threading.Timer(delay, self._solve)
            self._timer.daemon = True
            self._timer.start()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the pending solve is done (for tests and the benchmark)."""
        return self._done.wait(timeout)

    def _solve(self) -> None:
        try:
            self._solve_now()
        except (UserError, ValueError) as err:
            self._message(f"stance: {err}")
        finally:
            self._done.set()

    def _solve_now(self) -> None:
        import jax.numpy as jnp

        from fourierjax.stance import StanceResult, balance, center_of_mass, pose_fk, solve_stance

        shape_set = self.sets[self.gui_set.value]
        obj = None if shape_set.object_mode == "none" else jnp.asarray(self.gizmo_object.position, jnp.float32)
        kw = {"target_right": jnp.asarray(self.gizmo_target.position, jnp.float32)} if self.gui_reach.value else {}
        problem = shape_set.problem(self.body, jnp.asarray(float(self.gui_intensity.value), jnp.float32), obj, **kw)
        sol = solve_stance(problem)
        fk = pose_fk(self.body, sol.pose)
        pos = np.asarray(fk.positions)
        if not np.isfinite(pos).all():
            raise UserError("the solver produced an invalid pose (NaN); try a smaller intensity")
        com = np.asarray(center_of_mass(self.body, fk))
        feet = np.asarray(balance.monitor_points_world(self.body, problem.feet)).reshape(-1, 3)
        hull = balance.support_polygon(feet[:, [0, 2]])
        self.solution, self.positions = sol, pos
        parents = np.asarray(self.body.skeleton.topology.parents)
        n = len(parents)
        child = np.flatnonzero(parents >= 0)
        segs = np.stack([pos[:n][parents[child]], pos[:n][child]], axis=1)
        scene = self.server.scene
        if self._bones is None:
            self._bones = scene.add_line_segments("/stance/bones", segs, (180, 60, 140), thickness=0.03)
        else:
            self._bones.points = segs
        ring = np.stack([hull, np.roll(hull, -1, axis=0)], axis=1)
        ring3 = np.zeros((len(ring), 2, 3))
        ring3[..., 0], ring3[..., 2], ring3[..., 1] = ring[..., 0], ring[..., 1], 0.002
        scene.add_line_segments("/stance/support", ring3, (60, 60, 60), thickness=0.01)
        scene.add_icosphere("/stance/balance", radius=0.025, color=(200, 30, 30), position=(com[0], 0.005, com[2]))
        converged = bool(sol.converged)
        text = (f"{shape_set.name} at {float(self.gui_intensity.value):g}: objective {float(sol.objective):.4g}, "
                f"{int(sol.iterations)} iterations")
        if converged:
            self.gui_result.content = text
        else:
            why = StanceResult[sol.result]  # the outcome's sentence, e.g. "... ran out of steps ..."
            self.gui_result.content = f"**Did not converge** ({why}): {text}"
            self._message(f"stance: {shape_set.name} at intensity {float(self.gui_intensity.value):g} did not "
                          f"converge: {why}")
        self.solves += 1  # counted once drawn and reported

    def close(self) -> None:
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
