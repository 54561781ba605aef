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

The config file holds one mapping under ``MarineFormation-v0``, like the SB3
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
| ``lr``, ``max_grad_norm`` | Adam learning rate, gradient clipping | 3e-4, 1.0 |
| ``gamma``, ``lmbda`` | discount, GAE λ | 0.99, 0.95 |
| ``clip_epsilon``, ``entropy_coef`` | PPO clip range, entropy bonus | 0.2, 1e-4 |
| ``epochs``, ``minibatch_size`` | passes over each batch, formation-steps per minibatch | 4, 1600 |
| ``eval_episodes`` | evaluation episodes at the end (seeds 10 000 +), against the reference | 4 |

The run folder gets ``config.yaml`` (resolved, with the seed), ``policy.pt``
(the policy network's weights and what is needed to rebuild it),
``progress.csv`` (per iteration: frames, vessel-steps, seconds, the mean
training reward per vessel-step) and ``evaluation.json`` (the learned
policy's and the reference's mean return over the same seeds). Every file is
written atomically. ``python -m baselines.evaluate --policy RUN_FOLDER``
evaluates the policy next to the reference.
"""

from __future__ import annotations

import csv
import inspect
import io
import json
import pickle
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from marine_formation_env.atomic import atomic_write_bytes, atomic_write_text
from marine_formation_env.cli import ArgumentParser, report_error
from training.config import (
    TrainConfigError,
    _fraction,
    _hidden,
    _non_negative,
    _positive,
    _whole,
    add_run_arguments,
    config_from_arguments,
)

__all__ = ["DEFAULTS", "TorchPolicy", "load_torch_policy", "make_collector", "resolve", "train"]

#: Every key a config may hold, with its default.
DEFAULTS: dict[str, Any] = {
    "algo": "mappo",
    "scenario": "paper",
    "env_kwargs": {},
    "num_envs": 64,
    "frames_per_batch": 6400,
    "total_frames": 1_000_000,
    "minutes": None,
    "hidden": [64, 64],
    "lr": 3e-4,
    "max_grad_norm": 1.0,
    "gamma": 0.99,
    "lmbda": 0.95,
    "clip_epsilon": 0.2,
    "entropy_coef": 1e-4,
    "epochs": 4,
    "minibatch_size": 1600,
    "eval_episodes": 4,
}

ALGOS = ("mappo", "ippo")
POLICY_FILE = "policy.pt"


def resolve(raw: dict[str, Any], seed: int) -> dict[str, Any]:
    """The config with defaults filled in and every value checked (``TrainConfigError`` names the bad one)."""
    unknown = sorted(set(raw) - set(DEFAULTS) - {"seed"})
    if unknown:
        raise TrainConfigError(f"unknown key(s) {unknown}; valid keys: {sorted(DEFAULTS)}")
    cfg = {**DEFAULTS, **{k: v for k, v in raw.items() if k != "seed"}, "seed": seed}
    if cfg["algo"] not in ALGOS:
        raise TrainConfigError(f"algo must be one of {list(ALGOS)}, got {cfg['algo']!r}")
    if not isinstance(cfg["env_kwargs"], dict):
        raise TrainConfigError(f"env_kwargs must be a mapping, got {cfg['env_kwargs']!r}")
    for key in ("num_envs", "frames_per_batch", "total_frames", "epochs", "minibatch_size", "eval_episodes"):
        cfg[key] = _whole(key, cfg[key], 1)
    for key in ("lr", "max_grad_norm", "clip_epsilon"):
        cfg[key] = _positive(key, cfg[key])
    for key in ("gamma", "lmbda"):
        cfg[key] = _fraction(key, cfg[key])
    cfg["entropy_coef"] = _non_negative("entropy_coef", cfg["entropy_coef"])
    if cfg["minutes"] is not None:
        cfg["minutes"] = _positive("minutes", cfg["minutes"])
    cfg["hidden"] = _hidden(cfg["hidden"])
    if cfg["frames_per_batch"] % cfg["num_envs"]:
        raise TrainConfigError(
            f"frames_per_batch = {cfg['frames_per_batch']} must be a multiple of num_envs = {cfg['num_envs']}"
        )
    if cfg["minibatch_size"] > cfg["frames_per_batch"]:
        raise TrainConfigError(
            f"minibatch_size = {cfg['minibatch_size']} exceeds frames_per_batch = {cfg['frames_per_batch']}"
        )
    from marine_formation_env.scenarios import make_config

    try:
        make_config(cfg["scenario"], **cfg["env_kwargs"])
    except (ValueError, TypeError) as err:
        raise TrainConfigError(f"scenario {cfg['scenario']!r} with env_kwargs {cfg['env_kwargs']}: {err}") from err
    return cfg


# ----------------------------------------------------------------------------- networks


def _policy_network(obs_dim: int, action_dim: int, n_agents: int, hidden: list[int]) -> Any:
    """The shared actor: a ``MultiAgentMLP`` (shared parameters) → loc, scale → TanhNormal in [−1, 1]."""
    import torch
    from tensordict.nn import NormalParamExtractor, TensorDictModule
    from torch import nn
    from torchrl.modules import MultiAgentMLP, ProbabilisticActor, TanhNormal

    net = nn.Sequential(
        MultiAgentMLP(
            n_agent_inputs=obs_dim,
            n_agent_outputs=2 * action_dim,
            n_agents=n_agents,
            centralized=False,
            share_params=True,
            num_cells=hidden,
            activation_class=nn.Tanh,
        ),
        NormalParamExtractor(),
    )
    module = TensorDictModule(
        net, in_keys=[("vessel", "observation")], out_keys=[("vessel", "loc"), ("vessel", "scale")]
    )
    return ProbabilisticActor(
        module,
        in_keys=[("vessel", "loc"), ("vessel", "scale")],
        out_keys=[("vessel", "action")],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": torch.tensor(-1.0), "high": torch.tensor(1.0)},
        return_log_prob=True,
    )


def _critic_network(obs_dim: int, n_agents: int, hidden: list[int], centralized: bool) -> Any:
    from tensordict.nn import TensorDictModule
    from torch import nn
    from torchrl.modules import MultiAgentMLP

    net = MultiAgentMLP(
        n_agent_inputs=obs_dim,
        n_agent_outputs=1,
        n_agents=n_agents,
        centralized=centralized,
        share_params=True,
        num_cells=hidden,
        activation_class=nn.Tanh,
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

    def __init__(self, actor: Any, observation_dim: int, action_dim: int) -> None:
        self.actor = actor
        self.mlp = _shared_mlp(actor)
        self.observation_dim = observation_dim
        self.action_dim = action_dim

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        import torch

        # every vessel is one batch entry of a one-agent MLP (the weights are shared: any team size)
        flat = torch.as_tensor(np.asarray(obs, dtype=np.float32).reshape(-1, 1, obs.shape[-1]))
        with torch.no_grad():
            loc, _ = self.mlp(flat).chunk(2, dim=-1)
        return np.asarray(torch.tanh(loc).numpy(), dtype=np.float32).reshape(*obs.shape[:-1], self.action_dim)

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
        actor = _policy_network(int(dims["observation"]), int(dims["action"]), 1, [int(h) for h in saved["hidden"]])
        actor.load_state_dict(saved["actor"])
        config = json.loads(saved["config"])
    except (KeyError, RuntimeError, ValueError, TypeError, EOFError, pickle.UnpicklingError) as err:
        raise ValueError(f"cannot load the policy {str(path)!r}: {type(err).__name__}: {err}") from err
    return TorchPolicy(actor, int(dims["observation"]), int(dims["action"])), config


def _shared_mlp(actor: Any) -> Any:
    """The ``MultiAgentMLP`` of an actor built by :func:`_policy_network` (its loc, scale network's first layer)."""
    from torchrl.modules import MultiAgentMLP

    mlp = actor.module[0].module[0]
    if not isinstance(mlp, MultiAgentMLP):
        raise ValueError(f"not an actor of training.torchrl_ppo: found {type(mlp).__name__} where its MLP should be")
    return mlp


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
    seed = cfg["seed"]
    torch.manual_seed(seed)
    env = MarineFormationTorchEnv(num_envs=cfg["num_envs"], scenario=cfg["scenario"], **cfg["env_kwargs"])
    env.set_seed(seed)
    n, obs_dim, action_dim = env.n_agents, env.core.layout.dim, env.config.action_dim
    actor = _policy_network(obs_dim, action_dim, n, cfg["hidden"])
    critic = _critic_network(obs_dim, n, cfg["hidden"], centralized=cfg["algo"] == "mappo")
    collector = make_collector(env, actor, cfg["frames_per_batch"], cfg["total_frames"])
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(cfg["frames_per_batch"]),
        sampler=SamplerWithoutReplacement(),
        batch_size=cfg["minibatch_size"],
    )
    loss = ClipPPOLoss(
        actor_network=actor,
        critic_network=critic,
        clip_epsilon=cfg["clip_epsilon"],
        entropy_coeff=cfg["entropy_coef"],
        normalize_advantage=False,
    )
    loss.set_keys(
        reward=("vessel", "reward"),
        action=("vessel", "action"),
        value=("vessel", "state_value"),
        done=("vessel", "done"),
        terminated=("vessel", "terminated"),
        sample_log_prob=("vessel", "action_log_prob"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=cfg["gamma"], lmbda=cfg["lmbda"])
    optim = torch.optim.Adam(loss.parameters(), lr=cfg["lr"])

    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "config.yaml", yaml.safe_dump(cfg, sort_keys=False))
    rows: list[dict[str, Any]] = []
    begin = time.perf_counter()
    frames = 0
    bar = _progress(cfg["total_frames"], progress)
    for data in collector:
        # the formation's done flags for every vessel, as the loss reads them per agent
        for key in ("done", "terminated"):
            flag = data.get(("next", key))
            data.set(("next", "vessel", key), flag.unsqueeze(-1).expand(*flag.shape[:-1], n, 1))
        with torch.no_grad():
            loss.value_estimator(
                data, params=loss.critic_network_params, target_params=loss.target_critic_network_params
            )
        buffer.extend(data.reshape(-1))
        for _ in range(cfg["epochs"]):
            for _ in range(cfg["frames_per_batch"] // cfg["minibatch_size"]):
                values = loss(buffer.sample())
                total = values["loss_objective"] + values["loss_critic"] + values["loss_entropy"]
                optim.zero_grad()
                total.backward()
                torch.nn.utils.clip_grad_norm_(loss.parameters(), cfg["max_grad_norm"])
                optim.step()
        collector.update_policy_weights_()
        frames += data.numel()
        elapsed = time.perf_counter() - begin
        rows.append(
            {
                "frames": frames,
                "vessel_steps": frames * n,
                "seconds": round(elapsed, 3),
                "mean_reward": float(data.get(("next", "vessel", "reward")).mean()),
            }
        )
        bar.update(data.numel())
        bar.set_postfix(reward=f"{rows[-1]['mean_reward']:.4f}")
        if cfg["minutes"] is not None and elapsed >= 60.0 * cfg["minutes"]:
            break
    bar.close()
    collector.shutdown()
    _save(out, actor, cfg, obs_dim, action_dim, rows)
    from training.learned import evaluate_run

    policy, _ = load_torch_policy(out)
    last: dict[str, Any] = rows[-1] if rows else {"frames": 0, "vessel_steps": 0, "seconds": 0.0}
    summary = evaluate_run(out, policy, cfg, int(last["frames"]), int(last["vessel_steps"]), float(last["seconds"]))
    env.close()
    return summary


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
            "config": json.dumps(cfg),
        },
        buffer,
    )
    atomic_write_bytes(out / POLICY_FILE, buffer.getvalue())
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=["frames", "vessel_steps", "seconds", "mean_reward"])
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(out / "progress.csv", text.getvalue())


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
