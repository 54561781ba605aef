"""Learned policies with the same interface as the reference policy.

``ModelPolicy`` wraps an SB3 model (and the observation normalization it
was trained with) as a policy over PettingZoo observation dicts: every vessel
acts from its own masked observation with the shared network.
``load_sb3_run`` loads one from a run folder written by
``python -m training.train`` (``model.zip``, ``vecnormalize.pkl``,
``config.yaml``; a run with ``residual: true`` as the ``ResidualPolicy`` of
its network); ``load_learned_policy`` loads a run folder of any trainer,
by the ``trainer`` field of its ``config.yaml``.
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from baselines.engine import episode_reports
from baselines.reference import ReferencePolicy, rule_broadcasting
from baselines.residual import ResidualPolicy
from baselines.rollout import BatchPolicy
from baselines.runs import RunFolderError, load_run, read_config, run_folder_of
from baselines.seeds import evaluation_seeds
from marine_formation_env.atomic import atomic_write_text
from marine_formation_env.env import parallel_env
from marine_formation_env.scenarios import make_config
from training import run_folder
from training.config import algo_class

__all__ = [
    "UNREADABLE",
    "ModelPolicy",
    "UnreadableRunError",
    "evaluate_run",
    "evaluation_summary",
    "load_learned_policy",
    "load_sb3_run",
    "member_metrics",
]


class ModelPolicy(BatchPolicy):
    """A shared SB3 policy acting for every vessel.

    A policy whose features extractor is the slot network
    (``training.slot_policy.SlotFeatures``, ``any_slots``) reads any
    number of observation slots, so it acts in any team: observations of
    another length than its training team's go through the network directly
    (SB3's ``predict`` accepts only the training shape), with the same
    deterministic mode and the same clipping to the action space.

    Args:
        model: an SB3 model whose observation is one vessel's observation.
        normalizer: a ``VecNormalize`` (or None) whose ``normalize_obs`` is applied first.
        deterministic: act with the distribution's mode (default) or sample.
    """

    def __init__(self, model: Any, normalizer: Any = None, deterministic: bool = True) -> None:
        self.model = model
        self.normalizer = normalizer
        self.deterministic = deterministic
        self.observation_dim: int = model.observation_space.shape[0]
        self.action_dim: int = model.action_space.shape[0]
        from training.slot_policy import SlotFeatures  # torch: loaded with the model already

        self.any_slots: bool = isinstance(getattr(model.policy, "features_extractor", None), SlotFeatures)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(..., A)`` for observations ``(..., dim)``."""
        flat = np.asarray(obs, dtype=np.float32).reshape(-1, obs.shape[-1])
        other_length = flat.shape[-1] != self.observation_dim
        if other_length and not self.any_slots:
            raise ValueError(f"this policy reads observations of size {self.observation_dim}, got {flat.shape[-1]}")
        if self.normalizer is not None:
            if other_length and self.normalizer.norm_obs:  # training.config refuses this
                raise ValueError(
                    f"observation statistics of size {self.observation_dim} cannot normalize observations "
                    f"of size {flat.shape[-1]}"
                )
            flat = self.normalizer.normalize_obs(flat)
        if other_length:
            actions = self._act_any_slots(flat)
        else:
            actions, _ = self.model.predict(flat, deterministic=self.deterministic)
        return np.asarray(actions, dtype=np.float32).reshape(*obs.shape[:-1], -1)

    def _act_any_slots(self, flat: np.ndarray) -> np.ndarray:
        """What ``predict`` computes, for an observation length other than the training team's."""
        import torch

        policy = self.model.policy
        policy.set_training_mode(False)  # as predict does
        with torch.no_grad():
            actions = policy._predict(torch.as_tensor(flat, device=policy.device), self.deterministic).cpu().numpy()
        if policy.squash_output:
            return policy.unscale_action(actions)  # type: ignore[no-any-return]
        return np.clip(actions, self.model.action_space.low, self.model.action_space.high)


def load_learned_policy(path: str | Path, deterministic: bool = True) -> tuple[Any, dict[str, Any]]:
    """Load a trained policy and the resolved config of its run (``baselines.runs.load_run``).

    The kind of run is ``config.yaml``'s ``trainer`` field, and its loader the entry point of that name in
    ``marine_formation_env.trainers``.

    Args:
        path: a run folder of any trainer (or a path in it), or one SB3 model file of a run folder
            (``model.zip``, ``best_model.zip``, a checkpoint in ``checkpoints/``).
        deterministic: act with the distribution's mode (the default; the TorchRL and RLlib policies act
            deterministically only).

    Returns:
        ``(policy, config)`` where ``config`` is the run's ``config.yaml`` (``trainer``, ``seed``, ``scenario``
        and ``env_kwargs`` say what it was trained on).

    Raises:
        baselines.runs.RunFolderError: no ``config.yaml``, or one without a ``trainer`` field.
        UnreadableRunError: the policy files cannot be read.
    """
    try:
        return load_run(path, deterministic=deterministic)
    except (RunFolderError, UnreadableRunError):
        raise
    except ValueError as err:
        raise UnreadableRunError(str(err)) from None


def load_sb3_run(run: Path, deterministic: bool = True) -> tuple[BatchPolicy, dict[str, Any]]:
    """The policy of a ``training.train`` run and its config: ``run`` is the run folder (its final ``model.zip``
    and ``vecnormalize.pkl``) or one model file of it (``best_model.zip``, a checkpoint).

    The loader of the ``sb3`` entry point of ``marine_formation_env.trainers``.
    """
    run = Path(run)
    folder = run_folder_of(run)
    return _load_sb3_model(run if run.is_file() else folder / "model.zip", read_config(folder), deterministic)


def _load_sb3_model(
    model_path: Path, config: dict[str, Any], deterministic: bool
) -> tuple[ModelPolicy | ResidualPolicy, dict[str, Any]]:
    if not model_path.is_file():
        raise FileNotFoundError(f"no model at {str(model_path)!r}")
    try:
        model = algo_class(config["algo"]).load(model_path, device="cpu")
    except KeyError as err:
        raise UnreadableRunError(f"the config of {model_path.parent} has no {err}") from None
    except UNREADABLE as err:
        raise UnreadableRunError(f"cannot load the model {str(model_path)!r}: {_reason(err)}") from None
    normalizer = None
    stats = _vecnormalize_path(model_path)
    if stats is not None:
        try:
            with open(stats, "rb") as handle:
                normalizer = pickle.load(handle)
            normalizer.training = False
        except UNREADABLE as err:
            raise UnreadableRunError(f"cannot load the normalization {str(stats)!r}: {_reason(err)}") from None
    network = ModelPolicy(model, normalizer, deterministic)
    if not config.get("residual", False):
        return network, config
    return ResidualPolicy(network, make_config(config["scenario"], **config["env_kwargs"])), config


#: What reading a truncated, empty or foreign model or pickle file raises.
UNREADABLE = (
    zipfile.BadZipFile,
    AssertionError,  # SB3: "No data found in the saved file"
    EOFError,
    pickle.UnpicklingError,
    ValueError,
    KeyError,
    AttributeError,
    RuntimeError,
    OSError,
)


def evaluate_run(
    out: Path, policy: Any, cfg: dict[str, Any], *, vessel_steps: int, wall_time_s: float
) -> dict[str, Any]:
    """A trained policy and the reference on the evaluation seeds, written to ``out/evaluation.json``.

    The closing evaluation of every trainer (the engine of ``baselines.evaluate``), on
    ``baselines.seeds.evaluation_seeds(cfg["eval_episodes"])`` of ``cfg``'s ``scenario`` and ``env_kwargs``
    (the benchmark's reward, never ``train_reward``). The file's schema is the same for every trainer:
    ``seeds``, ``vessel_steps`` and ``wall_time_s`` (how much training the policy had), then for ``learned``
    and ``reference`` each ``<name>_return`` (mean), ``<name>_success`` (rate), ``<name>_returns`` (per
    episode) and ``<name>_action_change`` (mean per step) (``evaluation_summary``).
    """
    import json

    seeds = evaluation_seeds(cfg["eval_episodes"])
    summary = {
        "seeds": seeds,
        "vessel_steps": int(vessel_steps),
        "wall_time_s": float(wall_time_s),
        **evaluation_summary(policy, cfg["scenario"], cfg["env_kwargs"], seeds),
    }
    atomic_write_text(out / run_folder.EVALUATION_FILE, json.dumps(summary, indent=2) + "\n")
    return summary


def member_metrics(policies: dict[str, Any], config: Any, seeds: list[int]) -> dict[str, dict[str, Any]]:
    """Each of ``policies`` on ``seeds`` of one env config (engine of ``baselines.evaluate``).

    Per policy: the mean ``return`` and the per-episode ``returns``, the ``success`` rate, the mean
    ``action_change`` per step and the mean ``final_spread`` (the coordination spread at the end).
    """
    out: dict[str, dict[str, Any]] = {}
    for name, policy in policies.items():
        metrics, _ = episode_reports(policy, config, seeds)
        out[name] = {
            "return": float(np.mean([m["return"] for m in metrics])),
            "returns": [m["return"] for m in metrics],
            "success": float(np.mean([m["success"] for m in metrics])),
            "action_change": float(np.mean([m["action_change"] for m in metrics])),
            "final_spread": float(np.mean([m["final_coordination_spread"] for m in metrics])),
        }
    return out


def evaluation_summary(policy: Any, scenario: str, env_kwargs: dict[str, Any], seeds: list[int]) -> dict[str, Any]:
    """``policy`` and the reference on ``seeds`` of the scenario (``member_metrics``), flat: the mean return
    and success of each, the per-episode returns and the mean action change per step. Where the policy
    decides when to broadcast (``transmit``), the reference broadcasts by the channel's rule."""
    config = parallel_env(scenario, **env_kwargs).config
    periodic = rule_broadcasting(config)
    members = {
        **member_metrics({"learned": policy}, config, seeds),
        **member_metrics({"reference": ReferencePolicy(periodic)}, periodic, seeds),
    }
    return {f"{m}_{key}": members[m][key] for m in members for key in ("return", "success", "returns", "action_change")}


class UnreadableRunError(ValueError):
    """A model, normalization or config file of a run folder that cannot be read (names the file)."""


def _reason(err: BaseException) -> str:
    text = str(err) or "empty or truncated file"
    return f"{type(err).__name__}: {text}"


def _vecnormalize_path(model_path: Path) -> Path | None:
    """``vecnormalize.pkl`` beside ``model.zip``, or the checkpoint's own statistics."""
    if model_path.name == "model.zip" or model_path.name == "best_model.zip":
        candidate = model_path.with_name(model_path.stem.replace("model", "vecnormalize") + ".pkl")
        return candidate if candidate.is_file() else None
    # checkpoint names (training.run_folder): model_<N>_steps.zip and model_vecnormalize_<N>_steps.pkl
    stem = model_path.stem
    if stem.startswith("model_") and stem.endswith("_steps"):
        candidate = model_path.with_name(f"model_vecnormalize_{stem[len('model_') :]}.pkl")
        return candidate if candidate.is_file() else None
    return None
