"""Config tree: every combination composes and matches its snapshot; bad input is named."""

from pathlib import Path

import pytest
from hydra.errors import ConfigCompositionException, MissingConfigException
from omegaconf import OmegaConf

from legoh.config import validate
from tests.conftest import CONF_DIR, compose_config

SNAPSHOTS = Path(__file__).parent / "snapshots"


def group_options(group: str) -> list[str]:
    return sorted(p.stem for p in (Path(CONF_DIR) / group).glob("*.yaml"))


COMBOS = [(r, t, a) for r in group_options("robot") for t in group_options("trail")
          for a in group_options("algo")]


def test_groups_have_the_required_options() -> None:
    assert group_options("robot") == ["g1", "h1"]
    assert set(group_options("trail")) >= {"flat", "randommix", "ditch", "hurdle", "gap",
                                           "forest", "hill"}
    assert "oracle" in group_options("algo")


def test_defaults() -> None:
    cfg = compose_config()
    assert (cfg.robot.name, cfg.trail.name, cfg.algo.name) == ("h1", "randommix", "oracle")


@pytest.mark.parametrize(("robot", "trail", "algo"), COMBOS)
def test_snapshot(robot: str, trail: str, algo: str, update_snapshots: bool) -> None:
    """Resolved YAML equals tests/snapshots/<robot>-<trail>-<algo>.yaml.

    After an intended change of a default, rewrite them: pytest --update-snapshots
    """
    cfg = compose_config(f"robot={robot}", f"trail={trail}", f"algo={algo}")
    text = OmegaConf.to_yaml(cfg, resolve=True)
    path = SNAPSHOTS / f"{robot}-{trail}-{algo}.yaml"
    if update_snapshots:
        path.write_text(text)
    assert path.exists(), f"no snapshot {path.name}: run pytest --update-snapshots"
    assert text == path.read_text(), f"{path.name} differs: review, then --update-snapshots"


def test_no_stale_snapshots() -> None:
    expected = {f"{r}-{t}-{a}.yaml" for r, t, a in COMBOS}
    assert {p.name for p in SNAPSHOTS.glob("*.yaml")} == expected


def message(err: pytest.ExceptionInfo) -> str:
    """The error text a user sees: Hydra's message and the cause it wraps."""
    return f"{err.value}\n{err.value.__cause__}"


def test_unknown_robot_lists_valid_options() -> None:
    with pytest.raises(MissingConfigException) as err:
        compose_config("robot=h2")
    assert "robot/h2" in str(err.value)
    assert "g1" in str(err.value) and "h1" in str(err.value)


def test_mistyped_key_is_named() -> None:
    with pytest.raises(ConfigCompositionException) as err:
        compose_config("robot.kpp=3")
    assert "Key 'kpp' not in 'RobotConfig'" in message(err)


def test_appending_an_unknown_key_is_refused_too() -> None:
    """Hydra's append syntax skips the schema; legoh.config.validate (run.py calls it) does not."""
    validate(compose_config())
    with pytest.raises(ValueError, match=r"robot\.kpp"):
        validate(compose_config("+robot.kpp=3"))
    with pytest.raises(ValueError, match=r"robot\.camera\.zoom"):
        validate(compose_config("+robot.camera.zoom=3"))


def test_wrong_type_is_named() -> None:
    with pytest.raises(ConfigCompositionException) as err:
        compose_config("robot.action_scale=abc")
    assert "robot.action_scale" in message(err) and "abc" in message(err)


def test_bad_enum_value_is_named() -> None:
    with pytest.raises(ConfigCompositionException) as err:
        compose_config("robot.upper_body=flailing")
    assert "upper_body" in message(err) and "hold" in message(err)


def test_bad_depth_backend_is_named() -> None:
    with pytest.raises(ConfigCompositionException) as err:
        compose_config("env.depth.backend=lidar")
    assert all(w in message(err) for w in ("env.depth.backend", "lidar", "raymarch", "multiray"))


def test_mistyped_key_in_a_yaml_file_fails(tmp_path: Path) -> None:
    """A typo inside an option file (not only on the command line) fails at composition."""
    from hydra import compose, initialize_config_dir

    conf = tmp_path / "conf"
    for group in (p.name for p in Path(CONF_DIR).iterdir() if p.is_dir()):
        (conf / group).mkdir(parents=True)
        for src in (Path(CONF_DIR) / group).glob("*.yaml"):
            (conf / group / src.name).write_text(src.read_text())
    (conf / "config.yaml").write_text((Path(CONF_DIR) / "config.yaml").read_text())
    h1 = conf / "robot" / "h1.yaml"
    h1.write_text(h1.read_text() + "action_scael: 0.5\n")
    with initialize_config_dir(config_dir=str(conf), version_base="1.3"):
        with pytest.raises(ConfigCompositionException) as err:
            compose("config")
    assert "Key 'action_scael' not in 'RobotConfig'" in message(err)


@pytest.mark.parametrize(("override", "shown"), [
    ("env.episode_length_s=-1", "env.episode_length_s=-1.0 is out of range: "
                                "env.episode_length_s must be 0 < x"),
    ("algo.num_envs=0", "algo.num_envs=0 is out of range: algo.num_envs must be 1 <= x"),
    ("env.depth.width=-5", "env.depth.width=-5 is out of range: env.depth.width must be 1 <= x"),
    ("algo.gamma=1.5", "algo.gamma must be 0 <= x <= 1"),
    ("algo.critic_hidden=[256,0]", "algo.critic_hidden=[256, 0] is out of range: "
                                   "algo.critic_hidden must be 1 <= x"),
    ("env.command.speed=[1.0,0.2]", "env.command.speed=[1.0, 0.2] is out of range: "
                                    "env.command.speed must be [low, high] with low <= high"),
    ("env.curriculum.down=0.9", "env.curriculum.down=0.9 must not exceed env.curriculum.up"),
    ("eval.spawn_remaining=[10.0,2.0]", "eval.spawn_remaining=[10.0, 2.0] is out of range: "
                                        "eval.spawn_remaining must be [low, high] with low "
                                        "<= high, each 0 <= x"),
    ("eval.tc_radius=0", "eval.tc_radius=0.0 is out of range: eval.tc_radius must be 0 < x"),
    # failed before with: DID NOT RAISE (0 s between pushes pushed at every step)
    ("env.randomization.push_interval_s=0", "env.randomization.push_interval_s=0.0 is out of "
                                            "range: env.randomization.push_interval_s must "
                                            "be 0 < x"),
])
def test_values_out_of_range_are_named(override: str, shown: str) -> None:
    """validate() names the key, the value and the range of a number out of range.

    Failed before with: DID NOT RAISE (the schemas checked types only)."""
    with pytest.raises(ValueError, match="") as err:
        validate(compose_config(override))
    assert shown in str(err.value)


def test_every_numeric_setting_has_a_range() -> None:
    """Each numeric key of every option of every group matches a row of the range table, and
    every shipped option passes it (a new setting needs a row; a default must be valid)."""
    from legoh.config.ranges import numeric_leaves, rule_for

    overrides = [f"{g}={o}" for g in ("robot", "trail", "algo", "eval", "collector")
                 for o in group_options(g)]
    for override in overrides:
        cfg = compose_config(override)
        validate(cfg)
        plain = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
        unmatched = [k for k, _ in numeric_leaves(plain) if rule_for(k) is None]
        assert not unmatched, f"{override}: no range for {unmatched}"


def test_sim_backend_is_a_group_and_a_key() -> None:
    """sim=warp picks MuJoCo Warp with its own defaults; sim.backend=warp flips the key alone."""
    assert compose_config().sim.backend == "mujoco"
    warp = compose_config("sim=warp").sim
    assert (warp.backend, warp.hfield_chunk, warp.graph) == ("warp", 8.0, True)
    assert compose_config("sim.backend=warp").sim.hfield_chunk == 4.0
    with pytest.raises(ValueError, match=r"sim\.nconmax"):
        validate(compose_config("sim=warp", "sim.nconmax=0"))
