"""SB3 callbacks: evaluation against the reference, atomic checkpoints, a wall-clock budget, Ctrl-C.

Everything they write goes through ``training.run_folder`` (temporary file,
fsync, rename), so a run killed at any instant leaves readable files.
"""

from __future__ import annotations

import csv
import json
import pickle
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from baselines.engine import episode_reports
from baselines.metrics import summarize
from baselines.reference import ReferencePolicy, rule_broadcasting
from baselines.seeds import development_seeds
from marine_formation_env.env import parallel_env
from training import run_folder
from training.config import budget_fraction, curriculum_spread
from training.learned import ModelPolicy, load_learned_policy

__all__ = [
    "AtomicCheckpointCallback",
    "InitialStateCurriculum",
    "ProgressLog",
    "ReferenceEvalCallback",
    "StopRequest",
    "WallClockBudget",
    "evaluate_policy_episodes",
]

LOGGED = ("return", "final_coordination_spread", "rms_cross_track", "success")


def evaluate_policy_episodes(env: Any, policy: Any, seeds: list[int]) -> list[dict[str, Any]]:
    """Per-episode metrics of ``policy`` on ``seeds``, run as one batch (``baselines.engine``)."""
    metrics, _ = episode_reports(policy, env.config, list(seeds), backend=env.core.backend)
    return metrics


class ReferenceEvalCallback(BaseCallback):
    """Every ``eval_freq`` vessel-steps, run the learned policy and the reference on the same seeds.

    The seeds are ``baselines.seeds.development_seeds(episodes)``: this evaluation selects the best
    model, so it never runs on the evaluation seeds the run folder's ``evaluation.json`` reports.

    Logs ``eval/<metric>_learned``, ``eval/<metric>_reference`` and
    ``eval/return_ratio`` (reference return / learned return: 1 means equal,
    below 1 means the learned policy costs more; returns are ≤ 0) to
    TensorBoard, appends a row to ``evaluations.csv`` (rewritten atomically)
    and keeps the best model (highest mean learned return) as
    ``best_model.zip`` + ``best_vecnormalize.pkl`` + ``best_model.json`` (its
    evaluation row and ``eval_episodes``), replaced together
    (``training.run_folder.write_together``) *before* the row is appended,
    so the recorded best is never below a row of ``evaluations.csv``.

    A resumed run calls ``restore_best`` first, so the best score of the
    earlier part of the run is kept (a later evaluation replaces
    ``best_model.zip`` only if it beats it).
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
        self.seeds = development_seeds(self.episodes)
        self.out_dir = Path(out_dir)
        periodic = rule_broadcasting(self.env.config)
        self.reference = summarize(
            episode_reports(ReferencePolicy(periodic), periodic, self.seeds, backend=self.env.core.backend)[0]
        )
        self.best = -np.inf
        self._last = 0

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps  # a resumed run does not evaluate at once

    def _on_step(self) -> bool:
        if self.eval_freq > 0 and self.num_timesteps - self._last >= self.eval_freq:
            self._last = self.num_timesteps
            self.evaluate()
        return True

    def _row(self, learned: dict[str, Any], timesteps: int, wall_time: float) -> dict[str, Any]:
        row: dict[str, Any] = {"timesteps": int(timesteps), "wall_time": wall_time}
        for key in LOGGED:
            for label, summary in (("learned", learned), ("reference", self.reference)):
                row[f"{key}_{label}"] = summary[key]["mean"] if key in summary else float("nan")
        mean = learned["return"]["mean"]
        row["return_ratio"] = self.reference["return"]["mean"] / mean if mean else np.nan
        return row

    def restore_best(self) -> float:
        """Take the best score from ``best_model.json`` (a resumed run); return it (−inf if none).

        A best model scored on another number of episodes than ``self.episodes``
        (``eval_episodes`` changed on resume) is re-scored on the current
        evaluation seeds first, and ``best_model.json`` is rewritten, so the
        comparison with the coming evaluations is like for like.
        """
        record = run_folder.read_best(self.out_dir)
        if record is None or not (self.out_dir / "best_model.zip").is_file():
            self.best = -np.inf
            return self.best
        if int(record.get("eval_episodes", self.episodes)) == self.episodes:
            self.best = float(record["return_learned"])
            return self.best
        try:
            policy, _ = load_learned_policy(self.out_dir / "best_model.zip")
        except Exception as err:  # written atomically, so only damaged by hand: start the comparison afresh
            reason = " ".join(f"{type(err).__name__}: {err}".split())
            print(
                f"cannot re-score {self.out_dir / 'best_model.zip'} ({reason}); the next evaluation replaces it",
                file=sys.stderr,
            )
            self.best = -np.inf
            return self.best
        learned = summarize(evaluate_policy_episodes(self.env, policy, self.seeds))
        row = self._row(learned, int(record["timesteps"]), float(record.get("wall_time", time.time())))
        run_folder.write_bytes(
            self.out_dir / "best_model.json", json.dumps({**row, "eval_episodes": self.episodes}).encode()
        )
        self.best = float(row["return_learned"])
        return self.best

    def evaluate(self) -> dict[str, Any]:
        """Run the evaluation now; return the learned policy's summary."""
        normalizer = self.model.get_vec_normalize_env()
        learned = summarize(evaluate_policy_episodes(self.env, ModelPolicy(self.model, normalizer), self.seeds))
        row = self._row(learned, self.num_timesteps, time.time())
        for key, value in row.items():
            if key not in ("timesteps", "wall_time"):
                self.logger.record(f"eval/{key}", value)
        self.logger.dump(self.num_timesteps)
        if learned["return"]["mean"] > self.best:
            self.best = learned["return"]["mean"]
            record = json.dumps({**row, "eval_episodes": self.episodes}).encode()
            model = self.model
            writers: dict[str, Any] = {"best_model.zip": model.save}
            if normalizer is not None:
                writers["best_vecnormalize.pkl"] = lambda handle: pickle.dump(normalizer, handle)
            writers["best_model.json"] = lambda handle: handle.write(record)
            run_folder.write_together(self.out_dir, writers)
        path = self.out_dir / "evaluations.csv"
        run_folder.write_evaluations(path, [*run_folder.read_evaluations(path), row])
        if self.verbose:
            print(
                f"[eval] {self.num_timesteps} steps: return learned {learned['return']['mean']:.2f} "
                f"vs reference {self.reference['return']['mean']:.2f} (ratio {row['return_ratio']:.3f})"
            )
        return learned


class AtomicCheckpointCallback(BaseCallback):
    """Save a checkpoint each time the step count passes a multiple of ``every`` vessel-steps.

    Replaces SB3's ``CheckpointCallback`` with the same file names
    (``checkpoints/model_<N>_steps.zip``, ``checkpoints/model_vecnormalize_<N>_steps.pkl``),
    but each file is written atomically and the statistics before the model
    (``training.run_folder.save_checkpoint``).
    """

    def __init__(self, out_dir: Path, every: int, verbose: int = 0) -> None:
        super().__init__(verbose)
        if every < 1:
            raise ValueError(f"checkpoint interval must be ≥ 1 vessel-step, got {every}")
        self.out_dir = Path(out_dir)
        self.every = int(every)
        self._mark = 0

    def _on_training_start(self) -> None:
        self._mark = self.num_timesteps // self.every

    def _on_step(self) -> bool:
        mark = self.num_timesteps // self.every
        if mark > self._mark:
            self._mark = mark
            path = run_folder.save_checkpoint(self.model, self.out_dir)
            if self.verbose:
                print(f"saved checkpoint {path}")
        return True


class StopRequest(BaseCallback):
    """Stop training at the next step once ``requested`` is set (e.g. by a SIGINT handler)."""

    def __init__(self) -> None:
        super().__init__()
        self.requested = False

    def _on_step(self) -> bool:
        return not self.requested


class ProgressLog(BaseCallback):
    """The learning curve of a run: ``out/progress.csv``, one row per rollout.

    The columns are ``training.run_folder.PROGRESS_COLUMNS``, those of every trainer.
    ``episode_return_mean`` is the mean return (per vessel, the env's raw reward,
    as the evaluation's ``return``) of the training episodes that ended during
    the rollout, from the ``VecMonitor`` under the normalization (the
    stochastic policy's, on the training distribution of initial states);
    empty when none ended. ``wall_time_s`` counts from the start of this
    ``learn`` call (plus the last row's on a resumed run). The file is
    rewritten atomically at most every ``every`` seconds and at the end.
    """

    def __init__(self, out: Path, every: float = 10.0) -> None:
        super().__init__()
        self.path = Path(out) / "progress.csv"
        self.every = float(every)
        self.rows: list[dict[str, Any]] = []
        self.start = self.written = 0.0
        self.offset = 0.0
        self.pending: list[float] = []

    def resume(self, steps: int) -> None:
        """Keep the rows of an earlier run up to ``steps`` vessel-steps (a resumed run)."""
        if self.path.is_file():
            with self.path.open(newline="") as handle:
                self.rows = [row for row in csv.DictReader(handle) if int(row["vessel_steps"]) <= steps]
            self.offset = float(self.rows[-1]["wall_time_s"]) if self.rows else 0.0

    def _on_training_start(self) -> None:
        self.start = self.written = time.perf_counter()

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            if "episode" in info:  # VecMonitor's record of an episode that just ended
                self.pending.append(float(info["episode"]["r"]))
        return True

    def _on_rollout_end(self) -> None:
        fresh, self.pending = self.pending, []
        now = time.perf_counter()
        self.rows.append(
            {
                "vessel_steps": int(self.num_timesteps),
                "wall_time_s": round(self.offset + now - self.start, 3),
                "episode_return_mean": float(np.mean(fresh)) if fresh else "",
                "episodes": len(fresh),
            }
        )
        if now - self.written >= self.every:
            self._write()
            self.written = now

    def _on_training_end(self) -> None:
        self._write()

    def _write(self) -> None:
        run_folder.write_progress(self.path, self.rows)


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


class BudgetSchedule:
    """An SB3 schedule (``progress_remaining ↦ value``) that also follows a wall-clock budget.

    ``schedule(1 − used)`` with ``used`` the fraction of the budget spent, whichever of SB3's steps (``1 −
    progress_remaining``) and ``seconds`` of wall time since ``start`` runs out first
    (``training.config.budget_fraction``), floored at 0: a ``lin_<x>`` learning rate then reaches 0 at the
    end of the minutes the learning benchmarks give, as the TorchRL trainer's ``lin_<rate>`` does,
    instead of following an ``n_timesteps`` far beyond what the minutes reach. A constant schedule stays constant.
    """

    def __init__(self, schedule: Any, seconds: float, start: float) -> None:
        self.schedule = schedule
        self.seconds = float(seconds)
        self.start = float(start)

    def __call__(self, progress_remaining: float) -> float:
        used = budget_fraction(1.0 - progress_remaining, 1.0, time.perf_counter() - self.start, self.seconds)
        return float(self.schedule(max(0.0, 1.0 - used)))


class LearningRateBudget(BaseCallback):
    """At the start of training, make the model's learning-rate schedule a ``BudgetSchedule`` of ``seconds``."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = float(seconds)

    def _on_training_start(self) -> None:
        base = self.model.lr_schedule
        if isinstance(base, BudgetSchedule):  # a resumed model saved with one: the budget restarts
            base = base.schedule
        self.model.lr_schedule = BudgetSchedule(base, self.seconds, time.perf_counter())

    def _on_step(self) -> bool:
        return True


class InitialStateCurriculum(BaseCallback):
    """A curriculum over the initial state (``initial_state_curriculum``): before each rollout the training env's
    later (auto)resets start ``start + (1 − start) · min(1, used / until)`` of the way from the formation on its
    lanes to the scenario's initial state (``training.config.curriculum_spread``).

    ``used`` is the fraction of the budget spent, whichever of ``total_steps`` vessel-steps and ``seconds`` of
    wall time (counted from this ``learn`` call) runs out first, as the TorchRL trainer counts it. The innermost
    VecEnv (``SharedPolicyVecEnv`` or ``TeamsVecEnv``) must have ``set_initial_spread``.
    """

    def __init__(self, curriculum: dict[str, float], total_steps: int, seconds: float | None = None) -> None:
        super().__init__()
        self.curriculum = curriculum
        self.total_steps = max(1, int(total_steps))
        self.seconds = seconds
        self.start = time.perf_counter()

    def spread(self) -> float:
        """The spread for the next rollout."""
        used = budget_fraction(self.num_timesteps, self.total_steps, time.perf_counter() - self.start, self.seconds)
        return curriculum_spread(self.curriculum, used)

    def _on_training_start(self) -> None:
        self.start = time.perf_counter()

    def _on_rollout_start(self) -> None:
        scale = self.spread()
        env: Any = self.training_env.unwrapped  # SharedPolicyVecEnv or TeamsVecEnv
        env.set_initial_spread(scale)

    def _on_step(self) -> bool:
        return True
