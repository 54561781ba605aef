"""The TorchRL trainer's config: every key with its default, its checks, and the schedules over the budget.

``resolve`` fills in ``DEFAULTS`` and checks every value (``TrainConfigError`` names a bad one); the keys
and their meaning are in ``docs/training.md`` ("TorchRL: configuration"). The schedules (``learning_rate``,
``initial_spread``) are functions of the fraction of the run's budget spent (``budget_used``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from training.config import (
    TrainConfigError,
    _hidden,
    _positive,
    _whole,
    budget_fraction,
    check_curriculum,
    check_ppo_keys,
    check_renamed,
    check_train_reward,
    curriculum_spread,
    parse_schedule,
    training_env_kwargs,
)

__all__ = [
    "ALGOS",
    "DEFAULTS",
    "DISTRIBUTIONS",
    "INPUTS",
    "SCALES",
    "budget_used",
    "initial_spread",
    "learner_env_kwargs",
    "learning_rate",
    "resolve",
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
    check_ppo_keys(cfg)
    cfg["initial_scale"] = _positive("initial_scale", cfg["initial_scale"])
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


def budget_used(cfg: dict[str, Any], elapsed: float, frames: int) -> float:
    """The fraction of the run's budget spent: ``max(elapsed / (60·minutes), frames / total_frames)``.

    ``minutes`` null: frames only. Not capped (the last iteration may pass 1).
    """
    seconds = None if cfg["minutes"] is None else 60.0 * cfg["minutes"]
    return budget_fraction(frames, cfg["total_frames"], elapsed, seconds)


def learning_rate(cfg: dict[str, Any], elapsed: float, frames: int) -> float:
    """The Adam rate of the next iteration: ``learning_rate``, or for ``lin_<rate>`` that rate times the budget left.

    The budget left is ``1 −`` ``budget_used``, floored at 0.
    """
    if not isinstance(cfg["learning_rate"], str):
        return float(cfg["learning_rate"])
    return parse_schedule(cfg["learning_rate"]) * max(0.0, 1.0 - budget_used(cfg, elapsed, frames))


def initial_spread(cfg: dict[str, Any], elapsed: float, frames: int) -> float:
    """The training env's initial-state spread for the next iteration (``initial_state_curriculum``; none: 1).

    ``start + (1 − start) · min(1, used / until)`` with ``used`` = ``budget_used``.
    """
    return curriculum_spread(cfg["initial_state_curriculum"], budget_used(cfg, elapsed, frames))
