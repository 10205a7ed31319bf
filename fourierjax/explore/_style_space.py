"""The explorer's style-space view: the PCA plane of the loaded models and a draggable style point."""

from __future__ import annotations

import numpy as np

#: Where the plane stands (m): upright, to the right of the walker's start, facing +Z.
PLANE_ORIGIN = (2.6, 1.0, 0.0)
#: Half-width (m) the farthest model is drawn at.
PLANE_HALF_M = 0.8


class StyleSpacePanel:
    """PCA plane (Tilmanne & Dutoit; `style.style_pca`) of the gaits that share gait a's channels.

    Dragging the point and letting go sets the characteristic weights to the least-squares fit
    (`style.fit_style_weights`) of the style under the point, with s = 0 (gait a as the base).

    Arguments:
        server: the `viser.ViserServer`.
        explorer: the `Explorer` it edits.
    """

    def __init__(self, server, explorer):
        self.server, self.explorer = server, explorer
        self.pca = self.names = self.coords = None
        self.scale = 1.0
        self._gizmo = None
        self.refresh()

    def refresh(self) -> None:
        """Recompute the plane from the library (after a load or a new gait a)."""
        from fourierjax import style
        from fourierjax.errors import UserError

        ex = self.explorer
        p, lib = ex.params, ex.library
        a = lib.gait(p.a).model
        names = []
        for name, g in lib.gaits.items():
            try:
                style.check_compatible(a, g.model)
            except (UserError, ValueError):
                continue
            if g.model.num_harmonics == a.num_harmonics:
                names.append(name)
        scene = self.server.scene
        if len(names) < 3 or not p.weights:
            self.pca = None
            return
        matrix = style.style_matrix([lib.gaits[n].model for n in names])
        self.pca = style.style_pca(matrix, 2)
        coords = np.asarray(style.pca_project(self.pca, matrix))
        self.names, self.coords = names, coords
        self.scale = PLANE_HALF_M / max(float(np.abs(coords).max()), 1e-9)
        scene.add_frame("/style_space", show_axes=False, position=PLANE_ORIGIN)
        scene.add_box("/style_space/plane", color=(235, 235, 245), dimensions=(2.1 * PLANE_HALF_M,
                      2.1 * PLANE_HALF_M, 0.005), position=(0.0, 0.0, -0.01))
        for name, c in zip(names, coords, strict=True):
            xy = (float(c[0] * self.scale), float(c[1] * self.scale), 0.0)
            scene.add_icosphere(f"/style_space/models/{name}", radius=0.03, color=(40, 90, 200), position=xy)
            scene.add_label(f"/style_space/labels/{name}", name, position=(xy[0], xy[1] + 0.06, 0.0))
        start = coords[names.index(p.a)] * self.scale
        self._gizmo = scene.add_transform_controls(
            "/style_space/point", scale=0.25, disable_rotations=True, active_axes=(True, True, False),
            position=(float(start[0]), float(start[1]), 0.02))
        self._gizmo.on_update(self._on_drag)

    def _on_drag(self, event) -> None:
        if event.phase == "end":  # on release
            pos = np.asarray(event.target.position)
            self.apply(pos[:2] / self.scale)

    def apply(self, coords) -> bool:
        """Set the style to the least-squares weights of the style at plane `coords` `[2]` (ridge 1e-3,
        each weight clipped to its slider's [-1, 2]); True if applied."""
        import jax.numpy as jnp

        from fourierjax import style
        from fourierjax.errors import UserError

        ex = self.explorer
        if self.pca is None:
            ex.show_message("style space: needs three gaits on gait a's channels and one characteristic")
            return False
        with ex._lock:
            p, lib = ex.params, ex.library
            a = lib.gait(p.a).model
            chars = [lib.characteristics[n] for n, _ in p.weights]
            vector = style.pca_reconstruct(self.pca, jnp.asarray(coords, jnp.float32))
            try:
                target = style.model_from_style_vector(vector, a)
                w = np.asarray(style.fit_style_weights(a, chars, target, ridge=1e-3))
            except (UserError, ValueError) as err:
                ex.show_message(f"style space: {err}")
                return False
        changes = {f"weight_{n}": float(np.clip(wi, -1.0, 2.0)) for (n, _), wi in zip(p.weights, w, strict=True)}
        ok = ex.set(s=0.0, **changes)
        if ok:
            ex._sync_gui()
        return ok
