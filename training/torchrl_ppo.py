"""Multi-agent PPO (MAPPO / IPPO) with TorchRL on the batched TorchRL env.

The training loop of TorchRL's multi-agent PPO recipe (written for VMAS), on
:class:`~marine_formation_env.torchrl.MarineFormationTorchEnv`: a collector
steps ``num_envs`` formations at once, one policy network shared by every
vessel (a ``MultiAgentMLP`` with shared parameters, tanh-squashed Gaussian
actions in [−1, 1]), a critic that sees every vessel's observation (MAPPO) or
only its own (IPPO), GAE that bootstraps at the time limit (truncation) and
not at a collision or a workspace exit (termination), clipped PPO updates::

    python -m training.torchrl_ppo --config training/configs/torchrl/paper_speed_mappo.yaml --seed 0 \\
        --out runs/torchrl_paper_speed
    python -m training.torchrl_ppo --config training/configs/torchrl/paper_speed_mappo.yaml \\
        --set minutes=2 --set env_kwargs.topology=chain --out runs/try --overwrite

The config file holds one mapping under ``MarineFormation-v1``, like the SB3
configs of ``training.train`` (the same ``--set KEY=VALUE`` grammar, dots
nest; unknown keys and bad values are refused by name):

| key | meaning | default |
|---|---|---|
| ``algo`` | ``mappo`` (centralized critic) or ``ippo`` | ``mappo`` |
| ``scenario``, ``env_kwargs`` | the scenario and its overrides, as for ``parallel_env`` | ``paper``, ``{}`` |
| ``num_envs`` | formations stepped together | 64 |
| ``frames_per_batch`` | formation-steps per iteration (vessel-steps = × n) | 6400 |
| ``total_frames`` | formation-steps of the run | 1.0e6 |
| ``minutes`` | wall-clock limit of the run (stops after the iteration that passes it), or null | null |
| ``hidden`` | hidden layer sizes of the policy and the critic | ``[64, 64]`` |
| ``distribution`` | ``tanh_normal`` (TorchRL's recipe) or ``normal`` (SB3's; the env clips) | ``tanh_normal`` |
| ``initial_scale`` | the Gaussian's standard deviation where the network's scale output is 0 (at the start) | 1.0 |
| ``scale`` | ``state_dependent`` (a network output) or ``state_independent`` (learned, SB3's) | ``state_dependent`` |
| ``action_head_gain`` | scale the last layer's initial weights by this and zero its bias (SB3: 0.01), or null | null |
| ``action_scale`` | the env gets this × the policy's sample (one per action entry, or one for all; below) | 1.0 |
| ``lr``, ``max_grad_norm`` | Adam learning rate, gradient clipping | 3e-4, 1.0 |
| ``lr_schedule`` | ``constant``, or ``linear``: the rate falls linearly to 0 over the run's budget | ``constant`` |
| ``target_kl`` | stop an iteration's epochs once a minibatch's approximate KL exceeds 1.5 × this, or null | null |
| ``gamma``, ``lmbda`` | discount, GAE λ | 0.99, 0.95 |
| ``clip_epsilon``, ``entropy_coef`` | PPO clip range, entropy bonus | 0.2, 1e-4 |
| ``epochs``, ``minibatch_size`` | passes over each batch, formation-steps per minibatch | 4, 1600 |
| ``inputs`` | ``raw``, or ``predicted``: the networks read the slot network's fixed input map (below) | ``raw`` |
| ``drop_inputs`` | observation entries the policy does not read (names; below) | ``[]`` |
| ``normalize_observations``, ``normalize_advantage``, ``normalize_reward`` | see below | false |
| ``train_reward`` | reward weights and scales (fields of ``RewardConfig``) that only the training env uses | ``{}`` |
| ``initial_state_curriculum`` | ``{start: s₀, until: f}``: the training env's initial errors grow (below) | null |
| ``train_dt`` | the learner's control period [s] (below), or null: the scenario's ``dt`` | null |
| ``eval_episodes`` | evaluation episodes at the end (seeds 10 000 +), against the reference | 4 |
| ``threads`` | torch's intra-op threads (null: torch's default), as ``training.train --threads`` | 1 |

``distribution: tanh_normal`` squashes a Gaussian with tanh, as TorchRL's
multi-agent PPO recipe does; its log-probability of an action rounded to
±1 in float32 is far from the one it was sampled with, which showed as an
approximate KL of 1–5 per iteration even with the learning rate at 0.
``normal`` is SB3's choice: an unbounded Gaussian whose samples the env
clips to [−1, 1] (the env clips every action), with exact log-probabilities;
the deterministic action is then the mean clipped to [−1, 1].

``action_scale`` rescales the policy's action space, on the learner's side:
the network's Gaussian (mean and deviation, and ``initial_scale`` with them)
is over ``z`` and the env receives ``action_scale × z`` (per action entry).
The env, its action space and the evaluation are unchanged, and no action is
out of reach (the Gaussian is unbounded; the env clips at ±1 as always): a
network output of 1 now commands ``action_scale`` of the actuator's range.
It is for levels whose useful actions are a small part of the range: at
``force`` the reference's yaw accelerations stay below 0.0004 of the limit
after the first minute (docs/training.md), while an unscaled network's means
of about ±0.01 after its first minute of training were enough to spin
vessels out of the workspace within a minute.

The three normalizations are SB3's (``VecNormalize`` and PPO's advantage
standardization), done on the learner's side: ``normalize_observations``
puts a running mean and variance (one per observation entry, pooled over
every vessel, updated after each batch's epochs, saved with the policy) in
front of the actor and the critic; ``normalize_advantage`` standardizes the
advantages of each minibatch; ``normalize_reward`` divides the rewards the
critic and the advantages see by the running standard deviation of the
discounted return (clipped to ±10). The env's reward, the logged
``mean_reward`` and the evaluation are unchanged.

``inputs: predicted`` puts the slot network's fixed input map
(:mod:`training.inputs`, parameter-free) in front of the actor and the critic:
each slot's Δθ is predicted to now from the message's velocity and age,
``Δθ − ẋ_i·age`` (what ``reference:extrapolate`` does; the same Δθ over an
ideal link), the lane offset D_y is read as κ·D_y, and every entry is
divided by a fixed scale (metres by 50, speeds by 5, ages by 10 s, …). Over
acoustic links a slot holds a position up to 12 s old next to its age in
seconds; an MLP on the raw entries would have to find the product of two of
its inputs by itself. It replaces ``normalize_observations`` (both together
are refused). The saved policy and its numpy export
(``baselines.pretrained.MLPPolicy`` with ``inputs="predicted"``) apply the
same map.

``drop_inputs`` (names of ``OWN_FEATURES`` and ``SLOT_FEATURES``, the
latter dropped from every slot) zeroes those entries of the actor's input
(:class:`training.inputs.InputMask`, before the running norm); the critic
still reads everything. ``[lane_offset, linked, age]`` makes a vessel's
command a function of its errors and the speed profile alone: where every
error is zero, every vessel commands the same whoever it hears and whatever
its lane, as the paper's law does (a vessel that hears no one is a vessel
whose neighbours agree). An MLP that reads the link bits and the lane offset
can learn a different command at zero error for each vessel, which the
formation then holds as steady coordination and cross-track offsets
(docs/results.md, ``paper_force``). On lossy links the link bit and the age
say how fresh a slot is; on a curved path the lane offset sets each lane's
speed: drop them only where those do not matter. The saved policy and its
numpy export (``baselines.pretrained.MLPPolicy``'s ``input_mask``) apply
the same mask.

``train_reward`` shapes the reward the learner trains on, nothing else: the
training env's reward is the scenario's with these fields replaced (for
example ``{sigma_cross_track: 5.0, sigma_coordination: 5.0}``, so that an
error of a metre costs more than the benchmark's 20 m scales make it cost),
while ``env_kwargs``, the closing evaluation, ``baselines.evaluate`` and the
learned baselines keep the benchmark's reward. ``progress.csv``'s
``mean_reward`` and ``episode_return`` are then in the shaped reward, not
comparable with the reference's return.

``initial_state_curriculum`` is a curriculum over the initial state, in the
learner's env only: before each iteration the training env draws its
restarts ``s₀ + (1 − s₀) · min(1, used / f)`` of the way from the formation
on its lanes (every initial error zero) to the scenario's initial state, its
noise scaled alike (``MarineFormationTorchEnv.set_initial_spread``), where
``used`` is the fraction of the budget spent (below). With ``{start: 0.1,
until: 0.5}`` the formations start with a tenth of the scenario's errors at
first and with all of them from half the budget on. The evaluation always
uses the scenario's. ``progress.csv`` logs the spread.

``train_dt`` lets the learner decide less often than the scenario's control
period: its env holds each action for ``train_dt`` seconds (``dt`` of the
training env only; its RK4 substeps are ``env_kwargs``' ``substeps`` if set,
else ``ceil(train_dt / 0.1 s)``), so an
episode is ``horizon / train_dt`` decisions and ``gamma``, ``lmbda`` count per
``train_dt``. The policy is a memoryless feedback of the observation, so the
evaluation, ``baselines.evaluate`` and the export run it at the scenario's own
``dt``, as every other policy. The reward is per second (``−dt·Σ w·c``), so
returns stay comparable.

With ``lr_schedule: linear`` the budget is whichever of ``minutes`` and
``total_frames`` runs out first: before each iteration the rate is
``lr · (1 − max(seconds / (60 · minutes), frames / total_frames))``, as SB3's linear
schedule over ``progress_remaining``, with wall time counted because the
benchmarks give a run minutes, not frames. ``target_kl`` is SB3's early
stopping: before each minibatch's step, the magnitude of its mean of
TorchRL's ``kl_approx`` diagnostic (log π_old − log π_new, an estimator that
can come out below 0 on one minibatch, unlike SB3's) is compared with 1.5 ×
``target_kl``; once it is above, that minibatch and the iteration's
remaining epochs are skipped. Both are there because the constant-rate policy gets worse after about
20 M vessel-steps (docs/results.md, "Over training seeds").

The run folder gets ``config.yaml`` (resolved, with the seed), ``policy.pt``
(the policy network's weights and what is needed to rebuild it),
``progress.csv`` (per iteration: frames, vessel-steps, seconds, the mean
training reward per vessel-step, the mean return per vessel of the training
episodes that ended in the batch and their number (counted per vessel), the
learning rate, the last approximate KL, the number of minibatch updates and the training env's
initial-state spread for the next iteration) and
``evaluation.json`` (the learned policy's and the reference's mean return over the same seeds). Every file is
written atomically; ``policy.pt`` and ``progress.csv`` are also written once a
minute during training (:data:`SAVE_SECONDS`), so a long run can be watched and
an interrupted one keeps its last minute's policy.
``python -m baselines.evaluate --policy RUN_FOLDER`` evaluates the policy next
to the reference.
"""

from __future__ import annotations

import inspect
import io
import json
import pickle
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from marine_formation_env.atomic import atomic_write_bytes
from marine_formation_env.cli import ArgumentParser, report_error
from training.config import (
    TrainConfigError,
    _fraction,
    _hidden,
    _non_negative,
    _positive,
    _whole,
    add_run_arguments,
    budget_fraction,
    check_curriculum,
    check_renamed,
    check_train_reward,
    config_from_arguments,
    curriculum_spread,
    parse_schedule,
    training_env_kwargs,
)
from training.run_folder import PROGRESS_FILE, read_config, write_config, write_progress

__all__ = [
    "DEFAULTS",
    "EpisodeReturns",
    "RewardScaler",
    "TorchPolicy",
    "learning_rate",
    "load_torch_policy",
    "load_torchrl_run",
    "make_collector",
    "resolve",
    "running_norm",
    "train",
    "training_env_kwargs",
]

#: Every key a config may hold, with its default.
DEFAULTS: dict[str, Any] = {
    "algo": "mappo",
    "scenario": "paper",
    "env_kwargs": {},
    "n_envs": 64,
    "frames_per_batch": 6400,
    "total_frames": 1_000_000,
    "minutes": None,
    "hidden": [64, 64],
    "distribution": "tanh_normal",
    "initial_scale": 1.0,
    "scale": "state_dependent",
    "action_head_gain": None,
    "action_scale": 1.0,
    "learning_rate": 3e-4,
    "target_kl": None,
    "max_grad_norm": 1.0,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 1e-4,
    "n_epochs": 4,
    "minibatch_size": 1600,
    "inputs": "raw",
    "drop_inputs": [],
    "normalize_observations": False,
    "normalize_advantage": False,
    "normalize_reward": False,
    "train_reward": {},
    "initial_state_curriculum": None,
    "train_dt": None,
    "eval_episodes": 4,
    "threads": 1,
}

ALGOS = ("mappo", "ippo")
DISTRIBUTIONS = ("tanh_normal", "normal")
SCALES = ("state_dependent", "state_independent")
INPUTS = ("raw", "predicted")
POLICY_FILE = "policy.pt"
#: The trainer's own columns of ``progress.csv``, after :data:`training.run_folder.PROGRESS_COLUMNS`.
PROGRESS_OWN_COLUMNS = ("frames", "mean_reward", "learning_rate", "kl", "updates", "initial_spread")
#: Seconds of training between the intermediate saves of ``policy.pt`` and ``progress.csv``.
SAVE_SECONDS = 60.0


def resolve(raw: dict[str, Any], seed: int) -> dict[str, Any]:
    """The config with defaults filled in and every value checked (``TrainConfigError`` names the bad one)."""
    check_renamed(raw)
    unknown = sorted(set(raw) - set(DEFAULTS) - {"seed"})
    if unknown:
        raise TrainConfigError(f"unknown key(s) {unknown}; valid keys: {sorted(DEFAULTS)}")
    cfg = {**DEFAULTS, **{k: v for k, v in raw.items() if k != "seed"}, "seed": seed}
    if cfg["algo"] not in ALGOS:
        raise TrainConfigError(f"algo must be one of {list(ALGOS)}, got {cfg['algo']!r}")
    if not isinstance(cfg["env_kwargs"], dict):
        raise TrainConfigError(f"env_kwargs must be a mapping, got {cfg['env_kwargs']!r}")
    for key in ("n_envs", "frames_per_batch", "total_frames", "n_epochs", "minibatch_size", "eval_episodes"):
        cfg[key] = _whole(key, cfg[key], 1)
    if isinstance(cfg["learning_rate"], str):  # lin_<rate>: SB3's (rl-zoo's) linear schedule
        parse_schedule(cfg["learning_rate"])
    else:
        cfg["learning_rate"] = _positive("learning_rate", cfg["learning_rate"])
    for key in ("max_grad_norm", "clip_range", "initial_scale"):
        cfg[key] = _positive(key, cfg[key])
    for key in ("gamma", "gae_lambda"):
        cfg[key] = _fraction(key, cfg[key])
    cfg["ent_coef"] = _non_negative("ent_coef", cfg["ent_coef"])
    for key in ("normalize_observations", "normalize_advantage", "normalize_reward"):
        if not isinstance(cfg[key], bool):
            raise TrainConfigError(f"{key} must be true or false, got {cfg[key]!r}")
    if cfg["minutes"] is not None:
        cfg["minutes"] = _positive("minutes", cfg["minutes"])
    if cfg["inputs"] not in INPUTS:
        raise TrainConfigError(f"inputs must be one of {list(INPUTS)}, got {cfg['inputs']!r}")
    if cfg["inputs"] == "predicted" and cfg["normalize_observations"]:
        raise TrainConfigError(
            "inputs: predicted divides by fixed scales; normalize_observations: true would normalize again"
            " (set one of them)"
        )
    cfg["drop_inputs"] = _dropped(cfg["drop_inputs"])
    if cfg["drop_inputs"] and cfg["inputs"] == "predicted":
        raise TrainConfigError("drop_inputs applies to raw inputs; inputs: predicted maps them first (set one of them)")
    if cfg["scale"] not in SCALES:
        raise TrainConfigError(f"scale must be one of {list(SCALES)}, got {cfg['scale']!r}")
    if cfg["distribution"] not in DISTRIBUTIONS:
        raise TrainConfigError(f"distribution must be one of {list(DISTRIBUTIONS)}, got {cfg['distribution']!r}")
    if cfg["target_kl"] is not None:
        cfg["target_kl"] = _positive("target_kl", cfg["target_kl"])
    if cfg["threads"] is not None:
        cfg["threads"] = _whole("threads", cfg["threads"], 1)
    if cfg["action_head_gain"] is not None:
        cfg["action_head_gain"] = _positive("action_head_gain", cfg["action_head_gain"])
    cfg["hidden"] = _hidden(cfg["hidden"])
    if cfg["frames_per_batch"] % cfg["n_envs"]:
        raise TrainConfigError(
            f"frames_per_batch = {cfg['frames_per_batch']} must be a multiple of n_envs = {cfg['n_envs']}"
        )
    if cfg["minibatch_size"] > cfg["frames_per_batch"]:
        raise TrainConfigError(
            f"minibatch_size = {cfg['minibatch_size']} exceeds frames_per_batch = {cfg['frames_per_batch']}"
        )
    from marine_formation_env.scenarios import make_config

    try:
        scenario = make_config(cfg["scenario"], **cfg["env_kwargs"])
    except (ValueError, TypeError) as err:
        raise TrainConfigError(f"scenario {cfg['scenario']!r} with env_kwargs {cfg['env_kwargs']}: {err}") from err
    cfg["action_scale"] = _action_scale(cfg["action_scale"], scenario.action_dim)
    if np.any(np.asarray(cfg["action_scale"]) != 1.0) and cfg["distribution"] != "normal":
        raise TrainConfigError(
            f"action_scale {cfg['action_scale']!r} needs distribution: normal (tanh_normal squashes before it scales)"
        )
    check_train_reward(cfg)
    cfg["initial_state_curriculum"] = check_curriculum(cfg["initial_state_curriculum"])
    if cfg["train_dt"] is not None:
        cfg["train_dt"] = _positive("train_dt", cfg["train_dt"])
        try:
            make_config(cfg["scenario"], **learner_env_kwargs(cfg))
        except (ValueError, TypeError) as err:
            raise TrainConfigError(f"train_dt = {cfg['train_dt']!r}: {err}") from err
    return cfg


def learner_env_kwargs(cfg: dict[str, Any]) -> dict[str, Any]:
    """The learner's env overrides: ``training_env_kwargs`` (``train_reward``) and ``train_dt`` as its ``dt``."""
    kwargs = training_env_kwargs(cfg)
    if cfg["train_dt"] is not None:
        kwargs["dt"] = cfg["train_dt"]
    return kwargs


def _dropped(value: Any) -> list[str]:
    """``drop_inputs`` checked: a list of distinct names of observation entries."""
    from training.inputs import DROPPABLE

    if not isinstance(value, list) or not all(isinstance(name, str) for name in value):
        raise TrainConfigError(f"drop_inputs must be a list of observation entry names, got {value!r}")
    unknown = [name for name in value if name not in DROPPABLE]
    if unknown or len(set(value)) != len(value):
        raise TrainConfigError(
            f"drop_inputs must name distinct entries of {list(DROPPABLE)}, got {value!r}"
            + (f" (unknown: {unknown})" if unknown else " (repeated)")
        )
    return value


def _action_scale(value: Any, size: int) -> float | list[float]:
    """``action_scale``: one number in (0, 1] or a list of ``size`` of them, one per action entry."""

    def entry(x: Any) -> float:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not 0.0 < float(x) <= 1.0:
            raise TrainConfigError(f"action_scale entries must be numbers in (0, 1], got {value!r}")
        return float(x)

    if not isinstance(value, list):
        return entry(value)
    if len(value) != size:
        raise TrainConfigError(f"action_scale has {len(value)} entries, the action has {size}: got {value!r}")
    return [entry(x) for x in value]


# ----------------------------------------------------------------------------- networks


def running_norm(dim: int) -> Any:
    """A module ``x ↦ clip((x − mean) / sqrt(var + 1e-8), ±10)`` whose statistics are buffers.

    The statistics are pooled over every leading dimension (formations, time,
    vessels): one mean and variance per observation entry, the same for every
    vessel, so the shared weights still take any team size. They change only
    through :meth:`update` (parallel-variance merge of a batch, as SB3's
    ``RunningMeanStd``), never in ``forward``: the trainer updates them after
    the PPO epochs on a batch, so a batch is trained with the statistics it
    was collected with. They are saved in the module's ``state_dict``.
    """
    import torch
    from torch import nn

    class _RunningNorm(nn.Module):
        mean: torch.Tensor
        var: torch.Tensor
        count: torch.Tensor

        def __init__(self) -> None:
            super().__init__()
            self.register_buffer("mean", torch.zeros(dim))
            self.register_buffer("var", torch.ones(dim))
            self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return ((x - self.mean) / torch.sqrt(self.var + 1e-8)).clamp(-10.0, 10.0)

        @torch.no_grad()
        def update(self, x: torch.Tensor) -> None:
            flat = x.reshape(-1, dim).double()
            n_new = flat.shape[0]
            mean_new, var_new = flat.mean(0), flat.var(0, unbiased=False)
            total = self.count + n_new
            delta = mean_new - self.mean.double()
            mean = self.mean.double() + delta * (n_new / total)
            m2 = self.var.double() * self.count + var_new * n_new + delta**2 * (self.count * n_new / total)
            self.mean.copy_(mean.float())
            self.var.copy_((m2 / total).float())
            self.count.copy_(total)

    return _RunningNorm()


class RewardScaler:
    """Learner-side reward scaling, as SB3's ``VecNormalize`` does it (``norm_reward``).

    Each (formation, vessel) stream keeps a discounted return
    ``G ← γ·G + r`` (reset to 0 after the formation's episode ends, by
    termination or truncation); the running variance of every ``G`` seen
    (:func:`running_norm`'s statistics, one entry) scales the rewards:
    ``r / sqrt(var + 1e-8)`` clipped to ±10. Only what the critic and the
    advantages see changes; the env's reward does not. The streams carry on
    across batches because the collector does not reset the formations
    between batches.
    """

    def __init__(self, gamma: float) -> None:
        self.gamma = gamma
        self.stats = running_norm(1)
        self.returns: Any = None

    def __call__(self, reward: Any, done: Any) -> Any:
        """Scaled ``reward`` (``[B, T, n, 1]``); ``done`` is the formation's flag after each step, ``[B, T, 1]``."""
        import torch

        with torch.no_grad():
            if self.returns is None:
                self.returns = torch.zeros_like(reward[:, 0], dtype=torch.float64)
            seen = torch.empty_like(reward, dtype=torch.float64)
            for t in range(reward.shape[1]):
                self.returns = self.gamma * self.returns + reward[:, t]
                seen[:, t] = self.returns
                self.returns = self.returns * (~done[:, t]).unsqueeze(-1)
            self.stats.update(seen)
            return (reward / torch.sqrt(self.stats.var + 1e-8)).clamp(-10.0, 10.0)


class EpisodeReturns:
    """The returns of the training episodes that end in each batch (the learning curve of ``progress.csv``).

    Each (formation, vessel) stream sums the env's raw reward; when the
    formation's episode ends (termination or truncation) the sums of its
    vessels are recorded and reset. The streams carry on across batches, as
    the collector's formations do.
    """

    def __init__(self) -> None:
        self.sums: Any = None

    def __call__(self, reward: Any, done: Any) -> list[float]:
        """Per-vessel returns of the episodes ending in this batch (``reward`` [B, T, n, 1], ``done`` [B, T, 1])."""
        import torch

        with torch.no_grad():
            reward = reward[..., 0].double()
            if self.sums is None:
                self.sums = torch.zeros_like(reward[:, 0])
            ended: list[float] = []
            for t in range(reward.shape[1]):
                self.sums += reward[:, t]
                flags = done[:, t, 0]
                if bool(flags.any()):
                    ended.extend(self.sums[flags].flatten().tolist())
                    self.sums[flags] = 0.0
            return ended


def _policy_network(
    obs_dim: int,
    action_dim: int,
    n_agents: int,
    hidden: list[int],
    normalize: bool = False,
    distribution: str = "tanh_normal",
    initial_scale: float = 1.0,
    action_head_gain: float | None = None,
    scale: str = "state_dependent",
    action_scale: float | Sequence[float] = 1.0,
    inputs: str = "raw",
    dropped: Sequence[str] = (),
) -> Any:
    """The shared actor: [input mask →] [input map or running norm →] ``MultiAgentMLP`` (shared) → loc, scale → the
    distribution.

    The scale is a biased softplus of the network's output, equal to ``initial_scale`` where that output is 0
    (TorchRL's ``biased_softplus``), so a freshly initialized policy explores with about that deviation.
    With ``action_head_gain`` the MLP's last layer starts with its weights scaled by it and a zero bias, so the
    first actions' means are near 0 and their deviations near ``initial_scale`` (SB3 initializes its action
    layer with gain 0.01; TorchRL's default leaves means of about ±0.1 and more on unscaled observations).
    With ``scale="state_independent"`` the network outputs the means only and the deviation is one learned
    parameter per action entry, ``exp`` of a log-deviation that starts at ``log(initial_scale)`` (SB3's Gaussian,
    TensorDict's ``AddStateIndependentNormalScale``).
    With ``action_scale`` ≠ 1 a fixed last module multiplies loc and scale by it (per action entry):
    the Gaussian over the network's units becomes one over the env's (module docstring).
    With ``inputs="predicted"`` the network reads :class:`training.inputs.PredictedInputs` of the observation;
    with ``normalize`` its running norm (:func:`running_norm`); with ``dropped``
    an :class:`training.inputs.InputMask` of those entries first.
    """
    import math

    import torch
    from tensordict.nn import AddStateIndependentNormalScale, NormalParamExtractor, TensorDictModule
    from torch import nn
    from torchrl.modules import IndependentNormal, MultiAgentMLP, ProbabilisticActor, TanhNormal

    units = _scale_vector(action_scale, action_dim)
    rescaled = not np.all(units == 1.0)
    if rescaled and distribution != "normal":
        raise ValueError(f"action_scale {action_scale!r} needs distribution 'normal' (tanh squashes before scaling)")
    if dropped:
        from training.inputs import InputMask
    net = nn.Sequential(
        *([InputMask(obs_dim, dropped)] if dropped else []),
        *_input_modules(obs_dim, normalize, inputs),
        MultiAgentMLP(
            n_agent_inputs=obs_dim,
            n_agent_outputs=action_dim if scale == "state_independent" else 2 * action_dim,
            n_agents=n_agents,
            centralized=False,
            share_params=True,
            num_cells=hidden,
            activation_class=nn.Tanh,
        ),
        (
            AddStateIndependentNormalScale(action_dim, scale_mapping="exp", init_value=math.log(initial_scale))
            if scale == "state_independent"
            else NormalParamExtractor(scale_mapping=f"biased_softplus_{initial_scale}")
        ),
        *([_action_units(units)] if rescaled else []),
    )
    if action_head_gain is not None:
        *_, weight, bias = _shared_trunk_of(net)[-1].parameters()  # the MultiAgentMLP's output layer
        with torch.no_grad():
            weight.mul_(action_head_gain)
            bias.zero_()
    module = TensorDictModule(
        net, in_keys=[("vessel", "observation")], out_keys=[("vessel", "loc"), ("vessel", "scale")]
    )
    if distribution == "normal":  # SB3's: unbounded samples, the env clips them
        kind: dict[str, Any] = {"distribution_class": IndependentNormal}
    else:
        kind = {
            "distribution_class": TanhNormal,
            "distribution_kwargs": {"low": torch.tensor(-1.0), "high": torch.tensor(1.0)},
        }
    return ProbabilisticActor(
        module,
        in_keys=[("vessel", "loc"), ("vessel", "scale")],
        out_keys=[("vessel", "action")],
        return_log_prob=True,
        **kind,
    )


def _scale_vector(action_scale: float | Sequence[float], action_dim: int) -> np.ndarray:
    """``action_scale`` as ``(action_dim,)`` float32 (one number: the same for every entry)."""
    return np.broadcast_to(np.asarray(action_scale, dtype=np.float32), (action_dim,)).copy()


def _action_units(units: np.ndarray) -> Any:
    """The module ``(loc, scale) ↦ (k·loc, k·scale)`` with the fixed ``k = units`` (a buffer, not learned)."""
    import torch
    from torch import nn

    class ActionUnits(nn.Module):
        k: torch.Tensor

        def __init__(self) -> None:
            super().__init__()
            self.register_buffer("k", torch.as_tensor(units))

        def forward(self, pair: tuple[torch.Tensor, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
            loc, scale = pair
            return loc * self.k, scale * self.k

    return ActionUnits()


def _input_modules(obs_dim: int, normalize: bool, inputs: str) -> list[Any]:
    """What a network puts before its MLP: the running norm, the fixed input map
    (``inputs: predicted``), or nothing."""
    if inputs == "predicted":
        from training.inputs import PredictedInputs

        return [PredictedInputs()]
    return [running_norm(obs_dim)] if normalize else []


def _critic_network(
    obs_dim: int,
    n_agents: int,
    hidden: list[int],
    centralized: bool,
    normalize: bool,
    inputs: str = "raw",
) -> Any:
    from tensordict.nn import TensorDictModule
    from torch import nn
    from torchrl.modules import MultiAgentMLP

    net = nn.Sequential(
        *_input_modules(obs_dim, normalize, inputs),
        MultiAgentMLP(
            n_agent_inputs=obs_dim,
            n_agent_outputs=1,
            n_agents=n_agents,
            centralized=centralized,
            share_params=True,
            num_cells=hidden,
            activation_class=nn.Tanh,
        ),
    )
    return TensorDictModule(net, in_keys=[("vessel", "observation")], out_keys=[("vessel", "state_value")])


class TorchPolicy:
    """A trained TorchRL policy as a batch policy (``baselines``): deterministic, the squashed mean.

    ``act_batch((..., dim)) -> (..., A)``: every vessel acts from its own
    observation with the shared weights, so the number of formations and
    vessels in the batch is free.

    Attributes:
        observation_dim, action_dim: the sizes it was trained with.
    """

    def __init__(
        self,
        actor: Any,
        observation_dim: int,
        action_dim: int,
        distribution: str = "tanh_normal",
        action_scale: float | Sequence[float] = 1.0,
    ) -> None:
        self.actor = actor
        self.trunk = _shared_trunk(actor)
        self.observation_dim = observation_dim
        self.action_dim = action_dim
        self.distribution = distribution
        #: ``(action_dim,)``: the env's action per unit of the network's mean (``action_scale``)
        self.action_scale = _scale_vector(action_scale, action_dim)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        import torch

        # every vessel is one batch entry of a one-agent MLP (the weights are shared: any team size)
        flat = torch.as_tensor(np.asarray(obs, dtype=np.float32).reshape(-1, 1, obs.shape[-1]))
        with torch.no_grad():
            # the means are the first A outputs (then the scale's, unless the scale is state-independent)
            loc = self.trunk(flat)[..., : self.action_dim] * torch.as_tensor(self.action_scale)
        action = torch.tanh(loc) if self.distribution == "tanh_normal" else loc.clamp(-1.0, 1.0)
        return np.asarray(action.numpy(), dtype=np.float32).reshape(*obs.shape[:-1], self.action_dim)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The PettingZoo-dict form of :meth:`act_batch`."""
        agents = list(observations)
        actions = self.act_batch(np.stack([observations[a] for a in agents]))
        return dict(zip(agents, actions, strict=True))


def load_torch_policy(folder: str | Path) -> tuple[TorchPolicy, dict[str, Any]]:
    """The policy of a ``training.torchrl_ppo`` run folder and the run's resolved config.

    Raises:
        FileNotFoundError: no ``policy.pt`` in the folder.
        ValueError: the file is not a readable policy of this trainer.
    """
    import torch

    path = Path(folder) / POLICY_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist (not a training.torchrl_ppo run folder)")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
        dims = saved["dims"]
        # the shared MLP takes any number of agents: build it for one, each vessel is a batch entry
        hidden = [int(h) for h in saved["hidden"]]
        normalize = bool(saved.get("normalize_observations", False))
        distribution = str(saved.get("distribution", "tanh_normal"))
        config = json.loads(saved["config"])
        # runs saved before these keys trained with their defaults
        initial, kind = float(config.get("initial_scale", 1.0)), str(config.get("scale", "state_dependent"))
        units, inputs = config.get("action_scale", 1.0), str(config.get("inputs", "raw"))
        sizes, dropped = (int(dims["observation"]), int(dims["action"])), list(config.get("drop_inputs", []))
        actor = _policy_network(
            *sizes, 1, hidden, normalize, distribution, initial, None, kind, units, inputs, dropped=dropped
        )
        actor.load_state_dict(saved["actor"])
    except (KeyError, RuntimeError, ValueError, TypeError, EOFError, pickle.UnpicklingError) as err:
        raise ValueError(f"cannot load the policy {str(path)!r}: {type(err).__name__}: {err}") from err
    return TorchPolicy(actor, int(dims["observation"]), int(dims["action"]), distribution, units), config


def load_torchrl_run(run: Path, deterministic: bool = True) -> tuple[TorchPolicy, dict[str, Any]]:
    """The policy of a ``training.torchrl_ppo`` run folder and the run's ``config.yaml``.

    The loader of the ``torchrl`` entry point of ``marine_formation_env.trainers``. The policy acts
    deterministically (the Gaussian's mean, squashed or clipped as in training).

    Raises:
        ValueError: ``deterministic`` is false, or ``policy.pt`` is not a readable policy of this trainer.
    """
    if not deterministic:
        raise ValueError(f"the policy of the TorchRL run {str(run)!r} acts deterministically only")
    policy, _ = load_torch_policy(run)
    return policy, read_config(run)


def _update_norm(net: Any, observations: Any) -> None:
    """Merge a batch into the running norm of a network's ``nn.Sequential``, as the modules before it (an input
    mask) hand it on."""
    import torch

    seen = observations
    with torch.no_grad():
        for module in net:
            if hasattr(module, "update"):
                module.update(seen)
                return
            seen = module(seen)
    raise ValueError(f"no running norm in {[type(module).__name__ for module in net]}")


def _shared_trunk(actor: Any) -> Any:
    """The observation → network-output part of an actor built by :func:`_policy_network`: its input mask and
    running norm (each if any) and its ``MultiAgentMLP``, without the ``NormalParamExtractor`` (and the action
    units, if any)."""
    return _shared_trunk_of(actor.module[0].module)


def _shared_trunk_of(net: Any) -> Any:
    """The modules of :func:`_policy_network`'s ``nn.Sequential`` up to and including its ``MultiAgentMLP``."""
    from torchrl.modules import MultiAgentMLP

    found = [k for k, module in enumerate(net) if isinstance(module, MultiAgentMLP)]
    if len(found) != 1:
        kinds = [type(module).__name__ for module in net]
        raise ValueError(f"not an actor of training.torchrl_ppo: expected one MultiAgentMLP, found {kinds}")
    return net[: found[0] + 1]


# ----------------------------------------------------------------------------- training


def train(cfg: dict[str, Any], out: Path, progress: bool = True) -> dict[str, Any]:
    """Train with the resolved ``cfg`` into ``out``; returns the evaluation summary (also in ``evaluation.json``)."""
    import torch
    from tensordict.nn import set_composite_lp_aggregate
    from torchrl.data import LazyTensorStorage, ReplayBuffer
    from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
    from torchrl.objectives import ClipPPOLoss, ValueEstimators

    from marine_formation_env.torchrl import MarineFormationTorchEnv

    set_composite_lp_aggregate(False).set()
    if cfg["threads"] is not None:
        # one thread by default, as training.train: on the shared 2-core machine, with other processes running,
        # two intra-op threads made an iteration several times slower (docs/results.md, training throughput)
        torch.set_num_threads(cfg["threads"])
    seed = cfg["seed"]
    torch.manual_seed(seed)
    # the learner's env: the scenario with train_reward's shaping and train_dt (none by default); the evaluation
    # uses env_kwargs
    env = MarineFormationTorchEnv(num_envs=cfg["n_envs"], scenario=cfg["scenario"], **learner_env_kwargs(cfg))
    env.set_seed(seed)
    n, obs_dim, action_dim = env.n_agents, env.core.layout.dim, env.config.action_dim
    normalize = cfg["normalize_observations"]
    scaler = RewardScaler(cfg["gamma"]) if cfg["normalize_reward"] else None
    episodes = EpisodeReturns()
    exploration = cfg["distribution"], cfg["initial_scale"], cfg["action_head_gain"], cfg["scale"], cfg["action_scale"]
    actor = _policy_network(
        obs_dim, action_dim, n, cfg["hidden"], normalize, *exploration, cfg["inputs"], cfg["drop_inputs"]
    )
    critic = _critic_network(obs_dim, n, cfg["hidden"], cfg["algo"] == "mappo", normalize, cfg["inputs"])
    scale = initial_spread(cfg, 0.0, 0)
    env.set_initial_spread(scale)  # before the collector's first reset
    collector = make_collector(env, actor, cfg["frames_per_batch"], cfg["total_frames"])
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(cfg["frames_per_batch"]),
        sampler=SamplerWithoutReplacement(),
        batch_size=cfg["minibatch_size"],
    )
    loss = ClipPPOLoss(
        actor_network=actor,
        critic_network=critic,
        clip_epsilon=cfg["clip_range"],
        entropy_coeff=cfg["ent_coef"],
        normalize_advantage=cfg["normalize_advantage"],
    )
    # one shared policy: its advantages are standardized over every vessel together (TorchRL warns that
    # this pools the agent dimension, which is what a shared policy wants)
    warnings.filterwarnings("ignore", message="You requested advantage normalization", category=UserWarning)
    loss.set_keys(
        reward=("vessel", "reward"),
        action=("vessel", "action"),
        value=("vessel", "state_value"),
        done=("vessel", "done"),
        terminated=("vessel", "terminated"),
        sample_log_prob=("vessel", "action_log_prob"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=cfg["gamma"], lmbda=cfg["gae_lambda"])
    optim = torch.optim.Adam(loss.parameters(), lr=learning_rate(cfg, 0.0, 0))

    out.mkdir(parents=True, exist_ok=True)
    write_config(out, "torchrl", cfg, cfg["seed"])
    rows: list[dict[str, Any]] = []
    begin = time.perf_counter()
    saved_at = 0.0
    frames = 0
    bar = _progress(cfg["total_frames"], progress)
    for data in collector:
        raw_reward = data.get(("next", "vessel", "reward"))
        mean_reward = float(raw_reward.mean())  # logged as the env gave it, before any scaling
        ended = episodes(raw_reward, data.get(("next", "done")))
        if scaler is not None:
            data.set(("next", "vessel", "reward"), scaler(raw_reward, data.get(("next", "done"))))
        # the formation's done flags for every vessel, as the loss reads them per agent
        for key in ("done", "terminated"):
            flag = data.get(("next", key))
            data.set(("next", "vessel", key), flag.unsqueeze(-1).expand(*flag.shape[:-1], n, 1))
        with torch.no_grad():
            loss.value_estimator(
                data, params=loss.critic_network_params, target_params=loss.target_critic_network_params
            )
        buffer.extend(data.reshape(-1))
        rate = learning_rate(cfg, time.perf_counter() - begin, frames)
        for group in optim.param_groups:
            group["lr"] = rate
        kl, updates = _ppo_epochs(loss, optim, buffer, cfg)
        if normalize:  # after the epochs: each batch trains with the statistics it was collected with
            for net in (actor.module[0].module, critic.module):
                _update_norm(net, data.get(("vessel", "observation")))
        collector.update_policy_weights_()
        frames += data.numel()
        elapsed = time.perf_counter() - begin
        # the collector steps this env object: restarts from the next batch on draw at the new scale
        scale = initial_spread(cfg, elapsed, frames)
        env.set_initial_spread(scale)
        rows.append(
            {
                "vessel_steps": frames * n,
                "wall_time_s": round(elapsed, 3),
                "episode_return_mean": float(np.mean(ended)) if ended else "",
                "episodes": len(ended),
                "frames": frames,
                "mean_reward": mean_reward,
                "learning_rate": rate,
                "kl": kl,
                "updates": updates,
                "initial_spread": scale,
            }
        )
        bar.update(data.numel())
        bar.set_postfix(reward=f"{rows[-1]['mean_reward']:.4f}")
        if cfg["minutes"] is not None and elapsed >= 60.0 * cfg["minutes"]:
            break
        if elapsed - saved_at >= SAVE_SECONDS:  # a save takes milliseconds
            _save(out, actor, cfg, obs_dim, action_dim, rows)
            saved_at = elapsed
    bar.close()
    collector.shutdown()
    _save(out, actor, cfg, obs_dim, action_dim, rows)
    from training.learned import evaluate_run

    policy, _ = load_torch_policy(out)
    last: dict[str, Any] = rows[-1] if rows else {"vessel_steps": 0, "wall_time_s": 0.0}
    summary = evaluate_run(
        out, policy, cfg, vessel_steps=int(last["vessel_steps"]), wall_time_s=float(last["wall_time_s"])
    )
    env.close()
    return summary


def budget_used(cfg: dict[str, Any], elapsed: float, frames: int) -> float:
    """The fraction of the run's budget spent: ``max(elapsed / (60·minutes), frames / total_frames)``.

    ``minutes`` null: frames only. Not capped (the last iteration may pass 1).
    """
    seconds = None if cfg["minutes"] is None else 60.0 * cfg["minutes"]
    return budget_fraction(frames, cfg["total_frames"], elapsed, seconds)


def learning_rate(cfg: dict[str, Any], elapsed: float, frames: int) -> float:
    """The Adam rate of the next iteration: ``learning_rate``, or for ``lin_<rate>`` that rate times the budget left.

    The budget left is ``1 −`` :func:`budget_used`, floored at 0.
    """
    if not isinstance(cfg["learning_rate"], str):
        return float(cfg["learning_rate"])
    return parse_schedule(cfg["learning_rate"]) * max(0.0, 1.0 - budget_used(cfg, elapsed, frames))


def initial_spread(cfg: dict[str, Any], elapsed: float, frames: int) -> float:
    """The training env's initial-state spread for the next iteration (``initial_state_curriculum``; none: 1).

    ``start + (1 − start) · min(1, used / until)`` with ``used`` = :func:`budget_used`.
    """
    return curriculum_spread(cfg["initial_state_curriculum"], budget_used(cfg, elapsed, frames))


def _ppo_epochs(loss: Any, optim: Any, buffer: Any, cfg: dict[str, Any]) -> tuple[float, int]:
    """The PPO epochs on one batch; returns the last minibatch's approximate KL and the number of updates.

    With ``target_kl`` set, the epochs stop at the first minibatch whose ``|mean kl_approx|`` (between the
    policy that collected the batch and the current one, before this minibatch's step) exceeds 1.5 ×
    ``target_kl``, without stepping on it (SB3's rule).
    """
    import torch

    kl, updates = float("nan"), 0
    limit = None if cfg["target_kl"] is None else 1.5 * cfg["target_kl"]
    for _ in range(cfg["n_epochs"]):
        for _ in range(cfg["frames_per_batch"] // cfg["minibatch_size"]):
            values = loss(buffer.sample())
            if "kl_approx" in values.keys():
                kl = abs(float(values["kl_approx"].detach().mean()))
            if limit is not None and kl > limit:  # as SB3: this minibatch is not stepped on
                return kl, updates
            total = values["loss_objective"] + values["loss_critic"] + values["loss_entropy"]
            optim.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(loss.parameters(), cfg["max_grad_norm"])
            optim.step()
            updates += 1
    return kl, updates


def make_collector(env: Any, policy: Any, frames_per_batch: int, total_frames: int) -> Any:
    """TorchRL's single-process collector over ``env`` (``policy`` None: random actions).

    ``Collector`` in TorchRL ≥ 0.13, ``SyncDataCollector`` before; the actor
    needs no env transform (TorchRL ≥ 0.14 asks to be told).
    """
    try:
        from torchrl.collectors import Collector
    except ImportError:  # TorchRL < 0.13
        from torchrl.collectors import SyncDataCollector as Collector
    kwargs: dict[str, Any] = {"frames_per_batch": frames_per_batch, "total_frames": total_frames}
    if "auto_register_policy_transforms" in inspect.signature(Collector.__init__).parameters:
        kwargs["auto_register_policy_transforms"] = False
    return Collector(env, policy, **kwargs)


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, unit="frames", disable=not enabled, dynamic_ncols=True)


def _save(
    out: Path, actor: Any, cfg: dict[str, Any], obs_dim: int, action_dim: int, rows: list[dict[str, Any]]
) -> None:
    import torch

    buffer = io.BytesIO()
    torch.save(
        {
            "actor": actor.state_dict(),
            "dims": {"observation": obs_dim, "action": action_dim},
            "hidden": cfg["hidden"],
            "normalize_observations": cfg["normalize_observations"],
            "distribution": cfg["distribution"],
            "config": json.dumps(cfg),
        },
        buffer,
    )
    atomic_write_bytes(out / POLICY_FILE, buffer.getvalue())
    write_progress(out / PROGRESS_FILE, rows, PROGRESS_OWN_COLUMNS)


# ----------------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    prog = "python -m training.torchrl_ppo"
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_run_arguments(parser)
    args = parser.parse_args(argv)
    cfg = config_from_arguments(args, resolve, prog)
    if (args.out / POLICY_FILE).exists() and not args.overwrite:
        report_error(prog, f"{args.out} already holds a run ({POLICY_FILE}); pass --overwrite to replace it")
    summary = train(cfg, args.out, progress=not args.no_progress)
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
