"""The explorer's server: a viser scene with a live character, the gait panel, playback, export."""

from __future__ import annotations

import dataclasses
import pathlib
import sys
import threading
import time

import numpy as np

from fourierjax.errors import UserError
from fourierjax.explore import _engine
from fourierjax.explore._params import HIP_RULES, Params, config_text

#: Playback ticks per second (a new pose is sent at most this often).
PLAYBACK_HZ = 120.0
_BONE_COLOUR = (40, 90, 200)
#: The path dropdown: label -> `Params.path_radius_m` (m; > 0 turns left, 0 straight on).
PATHS = {"straight": 0.0, "circle r = 2 m, left": 2.0, "circle r = 4 m, left": 4.0, "circle r = 2 m, right": -2.0}


class Explorer:
    """A running explorer: the viser server, its GUI and the state behind it (shared by all tabs).

    Arguments:
        library: the gaits and characteristics to pick from (`load_sources`, `default_library`).
        host, port: where the server listens (default localhost only).
        out_dir: folder of exported files.
        seconds, fps: length and frame rate of the synthesized preview (and of the export).
        messages: messages to show at start (e.g. sources that could not be read).
        stance: whether to add the stance panel (it compiles the stance solver on first use).
    """

    def __init__(self, library, *, host: str = "127.0.0.1", port: int = 8080, out_dir=".", seconds: float = 4.0,
                 fps: float = 60.0, messages=(), stance: bool = True, verbose: bool = False):
        import viser

        self.library = library
        self.out_dir = pathlib.Path(out_dir)
        self.messages: list[str] = []
        self._lock = threading.RLock()
        self._wake = threading.Condition()
        self._pending: dict = {}
        self._stop = False
        self._exports = 0
        names = list(library.gaits)
        a, b = (_engine.DEFAULT_PAIR if all(n in library.gaits for n in _engine.DEFAULT_PAIR)
                else (names[0], names[min(1, len(names) - 1)]))
        self.params = Params(a, b, weights=self._weights_for(a, {}), seconds=seconds, fps=fps)
        self.server = viser.ViserServer(host=host, port=port, verbose=verbose)
        self.server.scene.set_up_direction("+y")
        self.server.scene.add_grid("/floor", width=20.0, height=20.0, plane="xz", cell_size=0.5)
        self.playing = True
        self.playback_rate = 1.0
        self.time_s = 0.0
        self.frame = 0
        self.pose_sent_at = 0.0  # time.perf_counter() of the last pose sent
        self.mode = "gait"  # or "transition": what the preview plays
        self._build_gui()
        self.server.on_client_connect(self._on_connect)
        self._recompute(self.params)
        self._bones = self.server.scene.add_line_segments(
            "/gait/bones", self._segments(self.frame), _BONE_COLOUR, thickness=0.035)
        self.stance = None
        if stance:
            from fourierjax.explore._stance import StancePanel

            self.stance = StancePanel(self.server, self.show_message)
        from fourierjax.explore._crowd import CrowdPanel

        self.crowd = CrowdPanel(self.server, self)
        from fourierjax.explore._style_space import StyleSpacePanel

        self.style_space = StyleSpacePanel(self.server, self)
        for m in messages:
            self.show_message(m)
        self._threads = [threading.Thread(target=self._playback_loop, daemon=True),
                         threading.Thread(target=self._update_loop, daemon=True)]
        for t in self._threads:
            t.start()

    # ------------------------------------------------------------------ state and computation

    @property
    def url(self) -> str:
        """The page's address."""
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def _weights_for(self, a: str, old: dict) -> tuple[tuple[str, float], ...]:
        from fourierjax import style

        out = []
        for name, char in self.library.characteristics.items():
            try:
                style.check_compatible(self.library.gait(a).model, char)
            except (UserError, ValueError):
                continue
            out.append((name, float(old.get(name, 0.0))))
        return tuple(out)

    def set(self, **changes) -> bool:
        """Apply parameter changes now (what a slider does), then send the new pose.

        Arguments:
            **changes: `Params` fields, or `weight_NAME=w` for a characteristic.

        Returns:
            True if applied; False if refused (the message is in the page and on stderr).
        """
        with self._lock:
            try:
                weights = dict(self.params.weights)
                for key in [k for k in changes if k.startswith("weight_")]:
                    name = key[len("weight_"):]
                    if name not in weights:
                        raise UserError(f"no characteristic {name!r} for gait {self.params.a}")
                    weights[name] = float(changes.pop(key))
                if "a" in changes:
                    weights = dict(self._weights_for(changes["a"], weights))
                p = dataclasses.replace(self.params, weights=tuple(weights.items()), **changes)
                self._recompute(p)
                self.mode = "gait"
            except (UserError, ValueError) as err:
                self.show_message(str(err))
                self._sync_gui()
                return False
            self._send_frame(self.frame)
        if self.crowd.gui_on.value:
            self.crowd.rebuild()
        if "a" in changes:
            self.style_space.refresh()
        return True

    def transition(self, duration_s: float | None = None) -> bool:
        """Play gait a → gait b over `duration_s` seconds (from a quarter of the preview on).

        Returns:
            True if it plays; False if refused (one message).
        """
        d = float(self.gui_duration.value if duration_s is None else duration_s)
        with self._lock:
            p = self.params
            start = 0.25 * p.seconds
            try:
                if not 0.0 < d <= p.seconds - start:
                    raise UserError(f"transition: duration must be in (0, {p.seconds - start:g}] s, got {d:g}")
                self._recompute(p, _engine.transition_motion(self.library, p, start, d))
            except (UserError, ValueError) as err:
                self.show_message(str(err))
                return False
            self.mode = "transition"
            self.time_s, self.playing = 0.0, True
            self._send_frame(0)
        self._status.content = (f"Transition {p.a} → {p.b} over {d:g} s from t = {start:g} s"
                                + (" (on a straight line)." if p.path_radius_m else "."))
        return True

    def _recompute(self, p: Params, motion=None) -> None:
        import jax.numpy as jnp

        from fourierjax import kinematics

        gait_a = self.library.gait(p.a)
        result = None
        if motion is None:
            # The view straight from the features (one jitted FK); the BVH channels wait for an export.
            _engine.check_pair(self.library, p)
            b, lib = self.library.gait(p.b), self.library
            model = _engine.edited_model(gait_a.model, b.model, [lib.characteristics[n] for n, _ in p.weights], p)
            result = _engine.synthesize_result(gait_a, model, p,
                                               ground=_engine.edited_ground(gait_a.model, b.model, p))
            pos = _engine.view_positions(gait_a, model.representation, result)
            self._channel_names = model.channel_names
        else:
            pos = np.asarray(kinematics.joint_positions(gait_a.template.skeleton(), jnp.asarray(motion.channels)))
        scale = float(gait_a.body_map.metres_per_unit or 1.0)
        pos = pos * scale
        up = gait_a.body_map.up_axis
        start = pos[0, gait_a.body_map.pelvis].copy()
        start[up] = 0.0
        self.params, self._motion, self.result = p, motion, result
        self.positions = pos - start  # [T, J, 3] metres, starting over the origin
        self._parents = np.asarray(gait_a.template.topology.parents)
        self.frame %= p.num_frames
        self.clear_message()

    @property
    def motion(self):
        """The `io.bvh.Motion` on screen (built on first use after each change)."""
        with self._lock:
            if self._motion is None:
                self._motion = _engine.result_motion(self.library.gait(self.params.a), self._channel_names,
                                                     self.result, self.params)
            return self._motion

    def current_positions(self) -> np.ndarray:
        """`[J, 3]` joint positions (m) of the frame on screen."""
        with self._lock:
            return self.positions[self.frame].copy()

    def _segments(self, frame: int) -> np.ndarray:
        pos = self.positions[frame]
        child = np.flatnonzero(self._parents >= 0)
        return np.stack([pos[self._parents[child]], pos[child]], axis=1)

    def _send_frame(self, frame: int) -> None:
        with self._lock:
            self.frame = frame
            segs = self._segments(frame)
            if hasattr(self, "_bones"):
                self._bones.points = segs
            self.pose_sent_at = time.perf_counter()

    # ------------------------------------------------------------------ messages

    def show_message(self, text: str) -> None:
        """One message in the page (the status line) and on the console; the server keeps running."""
        self.messages.append(text)
        print(f"fourierjax explore: {text}", file=sys.stderr, flush=True)
        if hasattr(self, "_status"):
            self._status.content = f"**Message:** {text}"

    def clear_message(self) -> None:
        if hasattr(self, "_status"):
            self._status.content = "Ready."

    # ------------------------------------------------------------------ GUI

    def _build_gui(self) -> None:
        gui, p = self.server.gui, self.params
        self._status = gui.add_markdown("Loading…")
        names = tuple(self.library.gaits)
        self._ignore = False  # set while the server itself moves a control
        with gui.add_folder("Gait"):
            self.gui_a = gui.add_dropdown("Model A", names, initial_value=p.a)
            self.gui_b = gui.add_dropdown("Model B", names, initial_value=p.b)
            self.gui_s = gui.add_slider("s (A→B)", -1.0, 2.0, 0.01, p.s,
                                        hint="Unuma eq. 3; outside [0, 1] extrapolates")
            self.gui_weights = {}
            for name, w in p.weights:
                self.gui_weights[name] = gui.add_slider(name, -1.0, 2.0, 0.01, w, hint=f"characteristic {name} (eq. 8)")
            self.gui_step = gui.add_slider("step", 0.0, 2.0, 0.01, p.step)
            self.gui_speed = gui.add_slider("speed", 0.0, 3.0, 0.01, p.speed)
            self.gui_gait = gui.add_slider("gait", 0.0, 1.0, 0.005, p.gait, hint="flight where N(t) > gait")
            self.gui_jump = gui.add_slider("jump", 0.0, 2.0, 0.01, p.jump)
            self.gui_rule = gui.add_dropdown("hip rule", HIP_RULES, initial_value=p.hip_rule)
            self.gui_root = gui.add_checkbox("root motion", p.root_motion)
            self.gui_noise = gui.add_slider("noise (deg)", 0.0, 10.0, 0.1, p.noise_deg)
            self.gui_lock = gui.add_checkbox("foot locking", p.foot_lock,
                                             hint="plant the feet: synthesize_gait(foot_lock=True)")
        with gui.add_folder("Playback"):
            play = gui.add_button("Play")
            pause = gui.add_button("Pause")
            play.on_click(lambda _: setattr(self, "playing", True))
            pause.on_click(lambda _: setattr(self, "playing", False))
            self.gui_time = gui.add_slider("time (s)", 0.0, p.seconds, 1.0 / p.fps, 0.0)
            self.gui_rate = gui.add_slider("playback speed", 0.1, 2.0, 0.05, 1.0)
            self.gui_time.on_update(self._on_scrub)
            self.gui_rate.on_update(lambda e: setattr(self, "playback_rate", float(e.target.value)))
        with gui.add_folder("Transition and path"):
            self.gui_duration = gui.add_slider("transition D (s)", 0.1, 5.0, 0.1, 1.0)
            go = gui.add_button("Transition A→B")
            go.on_click(lambda _: self.transition())
            self.gui_path = gui.add_dropdown("path", tuple(PATHS), initial_value=_path_label(p.path_radius_m),
                                             hint="synthesize_gait(path=): the walk follows it, feet planted; "
                                             "the export and its config too")
        controls = {"a": self.gui_a, "b": self.gui_b, "s": self.gui_s, "step": self.gui_step,
                    "speed": self.gui_speed, "gait": self.gui_gait, "jump": self.gui_jump,
                    "hip_rule": self.gui_rule, "root_motion": self.gui_root, "noise_deg": self.gui_noise,
                    "foot_lock": self.gui_lock, "path_radius_m": self.gui_path}
        controls.update({f"weight_{n}": h for n, h in self.gui_weights.items()})
        self._controls = controls
        for key, handle in controls.items():
            handle.on_update(self._on_control(key))
        with gui.add_folder("Load and export"):
            self.gui_file = gui.add_text("BVH or model file", "")
            load = gui.add_button("Load")
            load.on_click(lambda _: self.load(self.gui_file.value))
            export = gui.add_button("Export BVH + config")
            export.on_click(lambda _: self.export())
            gif = gui.add_button("Export GIF of this view")
            gif.on_click(lambda e: self.export_gif(e.client))

    @staticmethod
    def _on_connect(client) -> None:
        # Both characters in view: the walker starts at the origin, the stance stands at x = -1.5 m.
        client.camera.position = (2.2, 1.9, 4.6)
        client.camera.look_at = (-0.6, 0.8, 0.6)

    def _on_control(self, key):
        def callback(event):
            if event.client is None:  # the server moved it (a refused value put back)
                return
            value = event.target.value
            if key == "path_radius_m":
                value = PATHS[value]
            value = float(value) if isinstance(value, int | float) and not isinstance(value, bool) else value
            with self._wake:
                self._pending[key] = value
                self._wake.notify()
        return callback

    def _on_scrub(self, event) -> None:
        if event.client is None:
            return
        with self._lock:
            self.playing = False
            self.time_s = float(event.target.value)
            self._send_frame(int(self.time_s * self.params.fps) % self.params.num_frames)

    def _sync_gui(self) -> None:
        """Put the controls back to the parameters in force (after a refused change)."""
        p = self.params
        values = {"a": p.a, "b": p.b, "s": p.s, "step": p.step, "speed": p.speed, "gait": p.gait,
                  "jump": p.jump, "hip_rule": p.hip_rule, "root_motion": p.root_motion,
                  "noise_deg": p.noise_deg, "foot_lock": p.foot_lock, "path_radius_m": _path_label(p.path_radius_m)}
        values.update({f"weight_{n}": w for n, w in p.weights})
        for key, handle in self._controls.items():
            if key in values and handle.value != values[key]:
                handle.value = values[key]

    def _update_loop(self) -> None:
        # One worker applies the latest values: a fast drag coalesces into few recomputes.
        while True:
            with self._wake:
                while not self._pending and not self._stop:
                    self._wake.wait()
                if self._stop:
                    return
                changes, self._pending = self._pending, {}
            self.set(**changes)

    def _playback_loop(self) -> None:
        last = time.perf_counter()
        tick = 0
        while not self._stop:
            time.sleep(1.0 / PLAYBACK_HZ)
            now = time.perf_counter()
            if self.playing:
                with self._lock:
                    if not self.playing:  # paused (a scrub) while this tick waited for the lock
                        last = now
                        continue
                    self.time_s = (self.time_s + (now - last) * self.playback_rate) % self.params.seconds
                    frame = int(self.time_s * self.params.fps) % self.params.num_frames
                    if frame != self.frame:
                        self._send_frame(frame)
                tick += 1
                if tick % 12 == 0:  # the scrubber follows at 10 Hz
                    self.gui_time.value = round(self.time_s, 3)
            last = now

    # ------------------------------------------------------------------ load and export

    def load(self, text: str) -> bool:
        """Add a BVH clip (fitted), a model file or a characteristic file to the pickers.

        Returns:
            True if it loaded; False (one message in the page and on stderr) otherwise.
        """
        text = (text or "").strip()
        if not text:
            self.show_message("type the path of a BVH clip or a model file first")
            return False
        try:
            lib, messages = _engine.load_sources([text], fallback=False)
        except UserError as err:
            messages, lib = [str(err)], None
        if messages or lib is None:
            self.show_message("; ".join(messages))
            return False
        with self._lock:
            self.library.gaits.update(lib.gaits)
            self.library.characteristics.update(lib.characteristics)
            names = tuple(self.library.gaits)
            self.gui_a.options = names
            self.gui_b.options = names
        self.style_space.refresh()
        loaded = ", ".join([*lib.gaits, *lib.characteristics])
        self._status.content = f"Loaded {loaded}."
        return True

    def export(self, out_dir=None) -> tuple[pathlib.Path, pathlib.Path] | None:
        """Write the motion on screen (BVH), its parameter set (TOML) and the model files it
        names; `fourierjax synth --config CONFIG --out X.bvh` writes the same frames.

        Returns:
            `(bvh path, config path)` (config None for a transition), or None when writing failed
            (message in the page).
        """
        from fourierjax.io import model_io
        from fourierjax.io.bvh import write_bvh

        out = pathlib.Path(out_dir) if out_dir is not None else self.out_dir
        if self.mode != "gait":  # a transition: its BVH, but no parameter set reproduces it
            with self._lock:
                self._exports += 1
                bvh = out / f"explore_{self._exports:03d}.bvh"
                try:
                    out.mkdir(parents=True, exist_ok=True)
                    write_bvh(self.motion, bvh)
                except OSError as err:
                    self.show_message(f"export failed: {err}")
                    return None
            self.show_message(f"exported {bvh}; a transition has no parameter set (no config written): move a "
                              "slider to go back to the gait panel")
            return bvh, None
        with self._lock:
            self._exports += 1
            stem = f"explore_{self._exports:03d}"
            p, motion = self.params, self.motion
            try:
                out.mkdir(parents=True, exist_ok=True)
                files = {}
                for key in dict.fromkeys((p.a, p.b)):
                    g = self.library.gait(key)
                    files[key] = f"{stem}.{_safe(key)}.npz"
                    model_io.save_model(out / files[key], g.model, motion=g.template,
                                        provenance={"source": g.source}, body_map=g.body_map)
                for name, _ in p.weights:
                    files[name] = f"{stem}.char_{_safe(name)}.npz"
                    model_io.save_characteristic(out / files[name], self.library.characteristics[name])
                config = out / f"{stem}.toml"
                config.write_text(config_text(p, files), encoding="utf-8")
                bvh = out / f"{stem}.bvh"
                write_bvh(motion, bvh)
            except (OSError, UserError) as err:
                self.show_message(f"export failed: {err}")
                return None
        self._status.content = f"Exported `{bvh}` and `{config}`"
        print(f"fourierjax explore: wrote {bvh} and {config}", file=sys.stderr, flush=True)
        return bvh, config

    def export_gif(self, client, out_dir=None, *, fps: float = 15.0, size: tuple[int, int] = (360, 480)):
        """Record one pass of the preview as the browser tab `client` shows it (its camera), as a GIF.

        Arguments:
            client: the `viser.ClientHandle` of the tab (the one whose button was clicked).
            out_dir: folder (default the explorer's `out_dir`).
            fps: frames per second of the GIF.
            size: `(height, width)` in pixels, at most the tab's.

        Returns:
            The GIF's path, or None (one message) when the tab could not render.
        """
        from PIL import Image

        out = pathlib.Path(out_dir) if out_dir is not None else self.out_dir
        was_playing, self.playing = self.playing, False
        images = []
        try:
            p = self.params
            for frame in range(0, p.num_frames, max(1, int(round(p.fps / fps)))):
                self._send_frame(frame)
                images.append(Image.fromarray(client.get_render(*size, timeout=30.0)))
            out.mkdir(parents=True, exist_ok=True)
            self._exports += 1
            path = out / f"explore_{self._exports:03d}.gif"
            images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
        except (OSError, TimeoutError, RuntimeError) as err:
            self.show_message(f"GIF export failed: {err}")
            return None
        finally:
            self.playing = was_playing
        self._status.content = f"Exported `{path}` ({len(images)} frames)"
        print(f"fourierjax explore: wrote {path}", file=sys.stderr, flush=True)
        return path

    def close(self) -> None:
        """Stop the threads and the server."""
        with self._wake:
            self._stop = True
            self._wake.notify_all()
        for t in self._threads:
            t.join(timeout=2.0)
        if self.stance is not None:
            self.stance.close()
        self.crowd.close()
        self.server.stop()


def _path_label(radius_m: float) -> str:
    """The path dropdown's entry for a radius (the nearest one offered, for a radius set from Python)."""
    return min(PATHS, key=lambda k: abs(PATHS[k] - radius_m))


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
