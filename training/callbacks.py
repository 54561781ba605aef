"""SB3 callbacks: periodic evaluation against the reference policy, and a wall-clock budget."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from baselines.metrics import episode_metrics, summarize
from baselines.reference import ReferencePolicy
from baselines.rollout import run_episode
from marine_formation_env.env import parallel_env
from training.learned import ModelPolicy

__all__ = ["EVAL_SEED", "ReferenceEvalCallback", "WallClockBudget", "evaluate_policy_episodes"]

#: Evaluation episodes use seeds EVAL_SEED + k, disjoint from the training seeds.
EVAL_SEED = 1_000_000

LOGGED = ("return", "final_coordination_spread", "rms_cross_track", "success")


def evaluate_policy_episodes(env: Any, policy: Any, episodes: int, seed: int = EVAL_SEED) -> list[dict[str, Any]]:
    """Per-episode metrics of ``policy`` on seeds ``seed, seed + 1, …``."""
    out = []
    for k in range(episodes):
        metrics = episode_metrics(run_episode(env, policy, seed=seed + k), env.config)
        metrics["seed"] = seed + k
        out.append(metrics)
    return out


class ReferenceEvalCallback(BaseCallback):
    """Every ``eval_freq`` vessel-steps, run the learned policy and the reference on the same seeds.

    Logs ``eval/<metric>_learned``, ``eval/<metric>_reference`` and
    ``eval/return_ratio`` (reference return / learned return: 1 means equal,
    below 1 means the learned policy costs more; returns are ≤ 0) to
    TensorBoard, appends a row to ``evaluations.csv`` and keeps the best model
    (highest mean learned return) as ``best_model.zip`` + ``best_vecnormalize.pkl``.
    """

    def __init__(
        self,
        scenario: str,
        env_kwargs: dict[str, Any],
        eval_freq: int,
        episodes: int,
        out_dir: Path,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        self.env = parallel_env(scenario, **env_kwargs)
        self.eval_freq = int(eval_freq)
        self.episodes = int(episodes)
        self.out_dir = Path(out_dir)
        self.reference = summarize(evaluate_policy_episodes(self.env, ReferencePolicy(self.env), self.episodes))
        self.best = -np.inf
        self._last = 0

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps  # a resumed run does not evaluate at once

    def _on_step(self) -> bool:
        if self.eval_freq > 0 and self.num_timesteps - self._last >= self.eval_freq:
            self._last = self.num_timesteps
            self.evaluate()
        return True

    def evaluate(self) -> dict[str, Any]:
        """Run the evaluation now; return the learned policy's summary."""
        normalizer = self.model.get_vec_normalize_env()
        learned = summarize(evaluate_policy_episodes(self.env, ModelPolicy(self.model, normalizer), self.episodes))
        row: dict[str, Any] = {"timesteps": self.num_timesteps, "wall_time": time.time()}
        for key in LOGGED:
            for label, summary in (("learned", learned), ("reference", self.reference)):
                value = summary[key]["mean"] if key in summary else float("nan")
                self.logger.record(f"eval/{key}_{label}", value)
                row[f"{key}_{label}"] = value
        ratio = self.reference["return"]["mean"] / learned["return"]["mean"] if learned["return"]["mean"] else np.nan
        self.logger.record("eval/return_ratio", ratio)
        row["return_ratio"] = ratio
        self.logger.dump(self.num_timesteps)
        path = self.out_dir / "evaluations.csv"
        new = not path.exists()
        with path.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)
        if learned["return"]["mean"] > self.best:
            self.best = learned["return"]["mean"]
            self.model.save(self.out_dir / "best_model.zip")
            if normalizer is not None:
                normalizer.save(str(self.out_dir / "best_vecnormalize.pkl"))
            (self.out_dir / "best_model.json").write_text(json.dumps({"timesteps": self.num_timesteps, **row}))
        if self.verbose:
            print(
                f"[eval] {self.num_timesteps} steps: return learned {learned['return']['mean']:.2f} "
                f"vs reference {self.reference['return']['mean']:.2f} (ratio {ratio:.3f})"
            )
        return learned


class WallClockBudget(BaseCallback):
    """Stop training once ``seconds`` of wall time have passed since training started."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = float(seconds)
        self.start = 0.0

    def _on_training_start(self) -> None:
        self.start = time.perf_counter()

    def _on_step(self) -> bool:
        return time.perf_counter() - self.start < self.seconds
