"""Stage 2's learning signal, worked on constructed cases: the navigation reward ranks a
walk above a fall, progress is counted through waypoints without jumps."""

import numpy as np
import pytest
import torch

from legoh.config.algo import NavReward, UnifiedConfig
from legoh.envs.mdp.rewards import active_terms, compute_rewards
from legoh.envs.mdp.state import Goals, NavProgress, TrailTable
from legoh.policies.student import nav_reward_weights
from tests.test_rewards import DT, PARAMS, neutral

WALKER = 0.041  # reward a step of the flat walker's own (walk preset) terms, measured
SPEED = 0.8  # m/s, env.goal_speed
TRAIL = 22.0  # m: a trail's length, the terminus straight ahead of the spawn


def episode_returns(form: NavReward, steps: int, fall_at: int | None = None,
                    stop_at: float | None = None, terminus: float = TRAIL) -> np.ndarray:
    """Discounted returns (gamma of stage 2) of two robots walking at SPEED toward a
    terminus ``terminus`` m ahead: env 0 walks on (or stops ``stop_at`` m before it), env 1
    the same but, if ``fall_at``, pitches 1 m forward over 10 steps and ends there, a
    failure. Both earn WALKER a step while alive; reaching the terminus ends an episode."""
    algo = UnifiedConfig(nav_reward=form)
    table = active_terms({k: w for k, w in nav_reward_weights(algo).items()}, PARAMS)
    x = torch.zeros(2, dtype=torch.float64)
    alive = torch.ones(2, dtype=torch.bool)
    total = np.zeros(2)
    for t in range(steps):
        step = torch.full((2,), SPEED * DT, dtype=torch.float64)
        if stop_at is not None:
            step = torch.clamp(terminus - stop_at - x, min=0.0).clamp(max=SPEED * DT)
        failed = torch.zeros(2, dtype=torch.bool)
        if fall_at is not None and t >= fall_at - 10:
            step[1] = 0.1  # the body pitches forward: 1 m in 10 steps
            failed[1] = t == fall_at - 1
        x = x + step
        state = neutral(base_xy=torch.stack([x, torch.zeros(2, dtype=x.dtype)], 1),
                        terminus_xy=torch.tensor([[terminus, 0.0]] * 2, dtype=x.dtype),
                        path_progress=step / DT, line_progress=step / DT, failed=failed)
        reward, _ = compute_rewards(state, table)
        reward = reward + WALKER
        total += (algo.gamma**t * reward * alive).numpy()
        reached = (terminus - x) < PARAMS["pn_reach"]["radius"]
        alive = alive & ~failed & ~reached
    return total


@pytest.mark.parametrize("form", [NavReward.progress, NavReward.line_progress])
def test_falling_returns_less_than_walking(form: NavReward) -> None:
    """A 20 s walk against a dive after 1 s: 5.7 against 2.8. The paper's term gives the
    fall the higher return (-11.1 against -26.5)."""
    walk, fall = episode_returns(form, steps=1000, fall_at=50)
    assert walk > fall + 1.0


def test_the_papers_form_pays_for_falling() -> None:
    """Why the form changed: under -0.75 d a step the dive out-earns the walk."""
    walk, fall = episode_returns(NavReward.paper, steps=1000, fall_at=50)
    assert fall > walk


@pytest.mark.parametrize("form", [NavReward.progress, NavReward.line_progress])
def test_reaching_returns_more_than_loitering(form: NavReward) -> None:
    """Reaching ends the episode (and its walking reward): the bonus outweighs what a robot
    standing 0.6 m short of a terminus 2 m ahead would still earn."""
    reach, _ = episode_returns(form, steps=1000, terminus=2.0)
    loiter, _ = episode_returns(form, steps=1000, stop_at=0.6, terminus=2.0)
    assert reach > loiter


def test_paper_form_weights_only_the_distance_term() -> None:
    w = nav_reward_weights(UnifiedConfig(nav_reward=NavReward.paper, pn_distance=1.0))
    assert w == {"pn_distance": 1.0, "pn_progress": 0.0, "pn_line_progress": 0.0,
                 "pn_reach": 0.0}


# --------------------------------------------------------------------------- progress
def l_trail() -> TrailTable:
    """One tile: start (0, 0), waypoints (5, 0), (5, 5), terminus (10, 5); 15 m of path."""
    wp = np.array([[[5.0, 0.0], [5.0, 5.0], [10.0, 5.0]]])
    one = np.zeros(1)
    return TrailTable(waypoints=wp, count=np.array([3]), cum_length=np.array([[5.0, 10.0, 15.0]]),
                      length=np.array([15.0]), start=np.zeros((1, 3)), start_yaw=one,
                      terminus=np.array([[10.0, 5.0]]), middle=np.array([[5.0, 5.0]]),
                      category=np.zeros(1, int), level=np.zeros(1, int),
                      variant=np.zeros(1, int), ahead=np.zeros((1, 3), bool)
                      ).to(torch.device("cpu"), torch.float64)


def test_progress_along_the_path_and_in_a_line() -> None:
    trails = l_trail()
    goals = Goals(1, trails, radius=0.6, device=torch.device("cpu"))
    nav = NavProgress(1, torch.device("cpu"), torch.float64)
    xy = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    assert goals.remaining(xy).item() == pytest.approx(14.0)
    nav.start(xy)
    path, line = nav.update(goals, trails.terminus[[0]], xy + torch.tensor([[0.1, 0.0]]), DT)
    assert path.item() == pytest.approx(0.1 / DT)
    expected = (np.hypot(9.0, 5.0) - np.hypot(8.9, 5.0)) / DT
    assert line.item() == pytest.approx(expected)


def test_passing_a_waypoint_is_no_jump_in_progress() -> None:
    """Both ends of a step are measured through the waypoint current after it: 0.1 m along
    x at the corner gains 0.35 m/s toward (5, 5), not the 19.5 m/s of the index change."""
    trails = l_trail()
    goals = Goals(1, trails, radius=0.6, device=torch.device("cpu"))
    nav = NavProgress(1, torch.device("cpu"), torch.float64)
    nav.start(torch.tensor([[4.6, 0.0]], dtype=torch.float64))
    now = torch.tensor([[4.7, 0.0]], dtype=torch.float64)
    goals.advance(now)
    assert goals.index.item() == 1
    path, _ = nav.update(goals, trails.terminus[[0]], now, DT)
    expected = (np.hypot(0.4, 5.0) - np.hypot(0.3, 5.0)) / DT
    assert path.item() == pytest.approx(expected)


def test_progress_is_zero_on_the_step_after_a_reset() -> None:
    nav = NavProgress(2, torch.device("cpu"), torch.float64)
    goals = Goals(2, l_trail(), radius=0.6, device=torch.device("cpu"))
    xy = torch.zeros(2, 2, dtype=torch.float64)
    nav.start(xy)
    nav.reset(torch.tensor([1]))  # env 1 diverged and was reset within the step
    path, line = nav.update(goals, torch.tensor([[10.0, 5.0]] * 2, dtype=torch.float64),
                            xy + 0.1, DT)
    assert path[0] != 0 and path[1] == 0 and line[1] == 0


# --------------------------------------------------------------------------- command
def test_stage_two_commands_the_evaluation_speed() -> None:
    """The oracle reads the forward-speed command, the student cannot: stage 2 commands
    env.goal_speed in every episode. Failed before: speeds drawn from U(0.3, 1.0), 10 % 0."""
    from legoh.envs.hiking_env import make_env
    from legoh.policies.student import student_env_overrides
    from tests.conftest import compose_config

    cfg = compose_config("algo=unified", "trail=flat", "trail.levels=1", "trail.variants=1")
    overrides = student_env_overrides(cfg)
    overrides["depth"].enabled = False  # the command does not need frames
    env = make_env(cfg, num_envs=32, **overrides)
    try:
        for _ in range(2):
            td = env.reset()
            assert torch.all(env.command.speed == cfg.env.goal_speed)
            assert torch.all(td["obs", "command"][:, 0] == cfg.env.goal_speed)
    finally:
        env.close()


# --------------------------------------------------------------------------- critic
def critic_shift(cfg) -> float:
    """How far one ppo_update moves a critic whose targets lie 20 below its values."""
    from tensordict import TensorDict
    from tensordict.nn import NormalParamExtractor, TensorDictModule
    from torchrl.modules import IndependentNormal, ProbabilisticActor, ValueOperator

    from legoh.modules.actor_critic import LOG_PROB, STATE_VALUE
    from legoh.objectives.ppo import make_ppo, ppo_update

    torch.manual_seed(0)
    actor = ProbabilisticActor(
        TensorDictModule(torch.nn.Sequential(torch.nn.Linear(3, 4), NormalParamExtractor()),
                         ["obs"], ["loc", "scale"]),
        in_keys=["loc", "scale"], distribution_class=IndependentNormal, return_log_prob=True,
        log_prob_key=LOG_PROB)
    critic = ValueOperator(torch.nn.Linear(3, 1), in_keys=["obs"])
    loss, _ = make_ppo(actor, critic, cfg)
    data = actor(TensorDict({"obs": torch.randn(256, 3)}, batch_size=[256]))
    with torch.no_grad():
        before = critic(data.clone())[STATE_VALUE]
    data.set(STATE_VALUE, before)
    data.set("value_target", before - 20.0)
    data.set("advantage", torch.zeros_like(before))
    optim = torch.optim.Adam(loss.parameters(), lr=cfg.lr)
    ppo_update(loss, optim, data.detach(), cfg, torch.Generator().manual_seed(0))
    with torch.no_grad():
        return float((before - critic(data.clone())[STATE_VALUE]).mean())


def test_the_stage_two_critic_follows_returns_far_below_its_values() -> None:
    """Stage 2 starts from the oracle's critic, ~30 above its returns. Failed before: the
    value was clipped to 0.2 from where it collected, whatever the epochs and lr."""
    from legoh.config.algo import OracleConfig

    long = {"lr": 0.01, "desired_kl": 0.0, "epochs": 40, "minibatches": 4}
    assert critic_shift(UnifiedConfig(**long)) > 1.5  # measured 1.78
    # the oracle keeps rsl_rl's clipping: stalled at 0.35 (0.2 + Adam's momentum), 20 epochs
    # or 40
    assert critic_shift(OracleConfig(**long)) < 0.5


# --------------------------------------------------------------------------- exploration
def test_every_student_explores_with_the_same_fixed_std() -> None:
    """Failed before: LEGO-H sampled with a trained std starting at 0.5, the distill-only
    baselines with 0.1."""
    from legoh.policies.student import build_student, make_student_env
    from tests.conftest import compose_config

    scales = {}
    for algo in ("unified", "ep_h", "rma_b"):
        cfg = compose_config(f"algo={algo}", "trail=flat", "trail.levels=1", "trail.variants=1")
        probe = make_student_env(cfg, 1, ((1,), 1))
        student = build_student(cfg, probe)
        probe.close()
        std = student.locomotion.module[0].module.std
        assert not any(p.requires_grad for p in std.parameters()), algo
        scales[algo] = std(torch.zeros(1, *std.scale_shape))[1]
        torch.testing.assert_close(scales[algo], torch.full_like(scales[algo],
                                                                 cfg.algo.init_noise_std))


# --------------------------------------------------------------------------- waypoints
@pytest.mark.parametrize("rule,passed", [("radius", [0, 0, 1]), ("past", [1, 0, 1])])
def test_a_waypoint_passed_beside_counts_under_the_past_rule(rule: str, passed: list) -> None:
    """Waypoint (5, 0), reached along +x. Robot 0 walked by it 1 m to the side, robot 1
    is 1 m short and to the side, robot 2 within the radius. Under ``radius`` robot 0 is
    labelled back toward a waypoint behind it (the circling the rule teaches)."""
    goals = Goals(3, l_trail(), radius=0.6, device=torch.device("cpu"), rule=rule)
    goals.advance(torch.tensor([[5.1, 1.0], [4.0, 1.0], [4.7, 0.2]], dtype=torch.float64))
    assert goals.index.tolist() == passed


def test_the_past_rule_measures_from_the_previous_waypoint() -> None:
    """At waypoint 1 (5, 5), reached along +y from (5, 0): past means y > 5."""
    goals = Goals(2, l_trail(), radius=0.6, device=torch.device("cpu"), rule="past")
    goals.index[:] = 1
    goals.advance(torch.tensor([[7.0, 5.1], [7.0, 4.9]], dtype=torch.float64))
    assert goals.index.tolist() == [2, 1]


def test_stage_two_trains_with_the_past_rule_and_evaluates_with_radius() -> None:
    """The oracle's env keeps radius (its training campaign uses it); stage 2's training
    env passes waypoints once past them; its evaluation counts TR and TC as the oracle's."""
    from legoh.config.env import WaypointPass
    from legoh.policies.student import student_env_overrides
    from tests.conftest import compose_config

    assert compose_config("algo=oracle").env.waypoint_pass == WaypointPass.radius
    cfg = compose_config("algo=unified")
    assert student_env_overrides(cfg)["waypoint_pass"] == WaypointPass.past
    assert "waypoint_pass" not in student_env_overrides(cfg, evaluation=True)


def test_stage_two_trains_under_full_randomisation_from_the_first_step() -> None:
    """The benchmark scores with Table 5's randomisation; the env's gate opens only while
    most training episodes end without a fall, and the first H1 student campaign fell too
    often for it to open in 45 minutes (its strength stayed 0). Failed before: stage 2's
    training env started at strength 0. ``algo.randomization=env`` keeps the gate."""
    from legoh.envs.hiking_env import make_env
    from legoh.policies.student import student_env_overrides
    from tests.conftest import compose_config

    for mode, strength in (("full", 1.0), ("env", 0.0)):
        cfg = compose_config("algo=unified", f"algo.randomization={mode}", "trail=flat",
                             "trail.levels=1", "trail.variants=1")
        overrides = student_env_overrides(cfg)
        overrides["depth"].enabled = False
        env = make_env(cfg, num_envs=4, **overrides)
        try:
            env.reset()
            assert env.randomization.strength(env.global_steps) == strength, mode
            assert env.randomization.delay_on(env.global_steps) == strength, mode
        finally:
            env.close()
    cfg = compose_config("algo=unified", "env.randomization.enabled=false")
    assert "randomization" not in student_env_overrides(cfg)  # off stays off
    with pytest.raises(Exception, match="algo.randomization"):
        compose_config("algo=unified", "algo.randomization=sometimes")


def test_an_unknown_waypoint_rule_is_refused() -> None:
    with pytest.raises(ValueError, match="env.waypoint_pass"):
        Goals(1, l_trail(), radius=0.6, device=torch.device("cpu"), rule="near")


# --------------------------------------------------------------------------- frame window
def test_the_student_sees_four_frames_half_a_second_apart() -> None:
    """The paper's window: 16 frames at 10 Hz sub-sampled to 4. Failed before: the last
    4 consecutive frames (0.1 s apart, 0.3 s in all)."""
    from legoh.envs.mdp.observations import DepthFrames
    from tests.conftest import compose_config

    cfg = compose_config("algo=unified")
    depth = cfg.env.depth
    frames = DepthFrames(1, depth, torch.device("cpu"))
    for k in range(30):  # frame k is filled with the value k
        frames.push(torch.full((1, depth.height, depth.width), float(k)))
    seen = frames(None, {})
    assert seen.shape == (1, 4, depth.height, depth.width)
    ages = (29 - seen[0, :, 0, 0]) * depth.every * cfg.sim.dt * cfg.sim.decimation  # s
    torch.testing.assert_close(ages, torch.tensor([1.5, 1.0, 0.5, 0.0]))


def test_a_reset_fills_the_whole_window_with_its_first_frame() -> None:
    from omegaconf import OmegaConf

    from legoh.config.env import DepthConfig, depth_window
    from legoh.envs.mdp.observations import DepthFrames

    cfg = OmegaConf.structured(DepthConfig(history=7, stride=3, height=2, width=2))
    assert depth_window(cfg) == [0, 3, 6]

    class FakeEnv:  # what DepthFrames.render reads, replaced
        pass

    frames = DepthFrames(2, cfg, torch.device("cpu"))
    frames.render = lambda env, ids: torch.ones(len(ids), 2, 2)
    frames.reset(torch.tensor([1]), FakeEnv())
    assert frames(None, {})[1].eq(1).all() and frames(None, {})[0].eq(0).all()


# --------------------------------------------------------------------------- prior
WALKER_CHECKPOINT = "experiments/results/learn_walk/h1-walk-s0-fast-c256-e3/oracle.pt"


def test_the_pretrained_prior_rebuilds_teacher_actions_better_than_a_fresh_one() -> None:
    """The VAE pre-trained on the walker's own rollouts, checked on new episodes. Measured
    with the 4096-frame default: 0.18 action units against 0.71 for the old first iteration
    (a fresh VAE, 4 steps) and 0.48 for each joint's mean."""
    import copy
    from pathlib import Path

    from legoh.config.env import DepthConfig
    from legoh.envs.hiking_env import make_env
    from legoh.policies.oracle import load_teacher
    from legoh.policies.student import student_env_overrides
    from legoh.train.prior import make_prior, pretrain_prior, reconstruction_error, teacher_actions
    from tests.conftest import compose_config

    torch.set_num_threads(1)
    walker = Path(__file__).resolve().parents[1] / WALKER_CHECKPOINT
    cfg = compose_config("algo=unified", "trail=flat", "trail.levels=1", "trail.variants=1",
                         f"algo.oracle_checkpoint={walker}", "algo.prior_pretrain_frames=1024",
                         "algo.prior_pretrain_steps=150")
    env = make_env(cfg, 16, **{**student_env_overrides(cfg), "depth": DepthConfig()})
    try:
        oracle, _ = load_teacher(cfg, walker, env)
        torch.manual_seed(0)
        vae, optim, _ = make_prior(cfg, env.action_spec.shape[-1])
        fresh = copy.deepcopy(vae)
        out = pretrain_prior(vae, optim, env, oracle, cfg, torch.Generator().manual_seed(0))
        held = teacher_actions(env, oracle, 512)  # new episodes (the rollout resets)
    finally:
        env.close()
    bound = cfg.env.action_clip
    pretrained = reconstruction_error(vae, held, bound)
    assert out["actions"] == 1024
    assert pretrained < 0.5 * reconstruction_error(fresh, held, bound)
    assert pretrained < 0.7 * out["recon_error_mean_guess"]  # more than each joint's mean


def test_a_vae_saved_before_the_fitted_range_still_loads() -> None:
    from legoh.modules.vae import ActionVAE, ActionVAEConfig

    vae = ActionVAE(4, ActionVAEConfig(hidden=8, blocks=1, latent=2))
    old = {k: v for k, v in vae.state_dict().items() if k not in ("center", "spread")}
    vae.fit_action_range(torch.randn(64, 4) * 2 + 1, bound=20.0)
    vae.load_state_dict(old)
    assert vae.center.eq(0).all() and vae.spread.eq(1).all()


# --------------------------------------------------------------------------- DAgger mixture
def test_the_teacher_share_decays_from_one_to_zero() -> None:
    from legoh.train.dagger import teacher_share

    assert [teacher_share(i, 4) for i in range(6)] == [1.0, 0.75, 0.5, 0.25, 0.0, 0.0]
    assert teacher_share(0, 0) == 0.0 and teacher_share(7, 0) == 0.0  # off


def test_the_mixture_executes_the_teacher_on_a_share_beta_of_the_steps() -> None:
    from tensordict import TensorDict
    from tensordict.nn import TensorDictModule

    from legoh import keys
    from legoh.modules.actor_critic import LOC
    from legoh.train.dagger import TeacherMix, student_rows

    student = TensorDictModule(lambda x: torch.zeros(x.shape[0], 2), ["obs"], [keys.ACTION])
    teacher = TensorDictModule(lambda x: torch.ones(x.shape[0], 2), ["obs"], [LOC])
    mix = TeacherMix(student, teacher)
    td = TensorDict({"obs": torch.zeros(4000, 3)}, batch_size=[4000])
    for beta in (0.0, 0.25, 1.0):
        mix.beta.fill_(beta)
        torch.manual_seed(0)
        out = mix(td.clone())
        acted = out.get(keys.TEACHER_ACTED).squeeze(-1)
        assert out.get(keys.ACTION)[acted].eq(1).all() and out.get(keys.ACTION)[~acted].eq(0).all()
        assert abs(float(acted.float().mean()) - beta) < 0.03
        assert student_rows(out).shape[0] == int((~acted).sum())


def test_dagger_labels_are_clamped_to_algo_label_clip() -> None:
    """The shipped v2 H1 oracle's raw mean actions on its own hiking states exceed what the
    env applies (its ankles' RMS ~25, env.action_clip 20): ``algo.label_clip`` clamps the
    DAgger labels the imitation and the prior learn from; None keeps them raw. Failed
    before: no clamp, the labels reached ~47."""
    from legoh import keys
    from legoh.envs.hiking_env import make_env
    from legoh.modules.actor_critic import LOC
    from legoh.policies.embodiment import with_checkpoint_body
    from legoh.policies.oracle import load_teacher
    from legoh.policies.pretrained import resolve_checkpoint
    from legoh.train.unified import label_with_oracle
    from tests.conftest import compose_config

    path = resolve_checkpoint("pretrained", "h1")
    cfg = with_checkpoint_body(compose_config("robot=h1", "trail=hike", "algo=unified",
                                              "env.reward_preset=leap"), path)
    assert cfg.algo.label_clip is None  # the default: the oracle's raw mean
    env = make_env(cfg, num_envs=8)
    try:
        oracle, _ = load_teacher(cfg, path, env)
        td, raw = env.reset(), []
        with torch.no_grad():
            for _ in range(40):
                td = oracle(td)
                raw.append(td.get(LOC).abs().max())
                label_with_oracle(oracle, td)
                assert torch.equal(td.get(keys.TEACHER_ACTION), td.get(LOC))
                label_with_oracle(oracle, td, clip=5.0)
                assert td.get(keys.TEACHER_ACTION).abs().max() <= 5.0
                td = env.step(td)["next"]
    finally:
        env.close()
    assert max(raw) > 5.0  # the case the clamp is for
