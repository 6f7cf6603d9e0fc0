"""The main job's defaults: it starts from the shipped oracle (``init=pretrained``), trains
with the hiking reward, and prints its benchmark beside the shipped policy's own."""

import json
from pathlib import Path

import pytest
import torch

from legoh import app
from legoh.config.env import hike_weights, walk_weights
from legoh.envs.mdp.rewards import preset_weights
from legoh.eval.metrics import METRICS
from legoh.policies.pretrained import PRETRAINED_DIR, benchmark_protocol, init_checkpoint
from legoh.train.oracle import train_oracle
from legoh.train.runner import progress_line
from tests.conftest import compose_config

TINY = ("trail=flat", "trail.levels=1", "trail.variants=1", "algo.num_envs=4",
        "algo.steps_per_env=8", "algo.epochs=1", "algo.minibatches=2", "algo.total_frames=32")


def test_init_settings_resolve(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys) -> None:
    assert init_checkpoint(None, "h1") is None
    assert init_checkpoint("none", "h1") is None
    assert init_checkpoint("some/oracle.pt", "h1") == Path("some/oracle.pt")
    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", tmp_path)
    (tmp_path / "h1_oracle.pt").write_bytes(b"")
    assert init_checkpoint("pretrained", "h1") == tmp_path / "h1_oracle.pt"
    assert init_checkpoint("pretrained", "g1") is None  # none shipped: from scratch, said
    assert "no pretrained oracle ships for robot 'g1'" in capsys.readouterr().out


def test_the_default_run_starts_from_the_shipped_oracle_and_none_from_scratch(tmp_path: Path
                                                                              ) -> None:
    if not (PRETRAINED_DIR / "h1_oracle.pt").is_file():
        pytest.skip("no shipped H1 oracle")
    shipped = torch.load(PRETRAINED_DIR / "h1_oracle.pt", map_location="cpu",
                         weights_only=False)["models"]["actor"]
    name = next(k for k in shipped if k.endswith("weight"))
    actors = {}
    for init in ("pretrained", "none"):
        cfg = compose_config(*TINY, f"init={init}")
        run = train_oracle(cfg, tmp_path / init)
        state = torch.load(run.checkpoint, map_location="cpu", weights_only=False)
        actors[init] = state["models"]["actor"][name]
    # one iteration of 2 Adam steps at the shipped lr (~1e-4) moves a weight ~2e-4
    assert torch.allclose(actors["pretrained"], shipped[name], atol=1e-3)
    assert not torch.allclose(actors["none"], shipped[name], atol=1e-1)


def test_the_default_reward_tracks_the_velocity_toward_the_waypoint() -> None:
    cfg = compose_config()
    assert cfg.env.reward_preset == "leap"  # hike + clearance terms (docs/oracle.md)
    for preset in ("leap", "hike"):
        weights = preset_weights(preset, {}, {})
        assert weights["tracking_waypoint_vel"] == 1.0 and weights["tracking_lin_vel"] == 0.0
    walk = walk_weights()
    assert {k: v for k, v in hike_weights().items() if not k.startswith("tracking_")} == {
        k: v for k, v in walk.items() if not k.startswith("tracking_")}


def test_the_benchmark_is_printed_beside_the_shipped_one_on_the_same_protocol(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys) -> None:
    cfg = compose_config(*TINY)
    shipped = {m: [80.0, 0.0] for m in METRICS}
    card = {"main_job": {"protocol": benchmark_protocol(cfg),
                         "rows": {"overall": shipped, "level 0": shipped}}}
    (tmp_path / "h1_oracle.json").write_text(json.dumps(card))
    monkeypatch.setattr("legoh.policies.pretrained.PRETRAINED_DIR", tmp_path)
    mine = {m: (50.0, 2.0) for m in METRICS}
    result = {"rows": {"overall": mine}, "levels": {"level 0": mine}}
    app.print_beside_shipped(cfg, result)
    out = capsys.readouterr().out
    assert "overall: shipped h1_oracle.pt" in out and "level 0: this run" in out
    assert "80.00 ± 0.00" in out and "50.00 ± 2.00" in out
    other = compose_config(*TINY, "eval.robots=3")  # another protocol: nothing to set beside
    app.print_beside_shipped(other, result)
    assert capsys.readouterr().out == ""
    # a student (python run.py algo=unified) is set beside its default teacher
    app.print_beside_shipped(compose_config(*TINY, "algo=unified"), result)
    out = capsys.readouterr().out
    assert "oracle (the teacher by default)" in out and "overall: shipped h1_oracle.pt" in out


def test_progress_bar_shows_frames_metres_and_falls_of_the_ended_episodes() -> None:
    stats = {"episode_frames": 500.0, "episode_metres": 7.25, "fell_frac": 0.25,
             "frames_per_s": 4000.0, "reward": 0.03}
    line = progress_line(stats, 1_500_000, 0.02, {"level": "0.40"})
    assert line["frames"] == "1.50M" and line["walked"] == "7.2m" and line["ep"] == "10.0s"
    assert line["falls"] == "25%" and line["level"] == "0.40"
    quiet = progress_line({**stats, "episode_frames": float("nan"),
                           "episode_metres": float("nan"), "fell_frac": 0.0}, 6144, 0.02, {})
    assert quiet["walked"] == quiet["ep"] == quiet["falls"] == "-"  # nothing ended: no 0 %
