"""mode=play viewer=web: a real rollout served by a real viser server, its scene graph and
playback, the command through run.py (URL printed, Ctrl-C ends it), and a headless
Chromium whose screenshot shows the robot."""

import os
import re
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from legoh.config.compose import compose_config
from legoh.viewer import browser
from legoh.viewer.cli import for_trail, make_viewer, trail_names
from legoh.viewer.scene import body_meshes, robot_model

ROOT = Path(__file__).resolve().parents[1]
# two hurdle tiles of level 0, two robots, 1 s episodes: a scene with every kind of node
TINY = ("trail=hurdle", "trail.levels=1", "trail.variants=2", "eval.seconds=1",
        "eval.levels=[0]", "eval.variants=2")
ROBOTS = 2


@pytest.fixture(scope="module")
def viewer():
    """The web viewer of an untrained H1 on two hurdle tiles, on a free port."""
    cfg = compose_config(*TINY, "web.port=0")
    v = make_viewer(cfg, None, TINY, robots=ROBOTS)
    yield v
    v.close()


def test_scene_graph_holds_trail_robots_waypoints_and_terminus(viewer) -> None:
    """viser's own scene holds, per distinct tile the robots hike, its ground, its hurdles,
    its waypoints (one instance each, the terminus apart) and the terminus's flag; per
    robot body with a mesh one batched mesh, one instance per robot, posed as recorded."""
    scene, replay = viewer.server.scene, viewer.replay
    tiles = [replay.rollout.terrain.tiles[t] for t in replay.tiles]
    assert 1 <= len(tiles) <= ROBOTS and all(t.category == "hurdle" for t in tiles)
    for k, tile in enumerate(tiles):
        assert scene.get_handle_by_name(f"/terrain/tile_{k}/ground") is not None
        assert scene.get_handle_by_name(f"/terrain/tile_{k}/box_0") is not None  # a hurdle
        waypoints = scene.get_handle_by_name(f"/trail/tile_{k}/waypoints")
        assert len(waypoints.batched_positions) == len(tile.waypoints) - 1
        for part in ("pole", "flag"):
            node = scene.get_handle_by_name(f"/trail/tile_{k}/terminus/{part}")
            assert np.linalg.norm(node.position[:2] - tile.terminus[:2]) < 0.5
    model = robot_model(OmegaConf.to_object(compose_config(*TINY).robot))
    names = [model.body(b).name for b in body_meshes(model)]
    assert "pelvis" in names and "left_ankle_link" in names and len(names) >= 15
    for name in names:
        handle = scene.get_handle_by_name(f"/robots/{name}")
        assert handle is not None and len(handle.batched_positions) == ROBOTS
    viewer.slider.value = replay.rollout.steps  # the last step: each robot where it ended
    pelvis = scene.get_handle_by_name("/robots/pelvis")
    ends = replay.rollout.end
    np.testing.assert_allclose(pelvis.batched_positions,
                               replay.rollout.qpos[ends, np.arange(ROBOTS), :3], atol=1e-5)


def test_playback_steps_scrubs_plays_and_captions(viewer) -> None:
    """One step on, a scrub, play in real time x 4 until it pauses at the end; the caption
    names robot, trail, level, time and metres walked; following robot 1 turns it blue."""
    viewer.set_playing(False)
    viewer.slider.value = 0
    viewer._step(+1)
    assert viewer.slider.value == 1
    pelvis = viewer.server.scene.get_handle_by_name("/robots/pelvis")
    viewer.slider.value = 20
    np.testing.assert_allclose(pelvis.batched_positions[0],
                               viewer.replay.rollout.qpos[min(20, viewer.replay.rollout.end[0]),
                                                          0, :3], atol=1e-5)
    assert re.search(r"H1 .*trail hurdle, level 0 .*t = +0\.4 s .*walked [+-]\d+\.\d m",
                     viewer.caption.content), viewer.caption.content
    viewer.speed.value = "4"
    viewer.set_playing(True)
    deadline = time.monotonic() + 30.0
    while viewer.playing and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not viewer.playing and viewer.slider.value == viewer.replay.rollout.steps
    viewer.follow.value = "robot 1"
    assert viewer.caption.content.startswith("**robot 1**")
    assert tuple(pelvis.batched_colors[1]) != tuple(pelvis.batched_colors[0])
    viewer.follow.value = "robot 0"


def test_trail_selector_records_another_rollout(viewer) -> None:
    """The selector offers the benchmark trails; choosing flat and running again replaces
    the scene with flat tiles (no hurdles) and the caption says so."""
    assert {"flat", "hurdle", "forest", "ditch", "gap", "randommix"} <= set(trail_names())
    assert for_trail(["trail=hurdle", "trail.levels=1", "mode=play"], "flat") == [
        "trail.levels=1", "mode=play", "trail=flat"]
    before = viewer.replay
    viewer.trail.value = "flat"
    assert viewer.level.options == ("0",)
    viewer._rerun()
    try:
        assert viewer.replay is not before and viewer.replay.cfg.trail.name == "flat"
        scene = viewer.server.scene
        assert scene.get_handle_by_name("/terrain/tile_0/ground") is not None
        assert scene.get_handle_by_name("/terrain/tile_0/box_0") is None
        assert "trail flat" in viewer.caption.content
    finally:
        viewer.trail.value = "hurdle"
        viewer._rerun()
    assert viewer.replay.cfg.trail.name == "hurdle"


def chromium_or_skip() -> str:
    """Debian's chromium, as .ci/run installs it; CI fails without it, a desk skips."""
    path = browser.find_chromium()
    if path is None:
        reason = "no chromium on this machine: apt-get install chromium (.ci/run does)"
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    return path


def test_headless_chromium_shows_the_robot(viewer, tmp_path: Path) -> None:
    """The page in a real browser: the 3-D canvas is drawn (not blank), hiding the robots
    changes it where the followed robot stands (the canvas's centre: the camera looks at
    it), and following robot 1 moves the page's own camera to that robot."""
    path = chromium_or_skip()
    viewer.slider.value = 0
    # smaller than a desk's window: SwiftShader's cost grows with the pixels
    with browser.open_page(viewer.url, path, viewport={"width": 960, "height": 600}) as page:
        shown = browser.settled_canvas(page)
        page.screenshot(path=str(tmp_path / "viewer.png"))
        assert shown.std() > 10, f"a blank canvas at {viewer.url}"
        robots = [h for name, h in viewer.handles.items() if name.startswith("/robots/")]
        for handle in robots:
            handle.visible = False
        try:
            hidden = browser.settled_canvas(page)
        finally:
            for handle in robots:
                handle.visible = True
        changed = browser.changed(shown, hidden)
        h, w = changed.shape
        centre = changed[h // 2 - 60: h // 2 + 60, w // 2 - 60: w // 2 + 60]
        assert changed.sum() > 1000 and centre.sum() > 200, (changed.sum(), centre.sum())
        viewer.follow.value = "robot 1"
        target = viewer.replay.pos[0, 1, 0]
        deadline = time.monotonic() + 30.0
        client = next(iter(viewer.server.get_clients().values()))
        while time.monotonic() < deadline and np.linalg.norm(
                client.camera.look_at - target) > 0.05:
            page.wait_for_timeout(200)
        assert np.linalg.norm(client.camera.look_at - target) <= 0.05
        viewer.follow.value = "robot 0"


def test_run_py_serves_prints_the_url_and_ends_on_ctrl_c(tmp_path: Path) -> None:
    """The command a user types: it prints the URL, the page is served there, and SIGINT
    (Ctrl-C) ends it with exit code 0 and a last line saying so."""
    proc = subprocess.Popen(
        [sys.executable, "run.py", "mode=play", "viewer=web", *TINY, "web.port=0",
         f"hydra.run.dir={tmp_path / 'run'}"], cwd=ROOT, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        url, lines = None, []
        for line in proc.stdout:
            lines.append(line)
            match = re.search(r"web viewer: (http://\S+)", line)
            if match:
                url = match.group(1)
                break
        assert url, "".join(lines)[-3000:]
        with urllib.request.urlopen(url, timeout=30) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out[-3000:]
    assert "web viewer stopped" in out


def test_bad_port_is_refused_naming_key_value_and_range() -> None:
    """web.port out of 0..65535 fails at validation, naming the key, value and range."""
    from legoh.config import validate

    with pytest.raises(ValueError, match=r"web\.port=70000 .*0 <= x <= 65535"):
        validate(compose_config("web.port=70000"))
