"""Training configuration: YAML keyed like rl-baselines3-zoo, validated, no ``eval``.

A config file holds one mapping under the env id::

    MarineFormation-v0:
      algo: ppo                  # ppo | sac | td3 | a2c
      scenario: paper
      env_kwargs:                # any parallel_env override
        action_level: speed
        init_noise: {x: 40.0, y: 20.0, psi: 0.3, u: 1.0}
      n_envs: 16                 # formation copies (each vessel is one SB3 env entry)
      n_timesteps: 2.0e6         # vessel-steps (SB3 timesteps)
      policy: MlpPolicy
      normalize: true            # VecNormalize (or a mapping of its arguments)
      policy_kwargs: {net_arch: [64, 64], activation_fn: tanh}
      eval_freq: 100000          # vessel-steps between evaluations against the reference
      eval_episodes: 3
      checkpoint_freq: 500000
      learning_rate: 3.0e-4      # every other key is a hyperparameter of the algorithm
      n_steps: 128

Hyperparameter names are checked against the algorithm's constructor, env
overrides against :class:`~marine_formation_env.scenarios.ScenarioConfig`;
unknown keys raise :class:`TrainConfigError` naming them. ``learning_rate``
may be ``lin_<value>`` (linear decay to 0, as in the zoo); ``activation_fn`` is
a name (``tanh``, ``relu``, ``elu``, ``leaky_relu``).
"""

from __future__ import annotations

import copy
import inspect
import re
from pathlib import Path
from typing import Any

import yaml

from marine_formation_env import ENV_ID
from marine_formation_env.scenarios import ConfigError, make_config

__all__ = ["ALGOS", "SPECIAL_KEYS", "TrainConfigError", "algo_class", "apply_overrides", "load_config", "validate"]

#: Keys with a meaning for the training script (everything else goes to the algorithm).
SPECIAL_KEYS = {
    "algo": "ppo",
    "scenario": "paper",
    "env_kwargs": {},
    "n_envs": 8,
    "n_timesteps": 1_000_000,
    "policy": "MlpPolicy",
    "normalize": True,
    "policy_kwargs": {},
    "eval_freq": 100_000,
    "eval_episodes": 3,
    "checkpoint_freq": 500_000,
}

ALGOS = ("ppo", "sac", "td3", "a2c")
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")
_NOT_HYPERPARAMS = {"self", "policy", "env", "tensorboard_log", "verbose", "seed", "device", "_init_setup_model"}


class TrainConfigError(ValueError):
    """An invalid training configuration (names the offending key or value)."""


def algo_class(name: str) -> Any:
    """The SB3 algorithm class for ``name``."""
    import stable_baselines3 as sb3

    if name not in ALGOS:
        raise TrainConfigError(f"unknown algo {name!r}; choose one of {list(ALGOS)}")
    return getattr(sb3, name.upper())


class _Loader(yaml.SafeLoader):
    """YAML loader that reads ``3e6`` and ``3.0e6`` as floats (YAML 1.2), not as strings (YAML 1.1)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_config(path: str | Path) -> dict[str, Any]:
    """Read a config file and return its (unvalidated) mapping for ``MarineFormation-v0``."""
    path = Path(path)
    if not path.is_file():
        raise TrainConfigError(f"config file {str(path)!r} does not exist")
    data = yaml.load(path.read_text(), Loader=_Loader)
    if not isinstance(data, dict) or list(data) != [ENV_ID] or not isinstance(data[ENV_ID], dict):
        keys = list(data) if isinstance(data, dict) else type(data).__name__
        raise TrainConfigError(f"{path}: expected one mapping under {ENV_ID!r}, found {keys}")
    return dict(data[ENV_ID])


def apply_overrides(config: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """Apply ``{"a.b": value}`` overrides (dots address nested mappings) to a copy of ``config``."""
    out = copy.deepcopy(config)
    for dotted, value in overrides.items():
        node = out
        parts = dotted.split(".")
        for part in parts[:-1]:
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise TrainConfigError(f"--set {dotted}: {part!r} is not a mapping")
            node = child
        node[parts[-1]] = value
    return out


def validate(config: dict[str, Any]) -> dict[str, Any]:
    """Fill defaults and check every key and value; return the resolved config.

    Raises:
        TrainConfigError: unknown keys (hyperparameters, env overrides, policy
            kwargs), wrong types, or env overrides the env rejects.
    """
    resolved = {**copy.deepcopy(SPECIAL_KEYS), **copy.deepcopy(config)}
    cls = algo_class(resolved["algo"])
    allowed = set(inspect.signature(cls.__init__).parameters) - _NOT_HYPERPARAMS
    unknown = sorted(set(resolved) - set(SPECIAL_KEYS) - allowed)
    if unknown:
        raise TrainConfigError(
            f"unknown key(s) {unknown} for algo {resolved['algo']!r}; special keys: {sorted(SPECIAL_KEYS)}; "
            f"hyperparameters: {sorted(allowed)}"
        )
    for key in ("n_envs", "eval_episodes"):
        if not isinstance(resolved[key], int) or isinstance(resolved[key], bool) or resolved[key] < 1:
            raise TrainConfigError(f"{key} must be an integer ≥ 1, got {resolved[key]!r}")
    for key in ("n_timesteps", "eval_freq", "checkpoint_freq"):
        value = resolved[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise TrainConfigError(f"{key} must be a number ≥ 0, got {value!r}")
        resolved[key] = int(value)
    if not isinstance(resolved["env_kwargs"], dict):
        raise TrainConfigError(f"env_kwargs must be a mapping, got {resolved['env_kwargs']!r}")
    try:
        make_config(resolved["scenario"], **resolved["env_kwargs"])
    except ConfigError as err:
        raise TrainConfigError(f"env_kwargs: {err}") from None
    if not isinstance(resolved["policy_kwargs"], dict):
        raise TrainConfigError(f"policy_kwargs must be a mapping, got {resolved['policy_kwargs']!r}")
    act = resolved["policy_kwargs"].get("activation_fn")
    if act is not None and act not in ACTIVATIONS:
        raise TrainConfigError(f"policy_kwargs.activation_fn must be one of {list(ACTIVATIONS)}, got {act!r}")
    lr = resolved.get("learning_rate")
    if isinstance(lr, str):
        _parse_schedule(lr)
    norm = resolved["normalize"]
    if not isinstance(norm, (bool, dict)):
        raise TrainConfigError(f"normalize must be true/false or a mapping of VecNormalize arguments, got {norm!r}")
    return resolved


def _parse_schedule(value: str) -> float:
    if not value.startswith("lin_"):
        raise TrainConfigError(f"learning_rate must be a number or 'lin_<number>', got {value!r}")
    try:
        return float(value[4:])
    except ValueError:
        raise TrainConfigError(f"learning_rate must be a number or 'lin_<number>', got {value!r}") from None


def algo_kwargs(resolved: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments for the algorithm (hyperparameters and policy kwargs, built)."""
    import torch

    kwargs = {k: v for k, v in resolved.items() if k not in SPECIAL_KEYS}
    lr = kwargs.get("learning_rate")
    if isinstance(lr, str):
        start = _parse_schedule(lr)
        kwargs["learning_rate"] = lambda progress: progress * start
    policy_kwargs = dict(resolved["policy_kwargs"])
    if "activation_fn" in policy_kwargs:
        policy_kwargs["activation_fn"] = {
            "tanh": torch.nn.Tanh,
            "relu": torch.nn.ReLU,
            "elu": torch.nn.ELU,
            "leaky_relu": torch.nn.LeakyReLU,
        }[policy_kwargs["activation_fn"]]
    if policy_kwargs:
        kwargs["policy_kwargs"] = policy_kwargs
    return kwargs
