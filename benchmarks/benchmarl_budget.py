"""BenchMARL MAPPO on ``marine_formation/paper_speed`` for a wall-clock budget, then the common evaluation.

A step of ``benchmarks.training_throughput``, run with the interpreter of
the ecosystem environment (BenchMARL needs TorchRL 0.11)::

    .venv-ecosystem/bin/python -m benchmarks.benchmarl_budget --minutes 15 --out runs/throughput/benchmarl

BenchMARL's own experiment (its default MAPPO, MLP and on-policy settings;
no loggers, no evaluation during training, which would render videos) runs
until an iteration ends past the budget: a BenchMARL callback stops it there.
The policy is then evaluated deterministically by the engine of
``baselines.evaluate`` on the seeds every pipeline of the benchmark uses
(``training.learned.evaluate_run``), and ``evaluation.json`` is written.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from marine_formation_env.cli import ArgumentParser, int_at_least

__all__ = ["BenchMARLPolicy", "main", "run"]


class _BudgetSpent(Exception):
    """Raised by the callback at the end of the iteration that spends the budget."""


try:
    from benchmarl.experiment.callback import Callback
except ImportError:  # pragma: no cover - the module runs in the ecosystem environment only
    Callback = object  # type: ignore[assignment,misc]


class StopAfter(Callback):  # type: ignore[misc,valid-type]
    """A BenchMARL callback that ends the run after the training step that passes ``seconds``.

    Pickled with the experiment's config (BenchMARL saves its callbacks), so it lives at module level.
    """

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self.begin = time.perf_counter()
        self.trained = 0.0

    def on_train_end(self, training_td: Any, group: str) -> None:
        self.trained = time.perf_counter() - self.begin
        if self.trained >= self.seconds:
            raise _BudgetSpent


class BenchMARLPolicy:
    """A BenchMARL experiment's policy as a batch policy (``baselines``): deterministic actions.

    ``act_batch((B·N, dim)) -> (B·N, A)`` for B formations of N vessels (BenchMARL's
    actor is an N-agent MLP, so N is the task's team size).
    """

    def __init__(self, policy: Any, group: str, n_agents: int, observation_dim: int, action_dim: int) -> None:
        self.policy = policy
        self.group = group
        self.n_agents = n_agents
        self.observation_dim = observation_dim
        self.action_dim = action_dim

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        import torch
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        flat = np.asarray(obs, dtype=np.float32).reshape(-1, self.n_agents, self.observation_dim)
        td = TensorDict({(self.group, "observation"): torch.from_numpy(flat)}, batch_size=[flat.shape[0]])
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            action = self.policy(td).get((self.group, "action"))
        return np.asarray(action.numpy(), dtype=np.float32).reshape(*obs.shape[:-1], self.action_dim)


def run(minutes: float, out: Path, seed: int, episodes: int) -> dict[str, Any]:
    """Train for ``minutes``, evaluate, write ``out/evaluation.json``; returns its contents."""
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from marine_formation_env.benchmarl import MarineFormationTask
    from training.learned import evaluate_run

    task = MarineFormationTask.__members__["PAPER_SPEED"].get_from_yaml()
    config = ExperimentConfig.get_from_yaml()
    config.loggers = []
    config.create_json = False
    config.evaluation = False
    config.checkpoint_at_end = False
    config.max_n_frames = 10**12  # the callback ends the run
    config.max_n_iters = None
    out.mkdir(parents=True, exist_ok=True)
    config.save_folder = str(out)
    stop = StopAfter(60.0 * minutes)
    experiment = Experiment(
        task=task,
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=seed,
        config=config,
        callbacks=[stop],
    )
    try:
        experiment.run()
    except _BudgetSpent:
        pass
    env = experiment.test_env
    group = next(iter(experiment.group_map))
    n = len(experiment.group_map[group])
    policy = BenchMARLPolicy(
        experiment.policy, group, n, int(env.observation_spec[group, "observation"].shape[-1]), task_action_dim(env)
    )
    frames = int(experiment.total_frames)
    cfg = {"scenario": task.config["scenario"], "env_kwargs": task.config["overrides"], "eval_episodes": episodes}
    return evaluate_run(out, policy, cfg, vessel_steps=frames * n, wall_time_s=round(stop.trained, 3))


def task_action_dim(env: Any) -> int:
    """The action size of the env's one agent group."""
    group = next(iter(env.group_map))
    return int(env.full_action_spec[group, "action"].shape[-1])


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m benchmarks.benchmarl_budget", description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=15.0, help="wall-clock training budget (default 15)")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="training seed (default 0)")
    parser.add_argument("--episodes", type=int_at_least(1), default=10, help="evaluation episodes (default 10)")
    parser.add_argument("--out", type=Path, required=True, help="run folder")
    args = parser.parse_args(argv)
    if not args.minutes > 0:
        parser.error(f"--minutes must be > 0, got {args.minutes}")
    print(json.dumps(run(args.minutes, args.out, args.seed, args.episodes), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
