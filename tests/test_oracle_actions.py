"""experiments/oracle_actions.py's rollout restarts robots whose episode ended."""

import sys
from pathlib import Path

import torch

from legoh.envs.hiking_env import make_env
from tests.conftest import compose_config

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
from oracle_actions import rollout_actions  # noqa: E402


def test_robots_restart_after_their_episode_ends() -> None:
    # Fault: env.step(td)["next"] never reset a robot, so one whose episode ended stepped on
    # with done set (6 of 32 robots in the 150 steps of the committed table)
    env = make_env(compose_config("trail=randommix", "trail.variants=1", "trail.levels=2",
                                  "env.episode_length_s=0.1", "env.stagger_timeouts=false"),
                   num_envs=2)
    try:
        def still(td):
            return td.set("action", torch.zeros(2, env.num_actions))

        actions, ended = rollout_actions(env, still, 12)
    finally:
        env.close()
    assert actions.shape == (12, 2, env.num_actions)
    # 5-step episodes: each robot ends at steps 5 and 10 (a fall may end one sooner); with
    # done stuck on, 2 robots x 8 steps would count
    assert 4 <= ended <= 6
