"""Depth students: LEGO-H's unified policy and the baselines, as one navigation module
(depth rate, recurrent) plus one locomotion module (policy rate).

Every student is a :class:`Navigator` wrapped by :class:`NavigationModule` and followed by
the same locomotion actor (:func:`make_locomotion_actor`):

==========  ===========================================  ==================================
student     navigation (runs on each new depth frame)    what locomotion sees
==========  ===========================================  ==================================
lego_h      TC-ViTs over the frame history + GRU / CT    z_uni, (delta_g0, g1)
ep_h        per-frame depth CNN (2 m range) + GRU        depth latent, predicted heading
rma_b       none (blind): proprio-history encoder        history latent, terminus/waypoint
rma_h       frame-stack CNN -> g1..g3, trained apart     history latent, g1 (detached)
==========  ===========================================  ==================================

Latent tiling: :meth:`Navigator.frame` runs only on steps where a depth frame arrived (or
an episode began); its outputs are held in the recurrent state ``NAV_HELD`` and reused on
the steps between frames. :meth:`Navigator.act` runs every step on the held outputs (and
per-step inputs such as the proprioception history).

Recurrent state travels through the TensorDict the torchrl way: the module reads
``NAV_STATE``/``NAV_HELD`` and writes them under ``"next"``; :func:`student_primer` declares
them so the env resets them to zeros (a zero state is a fresh episode).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictModuleBase
from torch import nn
from torchrl.data import Composite, Unbounded
from torchrl.modules import IndependentNormal, ProbabilisticActor

from legoh import keys
from legoh.modules.actor_critic import LOC, LOG_PROB, SCALE, ConcatMLP, GaussianPolicyHead
from legoh.modules.encoders import HistoryConvEncoder, mlp

LATENT_DIM = 32  # z_uni has the size of the oracle's z_tea (scandot encoder output)
# the history latent (algo.history_latent) has the size and the encoder shape of the oracle's
# privileged latent and adaptation module (OracleNetConfig: priv_encoder[-1], channels)
PRIV_LATENT_DIM, HISTORY_CHANNELS = 20, 10
EP_DEPTH_RANGE = 2.0  # m: EP-H's short depth range (Extreme Parkour clips depth at 2 m)


@dataclass(frozen=True)
class StudentDims:
    """Per-env input sizes of a student, read from the env's observation spec."""

    proprio: int
    history: int
    depth: tuple[int, int, int] | None  # (frames, H, W), None without depth
    depth_far: float = 3.0  # m: the env's far plane (depth is normalised by it)

    @classmethod
    def from_spec(cls, spec, depth_far: float = 3.0) -> StudentDims:
        obs = spec["obs"]
        depth = tuple(obs["depth"].shape[-3:]) if "depth" in obs.keys() else None
        hist, proprio = obs["proprio_history"].shape[-2:]
        return cls(proprio=proprio, history=hist, depth=depth, depth_far=depth_far)

    def require_depth(self, student: str) -> tuple[int, int, int]:
        """(frames, H, W), or a clear error when the env gives no depth."""
        if self.depth is None:
            raise ValueError(f"{student} needs depth frames: the env has env.depth.enabled=False")
        return self.depth

    def as_layout(self) -> dict[str, tuple[int, ...]]:
        """Observation layout stored in checkpoints (a student from another robot fails)."""
        out = {"/".join(keys.PROPRIO): (self.proprio,),
               "/".join(keys.PROPRIO_HISTORY): (self.history, self.proprio)}
        if self.depth is not None:
            out["/".join(keys.DEPTH)] = self.depth
        return out


class Navigator(nn.Module):
    """What a student's navigation half provides (subclasses fill it in).

    Attributes:
        uses_depth: ``frame`` needs ``("obs","depth")``; otherwise it runs every step.
        state_shape: per-env recurrent state (zeros: a new episode).
        held_dim: size of the outputs held between frames.
        nav_dim: size of ``NAV_GOAL``. num_goals: near goals predicted (0: none).
        history_dim: size of ``HISTORY_LATENT`` (0: the navigator writes none).
        in_keys: observation keys read by ``frame`` and ``act``.
    """

    uses_depth: bool = True
    state_shape: tuple[int, ...] = (1,)
    held_dim: int = 1
    nav_dim: int = 4
    num_goals: int = 0
    history_dim: int = 0
    in_keys: tuple = (keys.GOAL, keys.PROPRIO)

    def frame(self, obs: dict, state: torch.Tensor, features: torch.Tensor | None = None
              ) -> tuple[torch.Tensor, torch.Tensor]:
        """Depth-rate step on B rows -> (held (B, held_dim), new state (B, *state_shape));
        ``features``: these rows' :meth:`encode`, when computed ahead."""
        raise NotImplementedError

    def encode(self, obs: dict) -> torch.Tensor | None:
        """The state-free features of a frame (B, F), which :func:`unroll` computes for all
        fresh frames of a batch in one call; None: the navigator has no such part."""
        return None

    def act(self, obs: dict, held: torch.Tensor) -> dict[str, torch.Tensor]:
        """Policy-rate outputs: ``latent`` (B, 32), ``nav_goal`` (B, nav_dim),
        ``near_goals`` (B, num_goals, 2), ``goal_correction`` (B, 2), and
        ``history_latent`` (B, history_dim) when ``history_dim``."""
        raise NotImplementedError


def _unit(xy: torch.Tensor) -> torch.Tensor:
    return xy / xy.norm(dim=-1, keepdim=True).clamp_min(1e-6)


class LegoHNavigator(Navigator):
    """TC-ViTs (legoh/modules/tcvit.py): latent z_uni, delta_g0 and g1..g3 from the frame
    history, the goals and proprioception. Only (delta_g0, g1) go to locomotion.

    ``history``: also a latent of the proprioception history every step (the oracle's
    adaptation module's shape; ``algo.history_latent``), which locomotion reads too."""

    in_keys = (keys.DEPTH, keys.GOAL, keys.PROPRIO)

    def __init__(self, dims: StudentDims, preset: str = "small", core: str = "gru",
                 history: bool = False) -> None:
        super().__init__()
        from legoh.modules.tcvit import TCViTs, tcvit_config

        frames, height, width = dims.require_depth("lego_h")
        self.cfg = tcvit_config(preset, core=core, frames=frames, height=height, width=width)
        self.net = TCViTs(self.cfg, proprio_dim=dims.proprio)
        self.state_shape = tuple(self.net.state_shape)
        self.num_goals = self.cfg.num_goals
        self.held_dim = LATENT_DIM + 2 + 2 * self.num_goals
        if history:
            self.history = HistoryConvEncoder(dims.proprio, dims.history, PRIV_LATENT_DIM,
                                              HISTORY_CHANNELS)
            self.history_dim = PRIV_LATENT_DIM
            self.in_keys = (*self.in_keys, keys.PROPRIO_HISTORY)

    def encode(self, obs):
        return self.net.encode(obs[keys.DEPTH], obs[keys.GOAL][:, :2])

    def frame(self, obs, state, features=None):
        if features is None:
            features = self.encode(obs)
        out = self.net.recur(features, obs[keys.GOAL], obs[keys.PROPRIO], state)
        held = torch.cat([out["latent"], out["goal_correction"],
                          out["near_goals"].flatten(-2)], dim=-1)
        return held, out["state"]

    def act(self, obs, held):
        latent, corr, goals = held.split([LATENT_DIM, 2, 2 * self.num_goals], dim=-1)
        goals = goals.unflatten(-1, (self.num_goals, 2))
        out = {"latent": latent, "goal_correction": corr, "near_goals": goals,
               "nav_goal": torch.cat([corr, goals[..., 0, :]], dim=-1)}
        if self.history_dim:
            out["history_latent"] = self.history(obs[keys.PROPRIO_HISTORY])
        return out


class DepthCNN(nn.Module):
    """Small conv net over (B, C, H, W) depth (Extreme Parkour's depth backbone shape:
    conv 5x5 - pool - conv 3x3, then a linear layer), output (B, out_dim) with ELU."""

    def __init__(self, channels: int, height: int, width: int, out_dim: int = 128) -> None:
        super().__init__()
        self.conv = nn.Sequential(
            nn.Conv2d(channels, 16, 5, padding=2), nn.ELU(), nn.MaxPool2d(2),
            nn.Conv2d(16, 32, 3, padding=1), nn.ELU(), nn.MaxPool2d(2), nn.Flatten())
        flat = 32 * (height // 4) * (width // 4)
        self.head = nn.Sequential(nn.Linear(flat, out_dim), nn.ELU())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.conv(x))


class EPHNavigator(Navigator):
    """EP-H: the newest frame only, depth clipped at 2 m, a CNN, a GRU over frames; outputs
    a depth latent and a heading = unit(terminus direction + predicted correction)."""

    in_keys = (keys.DEPTH, keys.GOAL, keys.PROPRIO)
    nav_dim = 2

    def __init__(self, dims: StudentDims, hidden: int = 256) -> None:
        super().__init__()
        _, height, width = dims.require_depth("ep_h")
        # normalised depth is d / far - 0.5: the 2 m clip in those units
        self.clip = min(EP_DEPTH_RANGE / dims.depth_far, 1.0) - 0.5
        self.cnn = DepthCNN(1, height, width)
        self.gru = nn.GRUCell(128 + 4 + dims.proprio, hidden)
        self.head = nn.Linear(hidden, LATENT_DIM + 2)
        self.state_shape = (hidden,)
        self.held_dim = LATENT_DIM + 2

    def frame(self, obs, state, features=None):  # no encode(): features is None
        depth = obs[keys.DEPTH][:, -1:].clamp(max=self.clip)
        x = torch.cat([self.cnn(depth), obs[keys.GOAL], obs[keys.PROPRIO]], dim=-1)
        h = self.gru(x, state)
        latent, corr = self.head(h).split([LATENT_DIM, 2], dim=-1)
        return torch.cat([torch.tanh(latent), corr], dim=-1), h

    def act(self, obs, held):
        latent, corr = held.split([LATENT_DIM, 2], dim=-1)
        heading = _unit(_unit(obs[keys.GOAL][..., :2]) + corr)
        return {"latent": latent, "goal_correction": corr, "nav_goal": heading}


class HistoryLatent(nn.Module):
    """RMA's adaptation encoder over the proprioception history -> a Tanh latent (B, 32)."""

    def __init__(self, dims: StudentDims) -> None:
        super().__init__()
        self.enc = HistoryConvEncoder(dims.proprio, dims.history, LATENT_DIM)
        self.out = nn.Tanh()

    def forward(self, history: torch.Tensor) -> torch.Tensor:
        return self.out(self.enc(history))


class RMABNavigator(Navigator):
    """RMA-B (blind): a latent from the proprioception history; the given terminus and
    middle waypoint are the navigation input. Nothing runs at depth rate."""

    uses_depth = False
    in_keys = (keys.GOAL, keys.PROPRIO_HISTORY)

    def __init__(self, dims: StudentDims) -> None:
        super().__init__()
        self.history = HistoryLatent(dims)

    def frame(self, obs, state, features=None):  # no encode(): features is None
        return torch.zeros(state.shape[0], 1, device=state.device), state

    def act(self, obs, held):
        return {"latent": self.history(obs[keys.PROPRIO_HISTORY]), "nav_goal": obs[keys.GOAL]}


class RMAHNavigator(Navigator):
    """RMA-H: vision predicts g1..g3 from the stacked frames and the goals; locomotion is
    RMA's (history latent) and follows g1 through a stop-gradient: the two halves are
    learned separately (goal loss for vision, imitation for locomotion)."""

    in_keys = (keys.DEPTH, keys.GOAL, keys.PROPRIO_HISTORY)
    nav_dim = 2

    def __init__(self, dims: StudentDims, num_goals: int = 3) -> None:
        super().__init__()
        frames, height, width = dims.require_depth("rma_h")
        self.num_goals = num_goals
        self.cnn = DepthCNN(frames, height, width)
        self.goals = mlp(128 + 4, [128, 2 * num_goals], None)
        self.history = HistoryLatent(dims)
        self.held_dim = 2 * num_goals

    def frame(self, obs, state, features=None):  # no encode(): features is None
        x = torch.cat([self.cnn(obs[keys.DEPTH]), obs[keys.GOAL]], dim=-1)
        return self.goals(x), state

    def act(self, obs, held):
        goals = held.unflatten(-1, (self.num_goals, 2))
        return {"latent": self.history(obs[keys.PROPRIO_HISTORY]), "near_goals": goals,
                "nav_goal": goals[..., 0, :].detach()}


STUDENTS = {"lego_h": LegoHNavigator, "ep_h": EPHNavigator, "rma_b": RMABNavigator,
            "rma_h": RMAHNavigator}


def make_navigator(name: str, dims: StudentDims, preset: str = "small", core: str = "gru",
                   history: bool = False) -> Navigator:
    """The navigation half of student ``name`` (one of :data:`STUDENTS`); ``history``: a
    history latent for locomotion too (LEGO-H only: RMA's students have theirs)."""
    if name not in STUDENTS:
        raise ValueError(f"unknown student {name!r}; choose one of {sorted(STUDENTS)}")
    if name == "lego_h":
        return LegoHNavigator(dims, preset, core, history)
    if history:
        raise ValueError(f"algo.history_latent=true applies to student 'lego_h' only, got "
                         f"algo.student={name!r}")
    return STUDENTS[name](dims)


class NavigationModule(TensorDictModuleBase):
    """Runs a :class:`Navigator` on a TensorDict step (batch (B,)), with latent tiling.

    Reads the navigator's observation keys, ``IS_INIT``, ``DEPTH_FRESH`` (when it uses
    depth), ``NAV_STATE`` and ``NAV_HELD``; writes ``STUDENT_LATENT``, ``NAV_GOAL``,
    ``NEAR_GOALS``, ``GOAL_CORRECTION`` and the new state under ``"next"``.
    """

    def __init__(self, navigator: Navigator) -> None:
        super().__init__()
        self.navigator = navigator
        # the precision of the depth-rate step (``Navigator.frame``): a trainer sets it to
        # its update's (``algo.update_precision``), so the student acts with the encoder
        # in the precision it learns in; outputs are held in float32 either way
        self.frame_precision: Callable[[], AbstractContextManager] = nullcontext
        extra = [keys.IS_INIT, keys.NAV_STATE, keys.NAV_HELD]
        if navigator.uses_depth:
            extra.append(keys.DEPTH_FRESH)
        self.in_keys = list(navigator.in_keys) + extra
        self.out_keys = [keys.STUDENT_LATENT, keys.NAV_GOAL, keys.NEAR_GOALS,
                         keys.GOAL_CORRECTION, ("next", *keys.NAV_STATE),
                         ("next", *keys.NAV_HELD)]
        if navigator.history_dim:
            self.out_keys.append(keys.HISTORY_LATENT)

    def state_spec(self, batch: tuple[int, ...] = ()) -> Composite:
        """The recurrent entries, for torchrl's ``TensorDictPrimer`` (zeros at reset)."""
        nav = self.navigator
        return Composite({
            keys.NAV_STATE: Unbounded(shape=(*batch, *nav.state_shape)),
            keys.NAV_HELD: Unbounded(shape=(*batch, nav.held_dim))}, shape=batch)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        nav = self.navigator
        obs = {k: td.get(k) for k in nav.in_keys}
        start = td.get(keys.IS_INIT).reshape(-1)
        fresh = start | td.get(keys.DEPTH_FRESH).reshape(-1) if nav.uses_depth else None
        held, state = self.advance(obs, td.get(keys.NAV_STATE), td.get(keys.NAV_HELD), start,
                                   fresh)
        for key, value in self.outputs(obs, held, held.shape[0]).items():
            td.set(key, value)
        td.set(("next", *keys.NAV_STATE), state)
        td.set(("next", *keys.NAV_HELD), held)
        return td

    def advance(self, obs: dict, state: torch.Tensor, held: torch.Tensor, start: torch.Tensor,
                fresh: torch.Tensor | None, features: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """One step of the recurrence on B rows: the state zeroed where an episode starts
        (``start`` (B,)), then ``Navigator.frame`` on the ``fresh`` rows (None: all) ->
        (held, state); ``features``: the rows' :meth:`Navigator.encode`, computed ahead."""
        nav = self.navigator
        state = state * (~start).view(-1, *[1] * len(nav.state_shape))
        if fresh is None or bool(fresh.all()):
            with self.frame_precision():
                new_held, new_state = nav.frame(obs, state, features)
            return new_held.to(held.dtype), new_state.to(state.dtype)
        if bool(fresh.any()):
            rows = fresh.nonzero().squeeze(-1)
            with self.frame_precision():
                new_held, new_state = nav.frame({k: v[rows] for k, v in obs.items()},
                                                state[rows],
                                                None if features is None else features[rows])
            held = held.index_copy(0, rows, new_held.to(held.dtype))
            state = state.index_copy(0, rows, new_state.to(state.dtype))
        return held, state

    def outputs(self, obs: dict, held: torch.Tensor, batch: int) -> dict:
        """The policy-rate outputs (``Navigator.act``) of ``batch`` rows under their keys."""
        out = self.navigator.act(obs, held)
        zeros = held.new_zeros
        outputs = {keys.STUDENT_LATENT: out["latent"], keys.NAV_GOAL: out["nav_goal"],
                   keys.NEAR_GOALS: out.get("near_goals", zeros(batch, 0, 2)),
                   keys.GOAL_CORRECTION: out.get("goal_correction", zeros(batch, 2))}
        if "history_latent" in out:
            outputs[keys.HISTORY_LATENT] = out["history_latent"]
        return outputs


def make_locomotion_actor(dims: StudentDims, nav_dim: int, action_dim: int,
                          action_bound: float, hidden: tuple[int, ...] = (512, 256, 128),
                          init_std: float = 0.5, min_std: float = 1e-4,
                          learn_std: bool = True, history_dim: int = 0) -> ProbabilisticActor:
    """The locomotion module: proprioception, z_uni and the navigation goal in (and the
    history latent, last, when ``history_dim``), a diagonal Normal over joint actions out
    (the oracle actor's MLP shape and distribution); its state-independent std starts at
    ``init_std`` and is a constant unless ``learn_std``.

    Reads ``PROPRIO`` (B, P), ``STUDENT_LATENT`` (B, 32), ``NAV_GOAL`` (B, nav_dim)
    [, ``HISTORY_LATENT`` (B, history_dim)]; writes ``LOC``/``SCALE`` (B, A), ``"action"``
    (B, A) and ``"sample_log_prob"`` (B,).
    """
    in_keys = [keys.PROPRIO, keys.STUDENT_LATENT, keys.NAV_GOAL]
    sizes = [dims.proprio, LATENT_DIM, nav_dim]
    if history_dim:
        in_keys.append(keys.HISTORY_LATENT)
        sizes.append(history_dim)
    body = ConcatMLP(sizes, [1] * len(sizes), hidden, action_dim, None)
    gaussian = GaussianPolicyHead(body, action_dim, action_bound, init_std, min_std)
    gaussian.std.requires_grad_(learn_std)
    head = TensorDictModule(gaussian, in_keys, [LOC, SCALE])
    return ProbabilisticActor(head, in_keys={"loc": LOC, "scale": SCALE}, out_keys=[keys.ACTION],
                              distribution_class=IndependentNormal,
                              distribution_kwargs={"tanh_loc": False}, return_log_prob=True,
                              log_prob_key=LOG_PROB)


@dataclass
class Student:
    """A student policy: navigation then locomotion, plus its sizes."""

    navigation: NavigationModule
    locomotion: ProbabilisticActor
    dims: StudentDims
    name: str

    @property
    def policy(self):
        """The acting policy (collector / benchmark): navigation then locomotion."""
        from tensordict.nn import TensorDictSequential

        return TensorDictSequential(self.navigation, self.locomotion)

    def modules(self) -> dict[str, nn.Module]:
        return {"navigation": self.navigation, "locomotion": self.locomotion}


def make_student(name: str, dims: StudentDims, action_dim: int, action_bound: float,
                 preset: str = "small", core: str = "gru", init_std: float = 0.5,
                 learn_std: bool = True, history_latent: bool = False) -> Student:
    """Student ``name`` (``lego_h``, ``ep_h``, ``rma_b``, ``rma_h``) for these input sizes;
    ``history_latent``: LEGO-H's locomotion reads a proprio-history latent too."""
    nav = make_navigator(name, dims, preset, core, history_latent)
    loco = make_locomotion_actor(dims, nav.nav_dim, action_dim, action_bound, init_std=init_std,
                                 learn_std=learn_std, history_dim=nav.history_dim)
    return Student(NavigationModule(nav), loco, dims, name)


def unroll(navigation: NavigationModule, batch: TensorDictBase) -> TensorDictBase:
    """Re-run the navigation module over a collected batch (N, T) with gradients, carrying
    its recurrent state through time from the state stored at t = 0 (truncated BPTT).

    The recurrence steps only through the times where some row has a fresh frame (or an
    episode starts); the held outputs are carried between them, and the policy-rate part
    (``Navigator.act``) runs once over all N x T rows. The same outputs as stepping the
    module through every t (``tests/test_students.py``), with a quarter of the Python steps
    at depth every 5 steps.

    Returns a TensorDict (N, T) with ``STUDENT_LATENT``, ``NAV_GOAL``, ``NEAR_GOALS`` and
    ``GOAL_CORRECTION``.
    """
    nav = navigation.navigator
    n, t = batch.shape[:2]
    obs = {k: batch.get(k) for k in nav.in_keys}
    start = batch.get(keys.IS_INIT).reshape(n, t)
    fresh = (start | batch.get(keys.DEPTH_FRESH).reshape(n, t)) if nav.uses_depth else None
    features = encode_fresh(nav, batch)
    state, held = batch.get(keys.NAV_STATE)[:, 0], batch.get(keys.NAV_HELD)[:, 0]
    helds = [held]
    latest = torch.zeros(t, dtype=torch.long)  # per t: which of ``helds`` is current
    active = range(t) if fresh is None else fresh.any(0).nonzero().squeeze(1).tolist()
    for step in active:
        held, state = navigation.advance(
            {k: v[:, step] for k, v in obs.items()}, state, held, start[:, step],
            None if fresh is None else fresh[:, step],
            None if features is None else features[:, step])
        helds.append(held)
        latest[step:] = len(helds) - 1
    held = torch.stack(helds, 1)[:, latest.to(held.device)].flatten(0, 1)  # (N T, H)
    out = navigation.outputs({k: v.flatten(0, 1) for k, v in obs.items()}, held, n * t)
    return TensorDict({k: v.unflatten(0, (n, t)) for k, v in out.items()}, batch_size=[n, t])


def encode_fresh(nav: Navigator, batch: TensorDictBase) -> torch.Tensor | None:
    """(N, T, F): ``nav.encode`` of every fresh frame of the batch (a new depth frame or an
    episode's first step), in one call; zeros elsewhere (never read). None when the
    navigator has no state-free part or sees no depth."""
    if not nav.uses_depth:
        return None
    n, t = batch.shape[:2]
    fresh = (batch.get(keys.IS_INIT) | batch.get(keys.DEPTH_FRESH)).reshape(n, t)
    idx = fresh.nonzero(as_tuple=True)
    features = nav.encode({k: batch.get(k)[idx] for k in nav.in_keys})
    if features is None:
        return None
    return features.new_zeros(n, t, features.shape[-1]).index_put(idx, features)
