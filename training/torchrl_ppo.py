"""Multi-agent PPO (MAPPO / IPPO) with TorchRL on the batched TorchRL env.

The loop of TorchRL's multi-agent PPO recipe (``sota-implementations/multiagent/mappo_ippo.py``) on
``MarineFormationTorchEnv``: a collector steps ``n_envs`` formations at once,
one policy shared by every vessel (``training.torchrl_networks``), GAE that bootstraps at the time limit and not
at a collision or a workspace exit, clipped PPO updates. The config's keys are in ``training.torchrl_config``
and ``docs/training.md``::

    python -m training.torchrl_ppo --config training/configs/torchrl/paper_speed_mappo.yaml --seed 0 \\
        --out runs/torchrl_paper_speed
    python -m training.torchrl_ppo --config training/configs/torchrl/paper_speed_mappo.yaml \\
        --set minutes=2 --set env_kwargs.topology=chain --out runs/try --overwrite

The run folder (``training.run_folder``) gets ``config.yaml`` (``trainer: torchrl``), ``policy.pt``,
``progress.csv`` and ``evaluation.json``; ``policy.pt`` and ``progress.csv`` are also written every
``SAVE_SECONDS`` during training.
"""

from __future__ import annotations

import inspect
import io
import json
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from marine_formation_env.atomic import atomic_write_bytes
from marine_formation_env.cli import ArgumentParser, report_error
from training.config import add_run_arguments, config_from_arguments
from training.run_folder import PROGRESS_FILE, write_config, write_progress
from training.torchrl_config import initial_spread, learner_env_kwargs, learning_rate, resolve
from training.torchrl_networks import (
    POLICY_FILE,
    actor_options,
    critic_network,
    load_torch_policy,
    policy_network,
    running_norm,
    update_norm,
)

__all__ = ["EpisodeReturns", "RewardScaler", "main", "make_collector", "train"]

#: The trainer's own columns of ``progress.csv``, after ``training.run_folder.PROGRESS_COLUMNS``.
PROGRESS_OWN_COLUMNS = ("frames", "mean_reward", "learning_rate", "kl", "updates", "initial_spread")
#: Seconds of training between the intermediate saves of ``policy.pt`` and ``progress.csv``.
SAVE_SECONDS = 60.0


class RewardScaler:
    """Learner-side reward scaling, as SB3's ``VecNormalize`` does it (``norm_reward``).

    Each (formation, vessel) stream keeps a discounted return
    ``G ← γ·G + r`` (reset to 0 after the formation's episode ends, by
    termination or truncation); the running variance of every ``G`` seen
    (``running_norm``'s statistics, one entry) scales the rewards:
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
        # one thread by default, as training.train: the networks are small, and on a shared machine more
        # intra-op threads contend with the simulation (docs/training.md)
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
    actor = policy_network(obs_dim, action_dim, n_agents=n, **actor_options(cfg))
    critic = critic_network(
        obs_dim,
        n_agents=n,
        hidden=cfg["hidden"],
        centralized=cfg["algo"] == "mappo",
        normalize=normalize,
        inputs=cfg["inputs"],
    )
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
                update_norm(net, data.get(("vessel", "observation")))
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
