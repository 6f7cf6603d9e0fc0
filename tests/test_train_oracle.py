"""Oracle stage: a tiny PPO run end to end, the loss on a fixed batch, resume, logs."""

import csv
import shutil
from pathlib import Path

import pytest
import torch
from tensordict import TensorDictBase

from legoh.checkpoint import CheckpointError, load_checkpoint
from legoh.envs.hiking_env import make_env
from legoh.logs import read_mcap
from legoh.objectives.ppo import adapt_learning_rate, make_ppo, ppo_update
from legoh.policies.oracle import build_oracle
from legoh.train.oracle import train_oracle
from tests.conftest import compose_config

# collection and update in turns: the oracle's default overlap starts a worker process per
# run (this file's tests 14 -> 49 s); test_collect.py runs the overlap itself
TINY = ("trail=flat", "trail.levels=1", "trail.variants=1", "algo.num_envs=4",
        "algo.steps_per_env=8", "algo.epochs=2", "algo.minibatches=2",
        "algo.checkpoint_every=1", "algo.trajectory_every=1", "collector.overlap=false")


def test_tiny_run_end_to_end_writes_logs_and_checkpoint(tmp_path: Path) -> None:
    cfg = compose_config(*TINY, "algo.total_frames=64")
    run = train_oracle(cfg, tmp_path)
    assert run.iterations == 2
    rows = run.csv.read_text().strip().splitlines()
    header = rows[0].split(",")
    assert len(rows) == 3  # header + 2 iterations
    for column in ("iteration", "loss_objective", "loss_critic", "loss_entropy", "kl_approx",
                   "lr", "frames_per_s", "reward", "level_mean", "loss_adaptation",
                   "reward/tracking_waypoint_vel", "reward/feet_phase", "episode_metres"):
        assert column in header, column
    topics = [topic for topic, _, _ in read_mcap(run.mcap)]
    assert topics.count("scalars") == 2
    assert topics.count("trajectory") == 2 * 8  # one message per step, both iterations
    state = load_checkpoint(run.checkpoint, expect_robot="h1")
    assert state["iteration"] == 2 and set(state["models"]) == {"actor", "critic", "adaptation"}


def test_resume_continues_from_the_checkpoint(tmp_path: Path) -> None:
    first = train_oracle(compose_config(*TINY, "algo.total_frames=32"), tmp_path)
    assert first.iterations == 1
    saved = load_checkpoint(first.checkpoint)["models"]["actor"]
    cfg = compose_config(*TINY, "algo.total_frames=96", f"resume={first.checkpoint}")
    second = train_oracle(cfg, tmp_path, resume=cfg.resume)
    assert second.iterations == 3
    rows = second.csv.read_text().strip().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3"]  # appended, not restarted
    resumed = load_checkpoint(second.checkpoint)["models"]["actor"]
    assert any(not torch.equal(saved[k], resumed[k]) for k in saved)  # it trained on


def test_resume_into_the_killed_runs_folder_keeps_one_history(tmp_path: Path, capsys) -> None:
    """A run killed after iteration 4 whose last checkpoint is at 2: the resumed run's CSV
    reads 1-4 once (rows past the checkpoint dropped, then logged again).

    Failed before with: iterations [1, 2, 3, 4, 3, 4] (3-4 twice)."""
    def keep_iteration_2(it, *_):
        if it == 2:
            shutil.copy(tmp_path / "oracle.pt", tmp_path / "at-2.pt")

    train_oracle(compose_config(*TINY, "algo.total_frames=128"), tmp_path,
                 on_iteration=keep_iteration_2)
    cfg = compose_config(*TINY, "algo.total_frames=128", f"resume={tmp_path / 'at-2.pt'}")
    run = train_oracle(cfg, tmp_path, resume=cfg.resume)
    rows = run.csv.read_text().strip().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3", "4"]
    assert "dropped iteration(s) 3-4" in capsys.readouterr().out


def test_divergence_is_counted_warned_once_and_logged_in_the_run_folder(
        tmp_path: Path, monkeypatch) -> None:
    """A threshold every moving robot crosses: each iteration logs its count of diverged
    resets, one warning says so, and MuJoCo's own log goes to the run folder, not the cwd.

    Failed before with: KeyError 'diverged' (no such column); MUJOCO_LOG.TXT in the cwd."""
    import mujoco

    monkeypatch.chdir(tmp_path)
    out = tmp_path / "run"

    def mujoco_warns(it, *_):  # a real MuJoCo instability warning, mid-run
        model = mujoco.MjModel.from_xml_string(
            "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>")
        data = mujoco.MjData(model)
        data.qvel[:] = float("nan")
        mujoco.mj_step(model, data)

    cfg = compose_config(*TINY, "algo.total_frames=64", "env.divergence_qvel=1e-6")
    with pytest.warns(RuntimeWarning, match="simulation.s. diverged in iteration 1") as seen:
        run = train_oracle(cfg, out, on_iteration=mujoco_warns)
    assert sum("diverged" in str(w.message) for w in seen) == 1
    with run.csv.open() as f:
        counts = [float(row["diverged"]) for row in csv.DictReader(f)]
    assert len(counts) == 2 and all(c > 0 for c in counts)
    assert "unstable" in (out / "MUJOCO_LOG.TXT").read_text()
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_resume_past_the_budget_ends_at_once(tmp_path: Path, capsys) -> None:
    """A budget below the checkpoint's progress means no more frames, said in a message.

    Failed before with: the collector got a negative frame budget (torchrl: endless) and
    collected on; the guard below caught iteration 3 of a 1-iteration budget."""
    first = train_oracle(compose_config(*TINY, "algo.total_frames=64"), tmp_path)
    assert first.iterations == 2
    cfg = compose_config(*TINY, "algo.total_frames=32", f"resume={first.checkpoint}")
    calls = []
    run = train_oracle(cfg, tmp_path, resume=cfg.resume,
                       on_iteration=lambda it, *_: calls.append(it) or True)
    assert calls == [] and run.iterations == 2
    assert "no more frames to collect" in capsys.readouterr().out
    assert load_checkpoint(run.checkpoint)["iteration"] == 2


def test_resume_into_another_robot_is_refused(tmp_path: Path) -> None:
    first = train_oracle(compose_config(*TINY, "algo.total_frames=32"), tmp_path / "h1")
    cfg = compose_config(*TINY, "robot=g1", "algo.total_frames=64")
    with pytest.raises(CheckpointError, match="g1"):
        train_oracle(cfg, tmp_path / "g1", resume=str(first.checkpoint))


def test_ppo_loss_falls_on_a_fixed_batch() -> None:
    # Unclipped rewards: a 16-step batch of clipped rewards is mostly zeros, which leaves the
    # critic nothing to fit.
    cfg, actor, loss, data = _fixed_batch()
    optimizer = torch.optim.Adam(loss.parameters(), lr=3e-4)

    def losses() -> dict[str, float]:
        with torch.no_grad():
            out = loss(data)
        return {k: float(v) for k, v in out.items() if k.startswith("loss_")}

    advantage = data["advantage"].reshape(-1)
    advantage = (advantage - advantage.mean()) / advantage.std()

    def log_prob() -> torch.Tensor:
        with torch.no_grad():
            return actor.get_dist(data.clone()).log_prob(data["action"]).reshape(-1)

    before, log_prob_before = losses(), log_prob()
    algo = cfg.algo.copy()
    algo.desired_kl = 0.0  # a fixed learning rate: this test is about the loss going down
    algo.epochs, algo.minibatches = 5, 4
    ppo_update(loss, optimizer, data, algo, torch.Generator().manual_seed(0))
    after = losses()
    assert after["loss_critic"] < before["loss_critic"]
    # what PPO pushes up: the advantage-weighted change of the taken actions' log-likelihood
    # (per sample first: the mean of log_prob x advantage itself is ~1e-7 and its change
    # below float32's resolution on some CPUs)
    assert float(((log_prob() - log_prob_before) * advantage).mean()) > 0


def test_adaptive_learning_rate_rule() -> None:
    assert adapt_learning_rate(1e-3, kl=0.05, desired_kl=0.01) == pytest.approx(1e-3 / 1.5)
    assert adapt_learning_rate(1e-3, kl=0.001, desired_kl=0.01) == pytest.approx(1.5e-3)
    assert adapt_learning_rate(1e-3, kl=0.01, desired_kl=0.01) == pytest.approx(1e-3)
    assert adapt_learning_rate(1e-5, kl=1.0, desired_kl=0.01) == pytest.approx(1e-5)  # clamp


def _rollout(*overrides: str):
    """(cfg, actor, critic, loss, gae, a 16-step rollout of 4 envs without advantages)."""
    cfg = compose_config(*TINY, *overrides)
    env = make_env(cfg, num_envs=4)
    torch.manual_seed(0)
    _, actor, critic, _ = build_oracle(env, cfg)
    loss, gae = make_ppo(actor, critic, cfg.algo)
    with torch.no_grad():
        batch = env.rollout(16, actor, break_when_any_done=False)
    env.close()
    return cfg, actor, critic, loss, gae, batch


def _fixed_batch(*overrides: str):
    # exact comparisons: float32 unless a test asks otherwise (auto picks bfloat16 on AMX)
    if not any(o.startswith("algo.update_precision=") for o in overrides):
        overrides = ("algo.update_precision=float32", *overrides)
    cfg, actor, _, loss, gae, batch = _rollout("env.only_positive_rewards=false", *overrides)
    gae(batch)
    return cfg, actor, loss, batch.reshape(-1)


def test_one_pass_gae_equals_torchrls_two_pass_gae() -> None:
    # The critic runs once on obs; next values are obs values shifted by a step, recomputed
    # where the next obs is not the following obs (episode ends, the batch's last step).
    # Episodes of 0.2 s end inside the 16-step rollout, so the recomputed rows are exercised.
    from torchrl.objectives.value import GAE

    cfg, _, critic, _, gae, batch = _rollout("env.episode_length_s=0.2")
    done = batch["next", "done"].squeeze(-1)
    assert done[:, :-1].any()  # some episode ends mid-batch
    two_pass = GAE(gamma=cfg.algo.gamma, lmbda=cfg.algo.gae_lambda, value_network=critic,
                   average_gae=False)
    expected = batch.clone()
    with torch.no_grad():
        two_pass(expected)
    got = gae(batch.clone())
    for key in ("advantage", "value_target", "state_value", ("next", "state_value")):
        torch.testing.assert_close(got[key], expected[key], rtol=1e-5, atol=1e-6)
    # a next value read from obs[t + 1] at an episode end would differ
    shifted = expected["state_value"][:, 1:][done[:, :-1]]
    assert not torch.allclose(shifted, expected["next", "state_value"][:, :-1][done[:, :-1]])


def test_exact_kl_reads_the_losss_own_forward_pass() -> None:
    # The KL that steers the learning rate comes from the distribution the loss computed, not
    # a second actor forward: it must equal the KL of a fresh forward on the same minibatch.
    from legoh.modules.actor_critic import LOC, SCALE
    from legoh.objectives.ppo import gaussian_kl

    cfg, actor, loss, data = _fixed_batch()
    optimizer = torch.optim.Adam(loss.parameters(), lr=1e-2)
    algo = cfg.algo.copy()
    algo.desired_kl, algo.epochs, algo.minibatches = 0.0, 1, 1
    ppo_update(loss, optimizer, data, algo, exact_kl=True)  # move the policy off the data's
    stats = ppo_update(loss, torch.optim.Adam(loss.parameters(), lr=0.0), data, algo,
                       exact_kl=True)
    with torch.no_grad():
        new = actor(data.select(*actor.in_keys).clone())
    expected = float(gaussian_kl(data[LOC], data[SCALE], new[LOC], new[SCALE]))
    assert expected > 1e-6  # the first update moved the policy
    assert stats["kl_exact"] == pytest.approx(expected, rel=1e-4)


def test_bfloat16_update_matches_float32_within_its_rounding() -> None:
    # update_precision=bfloat16: autocast forward passes. On the acting policy (lr 0) the
    # ratio is 1 up to rounding: KL and clip fraction far below the trust region's 0.01 / 0.2.
    cfg, _, loss, data = _fixed_batch("algo.update_precision=bfloat16")
    algo = cfg.algo.copy()
    algo.desired_kl, algo.epochs, algo.minibatches = 0.0, 1, 1
    still = ppo_update(loss, torch.optim.Adam(loss.parameters(), lr=0.0), data, algo,
                       exact_kl=True)
    assert still["kl_exact"] < 1e-3 and still["clip_fraction"] < 0.01
    before = [p.detach().clone() for p in loss.parameters()]
    ppo_update(loss, torch.optim.Adam(loss.parameters(), lr=1e-3), data, algo, exact_kl=True)
    assert all(p.dtype == torch.float32 for p in loss.parameters())  # weights stay float32
    assert any(not torch.equal(a, p) for a, p in zip(before, loss.parameters(), strict=True))


def test_update_precision_names_its_choices() -> None:
    with pytest.raises(Exception) as err:  # Hydra's override error, OmegaConf's as its cause
        compose_config(*TINY, "algo.update_precision=float16")
    cause = str(err.value.__cause__)
    assert "update_precision" in cause and "float32, bfloat16" in cause


def test_a_lagged_batch_is_clipped_against_the_current_policy() -> None:
    # collector.overlap acts with the weights of an earlier update. Against those, the KL
    # already counts the previous step (the adaptive lr then shrinks); lagged=True makes the
    # weights the update starts from the proximal policy: KL 0 and no clipping at lr 0.
    cfg, actor, loss, data = _fixed_batch()
    algo = cfg.algo.copy()
    algo.desired_kl, algo.epochs, algo.minibatches = 0.0, 1, 1
    ppo_update(loss, torch.optim.Adam(loss.parameters(), lr=1e-2), data, algo, exact_kl=True)
    still = torch.optim.Adam(loss.parameters(), lr=0.0)
    stale = ppo_update(loss, still, data.clone(), algo, exact_kl=True)
    fresh = ppo_update(loss, still, data.clone(), algo, exact_kl=True, lagged=True)
    assert stale["kl_exact"] > 1e-4
    assert fresh["kl_exact"] == pytest.approx(0.0, abs=1e-7)
    assert fresh["clip_fraction"] == 0.0


def test_rows_acted_far_off_the_current_policy_barely_move_a_lagged_update() -> None:
    """A student's batch under collector.overlap was acted by a policy whose mean lay many
    stds from the one its update starts from; re-evaluated as if the current policy had
    acted, those rows' log-probability gradients ((a - mu) / sigma^2) ran the update away
    (grad norm 4e5-9e7, docs/unified.md). Decoupled PPO weighs them by pi / pi_behav ~ 0.
    Failed before: re-evaluated under the current policy, these rows gave 4.5x the gradient
    norm of rows the current policy acted (6.3 vs 1.4); now ~0."""
    cfg, actor, loss, data = _fixed_batch()
    algo = cfg.algo.copy()
    algo.desired_kl, algo.epochs, algo.minibatches, algo.max_grad_norm = 0.0, 1, 1, 1e12
    algo.value_coef = algo.entropy_coef = 0.0  # the surrogate's gradient alone
    loss, _ = make_ppo(actor, loss.critic_network, algo)
    with torch.no_grad():
        dist = actor.get_dist(data.select(*actor.in_keys).clone()).base_dist
    torch.manual_seed(0)

    def acted_by(policy: torch.distributions.Normal) -> TensorDictBase:
        batch, action = data.clone(), policy.sample()
        batch.set("action", action)
        batch.set("sample_log_prob", policy.log_prob(action).sum(-1))
        return batch

    still = torch.optim.Adam(loss.parameters(), lr=0.0)
    on_policy = ppo_update(loss, still, acted_by(dist), algo)["grad_norm"]
    far = torch.distributions.Normal(dist.loc + 5 * dist.scale, dist.scale)  # 5 stds off
    lag = ppo_update(loss, still, acted_by(far), algo, lagged=True)["grad_norm"]
    assert lag < 0.1 * on_policy


def test_the_lagged_loss_is_torchrls_decoupled_ppo() -> None:
    """KeepDistPPOLoss on a lagged batch computes torchrl's decoupled PPO
    (delay_actor=True, max_importance_ratio=2) with the proximal log-prob computed once."""
    from torchrl.objectives import ClipPPOLoss

    from legoh.objectives.ppo import MAX_IMPORTANCE_RATIO, use_current_policy_as_proximal

    cfg, actor, loss, data = _fixed_batch()
    with torch.no_grad():  # the behaviour policy: the mean moved by half a std
        dist = actor.get_dist(data.select(*actor.in_keys).clone()).base_dist
        behaviour = torch.distributions.Normal(dist.loc + 0.5 * dist.scale, dist.scale)
        torch.manual_seed(0)
        action = behaviour.sample()
        data.set("action", action)
        data.set("sample_log_prob", behaviour.log_prob(action).sum(-1))
        for p in actor.parameters():  # this update's start: another step on from there
            p.add_(0.01 * torch.randn_like(p))
    reference = ClipPPOLoss(actor, loss.critic_network, clip_epsilon=cfg.algo.clip_epsilon,
                            entropy_coeff=cfg.algo.entropy_coef,
                            critic_coeff=cfg.algo.value_coef, loss_critic_type="l2",
                            normalize_advantage=True, delay_actor=True,
                            max_importance_ratio=MAX_IMPORTANCE_RATIO)
    reference.set_keys(sample_log_prob="sample_log_prob")
    with torch.no_grad():
        reference.target_actor_network_params.update_(reference.actor_network_params.detach())
    ours = data.clone()
    use_current_policy_as_proximal(loss, ours)
    with torch.no_grad():  # one step of the policy after the update began
        for p in actor.parameters():
            p.add_(0.01 * torch.randn_like(p))
        want, got = reference(data.clone()), loss(ours)
    for key in ("loss_objective", "clip_fraction", "kl_approx", "ESS"):
        assert float(got[key]) == pytest.approx(float(want[key]), rel=1e-4, abs=1e-6), key


def test_update_precision_auto_follows_the_cpu(monkeypatch) -> None:
    from legoh.objectives import ppo

    monkeypatch.setattr(ppo.Path, "read_text", lambda self: "fpu sse avx2 amx_bf16 amx_tile")
    assert ppo.use_bfloat16("auto", "cpu") and not ppo.use_bfloat16("float32", "cpu")
    monkeypatch.setattr(ppo.Path, "read_text", lambda self: "fpu sse avx2 avx512f")
    assert not ppo.use_bfloat16("auto", "cpu") and ppo.use_bfloat16("bfloat16", "cpu")


def test_a_batch_used_in_place_trains_as_a_copied_one(tmp_path: Path, request) -> None:
    """The in-process collector yields its own buffer (collect.py: no copy of each batch):
    the same seed logs the same losses as torchrl's copying collector, over three batches."""
    logs = []
    for k in range(2):
        if k == 1:
            request.getfixturevalue("copying_collector")
        run = train_oracle(compose_config(*TINY, "algo.total_frames=96"), tmp_path / str(k))
        with run.csv.open() as f:
            logs.append([{key: value for key, value in row.items()
                          if not key.startswith(("time/", "frames_per_s"))}
                         for row in csv.DictReader(f)])
    assert len(logs[0]) == 3 and logs[0] == logs[1]


def test_batch_scalars_log_each_categorys_share_of_the_robots() -> None:
    """``share/<category>``: the category mix the curriculum's lagging_mix moves."""
    from tensordict import TensorDict

    from legoh.train.runner import batch_scalars

    t, n = 3, 4
    z = torch.zeros(t, n, 1)
    nxt = TensorDict({"reward": z, "done": z.bool(),
                      "info": {"episode_steps": z, "episode_metres": z, "level": z.long(),
                               "reached": z.bool(), "fell": z.bool(), "diverged": z.bool(),
                               "progress": z,
                               "category": torch.tensor([0, 1, 1, 1]).expand(t, n),
                               "reward_terms": {"alive": z}}}, batch_size=[t, n])
    stats = batch_scalars(TensorDict({"next": nxt}, batch_size=[t, n]), ["gap", "forest"])
    assert stats["share/gap"] == 0.25 and stats["share/forest"] == 0.75
