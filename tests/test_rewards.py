"""Reward terms of ``legoh.envs.mdp.rewards``: sign and magnitude of each, worked by hand.

Every case starts from a neutral two-env ``StepState`` (upright, standing still at the target
height in the default pose, facing a waypoint 2 m ahead along +x) and changes the fields the
term reads; env 0 and env 1 take the two sides of the behaviour under test.
"""

from dataclasses import replace

import numpy as np
import pytest
import torch

from legoh.config.env import EnvConfig, table6_weights, walk_weights
from legoh.envs.mdp.rewards import (
    REWARD_TERMS,
    active_terms,
    compute_rewards,
    preset_weights,
    term_params,
)
from legoh.envs.mdp.state import StepState

N, J, F = 2, 4, 2  # envs, joints, feet
DT = 0.02  # s
GOAL_SPEED = 0.8  # m/s (the EnvConfig default, as are the other term parameters)
TARGET_HEIGHT = 0.96  # m
PARAMS = term_params(EnvConfig(), target_height=TARGET_HEIGHT, reach_radius=0.5)


def neutral(**changes: object) -> StepState:
    """A StepState of N envs in which every penalty is 0; ``changes`` (numpy or torch)
    replace fields."""
    def zeros(*shape: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
        return torch.zeros(*shape, dtype=dtype)

    def tile(row: list[float], k: int) -> torch.Tensor:
        return torch.tensor(row, dtype=torch.float64).expand(k, -1).clone()

    state = StepState(
        dt=DT, base_pos=tile([0.0, 0.0, TARGET_HEIGHT], N), base_quat=tile([1.0, 0, 0, 0], N),
        roll=zeros(N), pitch=zeros(N), yaw=zeros(N), lin_vel_body=zeros(N, 3),
        ang_vel_body=zeros(N, 3), gravity_body=tile([0.0, 0.0, -1.0], N),
        lin_vel_world=zeros(N, 3), base_xy=zeros(N, 2),
        base_height=torch.full((N,), TARGET_HEIGHT, dtype=torch.float64),
        dof_pos=zeros(N, J), dof_vel=zeros(N, J), last_dof_vel=zeros(N, J),
        default_pose=zeros(J), joint_range=tile([-1.0, 1.0], J),
        hip_idx=torch.tensor([0, 1]), torques=zeros(N, J), last_torques=zeros(N, J),
        action=zeros(N, J), last_action=zeros(N, J), waypoint_xy=tile([2.0, 0.0], N),
        terminus_xy=tile([20.0, 0.0], N), terminus_local=tile([20.0, 0.0], N),
        middle_local=tile([10.0, 0.0], N), feet_force=zeros(N, F, 3),
        feet_contact=torch.ones(N, F, dtype=torch.bool),
        first_contact=zeros(N, F, dtype=torch.bool), air_time=zeros(N, F),
        feet_on_edge=zeros(N, F, dtype=torch.bool), unsafe_contacts=zeros(N, dtype=torch.int64),
        level=zeros(N, dtype=torch.int64), command=zeros(N, 2), phase=zeros(N, F),
        stance=torch.ones(N, F, dtype=torch.bool), feet_height=zeros(N, F),
        swing_target=zeros(N, F), clock_weight=torch.ones(N, dtype=torch.float64),
        advance=torch.ones(N, dtype=torch.bool),
        path_progress=zeros(N), line_progress=zeros(N), failed=zeros(N, dtype=torch.bool),
    )
    return replace(state, **{k: torch.as_tensor(v) for k, v in changes.items()})


def value_of(name: str, state: StepState) -> np.ndarray:
    """A registered term on ``state`` with its default (EnvConfig) parameters."""
    return REWARD_TERMS[name](state, **PARAMS.get(name, {})).numpy()


def rows(*per_env: list[float]) -> np.ndarray:
    """(N, ...) array, one row per env."""
    return np.array(per_env, dtype=np.float64)


tilt = 0.3  # rad
# term -> (changed fields, expected value per env, why)
CASES: dict[str, tuple[dict, list[float], str]] = {
    "tracking_goal_vel": (
        {"lin_vel_world": rows([0.4, 0.0, 0.0], [-0.4, 0.0, 0.0])},
        [0.4 / GOAL_SPEED, -0.4 / GOAL_SPEED],
        "toward the waypoint positive, away negative"),
    "tracking_yaw": (
        {"yaw": np.array([0.0, np.pi / 2])}, [1.0, np.exp(-np.pi / 2)],
        "1 facing the waypoint, exp(-|error|) otherwise"),
    "lin_vel_z": ({"lin_vel_body": rows([0.0, 0.0, 0.0], [1.0, 0.0, -2.0])}, [0.0, 4.0],
                  "v_z^2 only"),
    "ang_vel_xy": ({"ang_vel_body": rows([0.0, 0.0, 5.0], [1.0, 2.0, 5.0])}, [0.0, 5.0],
                   "yaw rate is free, roll and pitch rates squared"),
    "orientation": (
        {"gravity_body": rows([0.0, 0.0, -1.0], [np.sin(tilt), 0.0, -np.cos(tilt)])},
        [0.0, np.sin(tilt) ** 2], "0 upright, > 0 tilted"),
    "dof_acc": ({"dof_vel": rows([0.0] * J, [DT, 2 * DT, 0.0, 0.0])}, [0.0, 5.0],
                "squared joint accelerations (rad/s^2)"),
    "collision": ({"unsafe_contacts": np.array([0, 3])}, [0.0, 3.0], "counts bodies"),
    "action_rate": ({"action": rows([0.0] * J, [3.0, 4.0, 0.0, 0.0])}, [0.0, 5.0],
                    "norm of the action change"),
    "delta_torques": ({"torques": rows([0.0] * J, [1.0, 2.0, 0.0, 0.0])}, [0.0, 5.0],
                      "squared torque change"),
    "torques": ({"torques": rows([0.0] * J, [1.0, -2.0, 0.0, 0.0]),
                 "last_torques": rows([1.0, -2.0, 0.0, 0.0], [1.0, -2.0, 0.0, 0.0])},
                [0.0, 5.0], "squared torques, not their change"),
    "hip_pos": ({"dof_pos": rows([0.0, 0.0, 0.5, 0.5], [0.1, -0.2, 0.5, 0.5])}, [0.0, 0.05],
                "hip joints only (0, 1); the others are free"),
    "dof_error": ({"dof_pos": rows([0.0] * J, [0.1, 0.0, 0.0, -0.2])}, [0.0, 0.05],
                  "squared offsets from the default pose"),
    "feet_stumble": (
        {"feet_force": rows([[3.0, 0.0, 1.0], [0.0, 0.0, 0.0]], [[0.0, 0.0, 0.0],
                                                                  [3.0, 4.0, 1.0]])},
        [0.0, 1.0], "fires when horizontal force > 4x vertical (3 < 4, 5 > 4)"),
    "feet_edge": ({"feet_on_edge": np.ones((N, F), dtype=bool), "level": np.array([0, 1])},
                  [0.0, 2.0], "only above level 0 (env.edge_min_level), counts feet"),
    "leap_air_time": (
        {"first_contact": np.array([[True, False], [True, False]]),
         "air_time": rows([0.8, 0.0], [0.8, 0.0]), "clock_weight": np.array([0.0, 1.0])},
        [0.3, 0.0], "feet_air_time where the clock yields (weight 0), nothing where it holds"),
    "feet_air_time": (
        {"first_contact": np.array([[True, False], [True, False]]),
         "air_time": rows([0.8, 0.0], [0.2, 0.0])},
        [0.3, -0.3], "long flights rewarded, short ones penalised, at touch-down"),
    "base_height": ({"base_height": np.array([TARGET_HEIGHT, TARGET_HEIGHT - 0.1])},
                    [0.0, 0.01], "zero at the target height"),
    "pn_distance": ({"terminus_xy": rows([0.3, 0.0], [0.0, 4.0])}, [1.0, -3.0],
                    "1 inside the reach radius, -0.75 d outside"),
    "pn_progress": ({"path_progress": np.array([0.8, -0.3])}, [0.8, -0.3],
                    "the path left shrinking pays, growing costs (m/s)"),
    "pn_line_progress": ({"line_progress": np.array([0.5, -0.5])}, [0.5, -0.5],
                         "the straight-line distance shrinking pays (m/s)"),
    "pn_reach": ({"terminus_xy": rows([0.3, 0.0], [0.0, 4.0])}, [1.0, 0.0],
                 "1 inside the reach radius, nothing outside"),
    "dof_pos_limits": ({"dof_pos": rows([0.9, -0.9, 0.0, 0.0], [1.2, -1.5, 0.0, 0.0])},
                       [0.0, 0.7], "zero inside the range, overshoot summed outside"),
    "tracking_lin_vel": (
        {"command": rows([0.5, 0.0], [0.5, 0.0]),
         "lin_vel_world": rows([0.5, 0.0, 0.0], [0.0, 0.0, 0.0])},
        [1.0, np.exp(-1.0)], "1 at the commanded speed, exp(-err^2 / sigma) off it"),
    "tracking_waypoint_vel": (
        {"command": rows([0.5, 0.0], [0.5, 0.0]), "waypoint_xy": rows([5.0, 0.0], [5.0, 0.0]),
         "lin_vel_world": rows([0.5, 0.0, 0.0], [0.0, 0.5, 0.0])},
        [1.0, np.exp(-2.0)], "1 at the commanded speed toward the waypoint; sideways pays little"),
    "tracking_ang_vel": (
        {"command": rows([0.0, 0.5], [0.0, 0.5]),
         "ang_vel_body": rows([0.0, 0.0, 0.5], [0.0, 0.0, 0.0])},
        [1.0, np.exp(-1.0)], "1 at the commanded yaw rate"),
    "alive": ({}, [1.0, 1.0], "one per step"),
    "dof_vel": ({"dof_vel": rows([0.0] * J, [1.0, 2.0, 0.0, 0.0])}, [0.0, 5.0],
                "squared joint velocities"),
    "feet_contact_phase": (
        {"stance": np.array([[True, False], [True, False]]),
         "feet_contact": np.array([[True, False], [False, True]])},
        [2.0, 0.0], "counts feet whose contact matches the clock"),
    "feet_swing_height": (
        {"feet_contact": np.array([[False, True], [False, True]]),
         "feet_height": rows([0.08, 0.5], [0.0, 0.5])},
        [0.0, 0.0064], "airborne feet only, squared error to the swing height"),
    "feet_phase": (
        {"swing_target": rows([0.0, 0.0], [0.05, 0.0]), "feet_height": rows([0.0, 0.0],
                                                                          [0.0, 0.0])},
        [1.0, np.exp(-0.5)], "1 on the clock's foot lift, exp(-err^2 / 0.005) off it"),
    "termination": ({"failed": np.array([False, True])}, [0.0, 1.0],
                    "1 on the step an episode ends in a failure"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_term(name: str) -> None:
    changes, expected, why = CASES[name]
    value = value_of(name, neutral(**changes))
    assert value.shape == (N,)
    np.testing.assert_allclose(value, expected, rtol=1e-4, atol=1e-9, err_msg=why)


def test_every_registered_term_has_a_case() -> None:
    assert set(CASES) == set(REWARD_TERMS)


def test_neutral_state_has_no_penalty() -> None:
    state = neutral()
    # facing the goal; far from the terminus; on command (standing); alive; feet down as
    # the (standing) clock asks
    bonuses = {"tracking_yaw", "pn_distance", "tracking_lin_vel", "tracking_waypoint_vel",
               "tracking_ang_vel", "alive",
               "feet_contact_phase", "feet_phase"}
    for name in REWARD_TERMS:
        if name not in bonuses:
            np.testing.assert_allclose(value_of(name, state), 0.0, atol=1e-6, err_msg=name)


@pytest.mark.parametrize("name", ["feet_contact_phase", "feet_swing_height", "feet_phase"])
def test_the_clock_terms_yield_where_its_weight_is_zero(name: str) -> None:
    """Near an edge, pit or obstacle (clock weight 0) the gait clock does not judge the
    feet (with ``yield_pay=0``: neither pays nor charges); halfway out of that zone, half."""
    changes = CASES[name][0]
    params = PARAMS.get(name, {})
    if "yield_pay" in params:
        params = {**params, "yield_pay": 0.0}
    full = REWARD_TERMS[name](neutral(**changes), **params).numpy()
    weighted = REWARD_TERMS[name](neutral(**changes, clock_weight=np.array([0.0, 0.5])),
                                  **params).numpy()
    np.testing.assert_allclose(weighted, [0.0, 0.5 * full[1]], atol=1e-12)


@pytest.mark.parametrize("name,best", [("feet_contact_phase", 2.0), ("feet_phase", 1.0)])
def test_where_the_clock_yields_it_pays_yield_pay_of_its_best(name: str, best: float) -> None:
    """env.gait.yield_pay: where the clock yields its positive terms pay that share of their
    best whatever the feet do, so the zone near an obstacle is not a tax (at 0 a robot near
    a gap lost ~80 % of its step's reward); halfway out, half of each."""
    params = {**PARAMS[name], "yield_pay": 0.6}
    state = neutral(**CASES[name][0], clock_weight=np.array([0.0, 0.5]))
    full = value_of(name, neutral(**CASES[name][0]))
    np.testing.assert_allclose(REWARD_TERMS[name](state, **params).numpy(),
                               [0.6 * best, 0.5 * full[1] + 0.5 * 0.6 * best], atol=1e-9)


def test_tracking_goal_vel_is_capped_at_goal_speed() -> None:
    fast = neutral(lin_vel_world=rows([3.0, 0.0, 0.0], [0.0, 3.0, 0.0]))
    np.testing.assert_allclose(value_of("tracking_goal_vel", fast), [1.0, 0.0], atol=1e-4)


def test_air_time_is_zero_without_touch_down() -> None:
    state = neutral(air_time=rows([0.8, 0.8], [0.2, 0.2]))
    np.testing.assert_array_equal(value_of("feet_air_time", state), [0.0, 0.0])


def test_preset_terms_are_registered() -> None:
    assert set(table6_weights()) <= set(REWARD_TERMS)
    assert set(walk_weights()) <= set(REWARD_TERMS)


def test_active_terms_skips_zero_weights() -> None:
    terms = active_terms({"torques": -1e-5, "pn_distance": 0.0, "collision": -10.0})
    assert set(terms) == {"torques", "collision"}
    assert terms["collision"].fn is REWARD_TERMS["collision"]
    assert terms["collision"].weight == -10.0


def test_active_terms_names_unknown_terms() -> None:
    with pytest.raises(ValueError, match=r"torqes.*known:.*torques"):
        active_terms({"torqes": -1.0, "collision": -10.0})


def test_compute_rewards_total_is_dt_times_weighted_sum() -> None:
    state = neutral(unsafe_contacts=np.array([1, 2]),
                    lin_vel_world=rows([0.4, 0.0, 0.0], [0.8, 0.0, 0.0]))
    weights = {"collision": -10.0, "tracking_goal_vel": 10.0, "torques": 0.0}
    total, parts = compute_rewards(state, active_terms(weights, PARAMS))
    assert set(parts) == {"collision", "tracking_goal_vel"}
    expected_parts = {"collision": DT * -10.0 * np.array([1.0, 2.0]),
                      "tracking_goal_vel": DT * 10.0 * np.array([0.5, 1.0])}
    for name, part in expected_parts.items():
        np.testing.assert_allclose(parts[name], part, rtol=1e-4)
    np.testing.assert_allclose(total, sum(expected_parts.values()), rtol=1e-4)


def test_clip_at_zero_leaves_the_termination_term_out() -> None:
    state = neutral(unsafe_contacts=np.array([1, 0]), failed=np.array([True, False]),
                    lin_vel_world=rows([0.0, 0.0, 0.0], [0.4, 0.0, 0.0]))
    weights = {"collision": -10.0, "tracking_goal_vel": 10.0, "termination": -200.0}
    total, parts = compute_rewards(state, active_terms(weights, PARAMS), clip=True)
    np.testing.assert_allclose(parts["termination"], [-200.0 * DT, 0.0])
    # env 0: -10 dt clipped to 0, then the fall's -200 dt; env 1: 10 x 0.5 dt, unclipped
    np.testing.assert_allclose(total, [-200.0 * DT, 5.0 * DT], rtol=1e-4)


def test_compute_rewards_with_no_terms_is_zero() -> None:
    total, parts = compute_rewards(neutral(), {})
    assert parts == {}
    np.testing.assert_array_equal(total.numpy(), np.zeros(N))


def test_robot_reward_scales_multiply_the_preset_and_the_user_has_the_last_word() -> None:
    base = preset_weights("hike", {}, {})
    scaled = preset_weights("hike", {}, {}, {"tracking_waypoint_vel": 2.0, "alive": 0.5})
    assert scaled["tracking_waypoint_vel"] == 2.0 * base["tracking_waypoint_vel"]
    assert scaled["alive"] == 0.5 * base["alive"]
    assert scaled["tracking_lin_vel"] == base["tracking_lin_vel"] == 0.0  # 0 stays off
    user = preset_weights("hike", {"tracking_waypoint_vel": 1.5}, {},
                          {"tracking_waypoint_vel": 2.0})
    assert user["tracking_waypoint_vel"] == 1.5
    with pytest.raises(ValueError, match="robot.reward_scales.nonsense"):
        preset_weights("hike", {}, {}, {"nonsense": 2.0})


def test_the_documented_overrides_of_a_robots_reward_scales_compose() -> None:
    """docs/robots.md's commands: each scale set back to 1 restores the preset's weights, and
    ``+robot.reward_scales.<term>=x`` adds one. (``robot.reward_scales={}``, the docs' earlier
    advice, merges into the dict and removed nothing.)"""
    from legoh.config.compose import compose_config

    g1 = compose_config("robot=g1")
    assert dict(g1.robot.reward_scales) == {"tracking_lin_vel": 2.0,
                                            "tracking_waypoint_vel": 2.0}
    assert dict(compose_config("robot=g1", "robot.reward_scales={}").robot.reward_scales) == \
        dict(g1.robot.reward_scales)
    unit = compose_config("robot=g1", "robot.reward_scales.tracking_lin_vel=1",
                          "robot.reward_scales.tracking_waypoint_vel=1").robot.reward_scales
    assert preset_weights("hike", {}, {}, dict(unit)) == preset_weights("hike", {}, {})
    more = compose_config("robot=g1", "+robot.reward_scales.alive=10").robot.reward_scales
    assert preset_weights("hike", {}, {}, dict(more))["alive"] == \
        10 * preset_weights("hike", {}, {})["alive"]
