"""The web viewer: a recorded play rollout (:class:`legoh.play.Rollout`) served with viser.

The page shows the trail tiles the robots hike (ground, hurdles and steps, trunks), the
robots, each tile's expert waypoints (passed grey, the current goal yellow) and a flag on
its terminus; in the side panel a caption (robot, trail, level, time, metres walked, the
outcome), the followed robot's depth view, playback (play / pause, step, a slider to scrub,
speed), the follow camera's robot, and a trail and level selector that records a new
rollout.

Every pose was computed before the page opens: playing only moves each robot body's
instances (one batched mesh per body, one instance per robot) to the poses of a step, so
the page stays smooth whatever the physics cost.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import viser
from omegaconf import DictConfig

from legoh.play import Rollout
from legoh.video import NEXT_WAYPOINT, PASSED, ROBOT, WAYPOINT, caption_line, depth_panel
from legoh.viewer.nodes import ROOTS, Replay, add_nodes, prepare, rgb255

FPS = 25.0  # page updates per second while playing (the video's rate)
SPEEDS = ("0.25", "0.5", "1", "2", "4")  # playback speeds offered, x real time
FREE = "free camera"  # the follow selector's entry that stops following
DEPTH_PANEL = (240, 320)  # px, height and width of the depth inset
FOLLOWED = (0.20, 0.45, 0.85)  # rgb 0-1: the followed robot stands out from the others


class WebViewer:
    """A viser server replaying play rollouts; :meth:`load` records and shows a new one.

    Args:
        cfg: the run config (robot, trail, eval, env) of the first rollout.
        run: records a rollout: ``run(cfg, level) -> Rollout`` (the policy is bound in it).
        compose: the config of another trail: ``compose(trail name) -> DictConfig``.
        trails: trail names the selector offers. host, port: where to serve (port 0: any
            free port; a taken port: viser tries the next ones).
        level: the first rollout's level (default: the hardest of ``eval.levels``).
    """

    def __init__(self, cfg: DictConfig, run: Callable[[DictConfig, int], Rollout],
                 compose: Callable[[str], DictConfig], trails: list[str],
                 host: str = "127.0.0.1", port: int = 8080, level: int | None = None,
                 depth_label: str = "robot's depth view") -> None:
        self.run, self.compose, self.depth_label = run, compose, depth_label
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.scene.set_up_direction("+z")
        self.server.gui.configure_theme(control_width="large")
        self._lock = threading.RLock()  # a rollout's swap vs. the playback thread
        self.replay: Replay | None = None
        self.handles: dict[str, viser.SceneNodeHandle] = {}
        self._time = 0.0  # steps since the start, fractional while playing
        self._depth_shown: tuple | None = None
        self._build_gui(cfg, trails)
        try:
            self.load(cfg, int(max(cfg.eval.levels)) if level is None else level)
        except BaseException:  # no rollout to serve: do not leave the server running
            self.server.stop()
            raise
        self._stop = threading.Event()
        self._player = threading.Thread(target=self._play_loop, name="legoh-viewer",
                                        daemon=True)
        self._player.start()

    @property
    def url(self) -> str:
        """Where the page is served."""
        host = self.server.get_host()
        return f"http://{'localhost' if host in ('0.0.0.0', '::') else host}:" \
               f"{self.server.get_port()}"

    # ---- the GUI ---------------------------------------------------------------------
    def _build_gui(self, cfg: DictConfig, trails: list[str]) -> None:
        gui = self.server.gui
        self.caption = gui.add_markdown("recording the rollout ...")
        self.depth = gui.add_image(np.zeros((*DEPTH_PANEL, 3), np.uint8), label="depth",
                                   format="png")
        with gui.add_folder("Playback"):
            self.play_button = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
            self.step_buttons = gui.add_button_group("One step", ("<", ">"))
            self.slider = gui.add_slider("Step", min=0, max=1, step=1, initial_value=0)
            self.speed = gui.add_dropdown("Speed (x real time)", SPEEDS, initial_value="1")
            self.follow = gui.add_dropdown("Follow", (FREE,), initial_value=FREE)
        with gui.add_folder("Rollout"):
            self.trail = gui.add_dropdown("Trail", trails, initial_value=cfg.trail.name)
            self.level = gui.add_dropdown("Level", ("0",), initial_value="0")
            self.rerun = gui.add_button("Run again", icon=viser.Icon.REFRESH)
            self.status = gui.add_markdown("")
        self.playing = False
        self.play_button.on_click(lambda _: self.set_playing(not self.playing))
        self.step_buttons.on_click(lambda e: self._step(-1 if e.target.value == "<" else 1))
        self.slider.on_update(lambda _: self._scrub(int(self.slider.value)))
        self.follow.on_update(lambda _: self.show(int(self.slider.value), jump=True))
        self.trail.on_update(lambda _: self._offer_levels(self._levels_of(self.trail.value)))
        self.rerun.on_click(lambda _: self._rerun())
        self.server.on_client_connect(self._on_connect)

    def _levels_of(self, trail: str) -> int:
        """How many levels ``trail`` has (the running config's when it is that trail)."""
        cfg = self.replay.cfg if self.replay is not None else None
        if cfg is not None and cfg.trail.name == trail:
            return int(cfg.trail.levels)
        return int(self.compose(trail).trail.levels)

    def _offer_levels(self, levels: int, level: int | None = None) -> None:
        options = tuple(str(k) for k in range(levels))
        current = self.level.value if level is None else str(level)
        self.level.options = options
        self.level.value = current if current in options else options[-1]

    def set_playing(self, playing: bool) -> None:
        """Play (from the start when at the end) or pause."""
        with self._lock:
            if playing and self.replay is not None \
                    and int(self._time) >= self.replay.rollout.steps:
                self._time = 0.0
            self.playing = playing
            self.play_button.label = "Pause" if playing else "Play"
            self.play_button.icon = viser.Icon.PLAYER_PAUSE if playing \
                else viser.Icon.PLAYER_PLAY

    def _step(self, delta: int) -> None:
        self.set_playing(False)
        self.slider.value = int(np.clip(self.slider.value + delta, 0, self.slider.max))

    def _scrub(self, step: int) -> None:
        """The slider moved (by hand or by the player): show that step."""
        with self._lock:
            if int(self._time) != step:
                self._time = float(step)
            self.show(step)

    def _play_loop(self) -> None:
        """Advance the slider in real time (x speed) while playing; stop at the end."""
        last = time.monotonic()
        while not self._stop.wait(1.0 / FPS):
            now, elapsed = time.monotonic(), time.monotonic() - last
            last = now
            with self._lock:
                if not self.playing or self.replay is None:
                    continue
                steps = self.replay.rollout.steps
                self._time = min(self._time + elapsed * float(self.speed.value)
                                 / self.replay.rollout.dt, float(steps))
                if int(self._time) >= steps:
                    self.set_playing(False)
                self.slider.value = int(self._time)

    # ---- the scene -------------------------------------------------------------------
    def load(self, cfg: DictConfig, level: int) -> None:
        """Record a rollout of ``cfg`` on ``level`` and show it from its first step."""
        self.status.content = f"recording {cfg.trail.name} level {level} ..."
        started = time.monotonic()
        replay = prepare(cfg, self.run(cfg, level))
        with self._lock:
            self.set_playing(False)
            for root in ROOTS:
                self.server.scene.remove_by_name(root)
            self.replay = replay
            self.handles = add_nodes(self.server.scene, replay)
            self._time, self._depth_shown = 0.0, None
            n = len(replay.rollout.end)
            self.follow.options = (*(f"robot {i}" for i in range(n)), FREE)
            self.follow.value = "robot 0"
            self._offer_levels(int(cfg.trail.levels), replay.rollout.level)
            self.trail.value = cfg.trail.name
            self.slider.max = replay.rollout.steps
            self.slider.value = 0
            self.show(0, jump=True)
        outcomes = ", ".join(f"{i}: {o}" for i, o in enumerate(replay.rollout.outcome))
        self.status.content = (f"{cfg.robot.name.upper()} on {cfg.trail.name} level "
                               f"{replay.rollout.level}, {n} robots ({outcomes}); recorded "
                               f"in {time.monotonic() - started:.0f} s")

    def _rerun(self) -> None:
        """The selector's trail and level: a new rollout (an error is shown, not raised)."""
        try:
            self.rerun.disabled = True
            self.load(self.compose(self.trail.value), int(self.level.value))
        except Exception as err:  # noqa: BLE001 - the page says what failed; the server lives
            self.status.content = f"**failed**: {err}"
        finally:
            self.rerun.disabled = False

    def followed(self) -> int | None:
        """The robot the camera follows (None: a free camera)."""
        value = self.follow.value
        return None if value == FREE else int(value.split()[-1])

    def show(self, frame: int, jump: bool = False) -> None:
        """Pose every robot as at ``frame`` (each frozen at its episode's end) and update
        the caption, depth inset, waypoint colours and, when following, each camera.
        ``jump``: put the cameras at the default view of the followed robot."""
        with self._lock:
            replay = self.replay
            if replay is None:
                return
            frame = int(np.clip(frame, 0, replay.rollout.steps))
            step = replay.step_of(frame)
            robots = np.arange(len(step))
            who = self.followed()
            me = 0 if who is None else who
            colors = np.tile(rgb255(ROBOT), (len(robots), 1)).astype(np.uint8)
            if who is not None:
                colors[who] = rgb255(FOLLOWED)
            with self.server.atomic():
                for b, body in enumerate(replay.names):
                    handle = self.handles[f"/robots/{body}"]
                    handle.batched_positions = replay.pos[step, robots, b]
                    handle.batched_wxyzs = replay.quat[step, robots, b]
                    handle.batched_colors = colors
                self._color_waypoints(replay, step, me)
            self._caption(replay, frame, step, me)
            self._follow(replay, step, who, jump)

    def _color_waypoints(self, replay: Replay, step: np.ndarray, me: int) -> None:
        """Each tile's waypoints by the goal of a robot on it (the followed one first)."""
        for k in range(len(replay.tiles)):
            on = np.flatnonzero(replay.tile_of == k)
            robot = me if me in on else int(on[0])
            goal = int(replay.rollout.goal[step[robot], robot])
            count = len(replay.rollout.tiles[robot].waypoints) - 1
            index = np.arange(count)
            colors = np.where((index < goal)[:, None], rgb255(PASSED), rgb255(WAYPOINT))
            colors[index == goal] = rgb255(NEXT_WAYPOINT)
            self.handles[f"/trail/tile_{k}/waypoints"].batched_colors = colors.astype(np.uint8)

    def _caption(self, replay: Replay, frame: int, step: np.ndarray, me: int) -> None:
        rollout, s = replay.rollout, int(step[me])
        outcome = rollout.outcome[me] if frame >= rollout.end[me] else ""
        line = caption_line(replay.cfg.robot.name, replay.cfg.trail.name, rollout.level,
                            s * rollout.dt, float(rollout.walked[s, me]), outcome)
        self.caption.content = f"**robot {me}** · {line}"
        if rollout.depth is None:
            self.depth.visible = False
            return
        frame_now = rollout.depth[s, me]
        if self._depth_shown is None or self._depth_shown[0] != me \
                or not np.array_equal(self._depth_shown[1], frame_now):
            # redrawn only when it changes: a new frame every env.depth.every steps
            self._depth_shown = (me, frame_now)
            self.depth.visible = True
            self.depth.image = depth_panel(frame_now, rollout.depth_far, *DEPTH_PANEL,
                                           label=self.depth_label)

    def _follow(self, replay: Replay, step: np.ndarray, who: int | None, jump: bool) -> None:
        """Move each page's camera with the followed robot, keeping the angle its user
        gave it; ``jump``: to the default view of it (also what a page opened later and
        its "Reset View" start from)."""
        if who is None:
            return
        if jump:
            view = replay.default_view(who, int(step[who]))
            self.server.initial_camera.look_at, self.server.initial_camera.position = view
        for client in self.server.get_clients().values():
            self._move_camera(client, replay.pos[step[who], who, 0], jump)

    def _move_camera(self, client: viser.ClientHandle, target: np.ndarray, jump: bool) -> None:
        camera = client.camera
        if camera.update_timestamp == 0.0:  # the page has not reported its camera yet
            return
        if jump:
            with client.atomic():
                camera.position = self.server.initial_camera.position
                camera.look_at = self.server.initial_camera.look_at
        else:
            camera.position = camera.position + (target - camera.look_at)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        """A page opened while following a robot starts at that robot (viser calls this
        once the page has reported its camera)."""
        with self._lock:
            if self.replay is not None and self.followed() is not None:
                self._move_camera(client, self.server.initial_camera.look_at, jump=True)

    def close(self) -> None:
        """Stop the player and the server."""
        self._stop.set()
        self._player.join(timeout=2.0)
        self.server.stop()


