"""Training configuration: YAML keyed like rl-baselines3-zoo, validated, no ``eval``.

A config file holds one mapping under the env id::

    MarineFormation-v1:
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

``teams`` (a list of env overrides, default empty) trains one policy on
several teams at once: each item, laid over ``env_kwargs``, is a team of its
own with ``n_envs`` formations (``{n_vessels: 5, topology: random,
topology_seed: 2}``); a team's ``scenario`` names the preset it starts from
instead of the config's (``{scenario: acoustic, n_vessels: 5}``). ``env_kwargs`` itself (the scenario of evaluations and
exports) gets the largest team's ``observation_slots`` unless it sets them,
every team inherits them, and a team with another observation length or
level is refused; the policy must read slots (``features_extractor_class:
slots``, ``training.slot_policy``, with ``normalize: {norm_obs: false}``).

``train_reward`` (a mapping of reward fields, default empty) shapes the reward
the learner trains on and nothing else, as in ``training.torchrl_ppo``:
``train_reward: {sigma_cross_track: 5.0, sigma_coordination: 5.0}`` trains
every team on 5 m scales, while evaluations, checkpoints' headers and exports
keep ``env_kwargs``'s reward, the benchmark's.
``residual: true`` trains the learned part of a residual policy
(``baselines.residual``): the env receives the extrapolating reference's
action plus the network's, gated to vanish in formation, so a network that
outputs zero is the paper's controller; evaluations, checkpoints and exports
act the same way.
``algo: ppo`` is ``training.smoothness.SmoothPPO``, SB3's PPO with one more
hyperparameter, ``temporal_smoothness`` (λ ≥ 0, default 0: PPO itself), a
regularizer on the change of the policy's mean action between consecutive
observations that leaves the reward alone (CAPS' temporal term).

Hyperparameter names are checked against the algorithm's constructor, env
overrides against ``ScenarioConfig``;
unknown keys raise ``TrainConfigError`` naming them. ``learning_rate``
may be ``lin_<value>`` (linear decay to 0, as in the zoo; with a wall-clock budget, over whichever of
it and ``n_timesteps`` runs out first: ``training.callbacks.BudgetSchedule``); ``activation_fn`` is
a name (``tanh``, ``relu``, ``elu``, ``leaky_relu``), and so is
``features_extractor_class`` (``slots``: ``training.slot_policy.SlotFeatures``).

Values SB3 or torch would choke on (or, worse, accept and fail on much later)
are refused here by name: ``n_steps``, ``batch_size``, ``n_epochs``,
``buffer_size``, ... must be whole numbers ≥ 1; ``gamma``, ``gae_lambda``,
``tau`` lie in [0, 1]; ``learning_rate``, ``clip_range``, ``max_grad_norm`` are
positive; ``policy_kwargs.net_arch`` is a list of positive whole numbers (or a
mapping of such lists, ``pi``/``vf`` for PPO and A2C, ``pi``/``qf`` for SAC
and TD3); ``policy`` is one of the algorithm's ``policy_aliases``.
``training.train`` then builds the algorithm once on the real env and reports
whatever else its constructor rejects. Malformed YAML is reported with the
file name and the parser's line and column.
"""

from __future__ import annotations

import copy
import inspect
import math
import re
from pathlib import Path
from typing import Any

import yaml

from marine_formation_env import ENV_ID
from marine_formation_env.cli import int_at_least, parse_overrides, report_error
from marine_formation_env.scenarios import ConfigError, make_config

__all__ = [
    "ALGOS",
    "RENAMED_KEYS",
    "RESUMABLE_KEYS",
    "SPECIAL_KEYS",
    "TrainConfigError",
    "algo_class",
    "apply_overrides",
    "check_curriculum",
    "check_ppo_keys",
    "check_renamed",
    "check_train_reward",
    "config_differences",
    "curriculum_spread",
    "load_config",
    "team_overrides",
    "training_env_kwargs",
    "validate",
]

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
    "teams": [],
    "train_reward": {},
    "initial_state_curriculum": None,
    "transmit_bias": None,
    "residual": False,
}

#: Keys a resumed run may change (``python -m training.train --resume --set ...``); nothing else.
RESUMABLE_KEYS = ("n_timesteps", "eval_freq", "eval_episodes", "checkpoint_freq")

ALGOS = ("ppo", "sac", "td3", "a2c")
#: Hyperparameters that must be whole numbers ≥ 1 (when the algorithm has them).
POSITIVE_INTS = (
    "n_steps",
    "batch_size",
    "n_epochs",
    "buffer_size",
    "target_update_interval",
    "policy_delay",
    "stats_window_size",
    "temporal_smoothness_pairs",
)
#: Hyperparameters that must be numbers in a closed interval; ``None`` means unbounded.
NUMBER_RANGES: dict[str, tuple[float | None, float | None]] = {
    "gamma": (0.0, 1.0),
    "gae_lambda": (0.0, 1.0),
    "tau": (0.0, 1.0),
    "vf_coef": (0.0, None),
    "target_policy_noise": (0.0, None),
    "target_noise_clip": (0.0, None),
    "temporal_smoothness": (0.0, None),
}
#: Hyperparameters that must be numbers > 0.
POSITIVE_NUMBERS = ("learning_rate", "clip_range", "max_grad_norm")
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")
#: Names of ``policy_kwargs.features_extractor_class``.
EXTRACTORS = ("slots",)
_NOT_HYPERPARAMS = {"self", "policy", "env", "tensorboard_log", "verbose", "seed", "device", "_init_setup_model"}


class TrainConfigError(ValueError):
    """An invalid training configuration (names the offending key or value)."""


#: Keys the TorchRL and RLlib trainers once had, with the one name all three trainers now use (SB3's).
RENAMED_KEYS = {
    "num_envs": "n_envs",
    "num_envs_per_env_runner": "n_envs",
    "lr": "learning_rate",
    "lr_schedule": "learning_rate",
    "lmbda": "gae_lambda",
    "lambda": "gae_lambda",
    "clip_epsilon": "clip_range",
    "clip_param": "clip_range",
    "entropy_coef": "ent_coef",
    "entropy_coeff": "ent_coef",
    "epochs": "n_epochs",
    "num_epochs": "n_epochs",
    "grad_clip": "max_grad_norm",
}


def check_renamed(raw: dict[str, Any], renamed: dict[str, str] | None = None) -> None:
    """Refuse a config that still uses an old key (``RENAMED_KEYS``, or ``renamed``), naming the new one."""
    table = RENAMED_KEYS if renamed is None else renamed
    for old in raw:
        if old in table:
            new = table[old]
            hint = " (a linear schedule is learning_rate: lin_<rate>)" if old == "lr_schedule" else ""
            raise TrainConfigError(f"the key {old!r} is now {new!r}{hint}; rename it in the config or --set")


def algo_class(name: str) -> Any:
    """The SB3 algorithm class for ``name``."""
    import stable_baselines3 as sb3

    if name not in ALGOS:
        raise TrainConfigError(f"unknown algo {name!r}; choose one of {list(ALGOS)}")
    if name == "ppo":  # PPO with one more hyperparameter, temporal_smoothness (default 0: PPO itself)
        from training.smoothness import SmoothPPO

        return SmoothPPO
    return getattr(sb3, name.upper())


def hyperparameter_names(cls: Any) -> set[str]:
    """The constructor arguments of an algorithm class and of the bases it passes ``**kwargs`` on to."""
    names: set[str] = set()
    for klass in cls.__mro__:
        if "__init__" not in vars(klass):
            continue
        params = inspect.signature(klass.__init__).parameters.values()
        names |= {p.name for p in params if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)}
        if not any(p.kind == p.VAR_KEYWORD for p in params):
            break
    return names - _NOT_HYPERPARAMS


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
    """Read a config file and return its (unvalidated) mapping for ``MarineFormation-v1``.

    Raises:
        TrainConfigError: a missing or unreadable file, malformed YAML (with the
            parser's line and column), or not one mapping under the env id.
    """
    path = Path(path)
    if not path.is_file():
        raise TrainConfigError(f"config file {str(path)!r} does not exist")
    try:
        data = yaml.load(path.read_text(encoding="utf-8"), Loader=_Loader)
    except UnicodeDecodeError as err:
        raise TrainConfigError(f"config file {str(path)!r} is not UTF-8 ({err.reason} at byte {err.start})") from None
    except yaml.YAMLError as err:
        raise TrainConfigError(f"config file {str(path)!r} is not valid YAML: {_yaml_problem(err)}") from None
    if isinstance(data, dict) and len(data) == 1 and str(next(iter(data))).startswith("MarineFormation-v"):
        found = str(next(iter(data)))
        if found != ENV_ID:
            raise TrainConfigError(
                f"{path}: the config is for {found}, but this version of the package has {ENV_ID} (the observation "
                "layout changed: docs/CHANGELOG.md); check the config and rename its key"
            )
    if not isinstance(data, dict) or list(data) != [ENV_ID] or not isinstance(data[ENV_ID], dict):
        keys = list(data) if isinstance(data, dict) else type(data).__name__
        raise TrainConfigError(f"{path}: expected one mapping under {ENV_ID!r}, found {keys}")
    return dict(data[ENV_ID])


def _yaml_problem(err: yaml.YAMLError) -> str:
    """``line L, column C: <problem>`` (1-based, where the parser stopped) from a PyYAML error."""
    if isinstance(err, yaml.MarkedYAMLError):
        mark = err.problem_mark or err.context_mark
        problem = " ".join(part for part in (err.context, err.problem) if part) or "syntax error"
        if mark is not None:
            return f"line {mark.line + 1}, column {mark.column + 1}: {problem}"
        return problem
    return " ".join(str(err).split())


def config_differences(old: Any, new: Any, prefix: str = "") -> list[tuple[str, Any, Any]]:
    """``(dotted key, old value, new value)`` for every leaf where two configs differ (missing = None)."""
    if isinstance(old, dict) and isinstance(new, dict):
        out: list[tuple[str, Any, Any]] = []
        for key in list(old) + [k for k in new if k not in old]:
            out.extend(config_differences(old.get(key), new.get(key), f"{prefix}{key}."))
        return out
    if (old == new and type(old) is type(new)) or _same_number(old, new):
        return []
    return [(prefix[:-1], old, new)]


def _same_number(a: Any, b: Any) -> bool:
    numbers = (int, float)
    return (
        isinstance(a, numbers) and isinstance(b, numbers) and not isinstance(a, bool) and not isinstance(b, bool)
        and a == b
    )  # fmt: skip


def team_overrides(resolved: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """The preset and env overrides of each team of a resolved config (no ``teams``: the config's scenario
    and ``env_kwargs`` alone).

    With ``teams``, each team is its ``scenario`` (the config's if it names none) with ``env_kwargs`` and the
    team's other overrides on top, and ``validate`` has given ``env_kwargs`` (the scenario of evaluations
    and exports) the largest team's ``observation_slots``, which every team inherits unless it sets its own.
    """
    teams = resolved.get("teams") or [{}]
    return [
        (
            team.get("scenario", resolved["scenario"]),
            {**resolved["env_kwargs"], **{key: value for key, value in team.items() if key != "scenario"}},
        )
        for team in teams
    ]


def training_env_kwargs(cfg: dict[str, Any], env_kwargs: dict[str, Any] | None = None) -> dict[str, Any]:
    """The env overrides the learner trains on: ``env_kwargs`` with ``train_reward``'s fields in its reward.

    ``env_kwargs`` defaults to the config's own (the scenario of evaluations); pass a team's overrides
    (``team_overrides``) to shape that team's reward. Evaluations and exports never see the shaping.
    """
    base = cfg["env_kwargs"] if env_kwargs is None else env_kwargs
    if not cfg["train_reward"]:
        return dict(base)
    return {**base, "reward": {**base.get("reward", {}), **cfg["train_reward"]}}


def check_train_reward(cfg: dict[str, Any]) -> None:
    """``train_reward`` must be a mapping that merges into every training env's reward, with fields and values
    the scenario's resolver accepts (it names a bad one)."""
    shaped = cfg["train_reward"]
    if not isinstance(shaped, dict):
        raise TrainConfigError(f"train_reward must be a mapping of reward fields, got {shaped!r}")
    if not shaped:
        return
    for scenario, kw in team_overrides(cfg):  # env_kwargs alone without teams (the TorchRL trainer's case)
        if not isinstance(kw.get("reward", {}), dict):
            raise TrainConfigError(f"train_reward needs env_kwargs.reward to be a mapping, got {kw['reward']!r}")
        try:
            make_config(scenario, **training_env_kwargs(cfg, kw))
        except (ValueError, TypeError) as err:
            raise TrainConfigError(f"train_reward {shaped}: {err}") from err


def _transmit_bias(value: Any, transmit: bool, algo: str) -> float | None:
    """``transmit_bias`` checked: null, or a number for a Gaussian policy (ppo, a2c) of a scenario whose action
    has the ``transmit`` entry."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise TrainConfigError(f"transmit_bias must be a number or null, got {value!r}")
    if not transmit:
        raise TrainConfigError(
            f"transmit_bias = {value!r} sets the transmit entry's initial mean, but the action has none"
            " (set env_kwargs: {transmit: true})"
        )
    if algo not in ("ppo", "a2c"):
        raise TrainConfigError(f"transmit_bias sets a Gaussian policy's mean (ppo, a2c), not {algo}'s")
    return float(value)


def check_curriculum(value: Any) -> dict[str, float] | None:
    """``initial_state_curriculum`` checked: null, or ``{start: [0, 1], until: (0, 1]}`` (both keys).

    The learner's env starts its formations ``start + (1 − start) · min(1, used / until)`` of the way from
    the formation on its lanes to the scenario's initial state, ``used`` being the fraction of the run's
    budget spent (``curriculum_spread``); both trainers take it.
    """
    if value is None:
        return None
    key = "initial_state_curriculum"
    if not isinstance(value, dict) or set(value) != {"start", "until"}:
        raise TrainConfigError(f"{key} must be null or a mapping with the keys start and until, got {value!r}")
    start = _fraction(f"{key}.start", value["start"])
    until = _fraction(f"{key}.until", value["until"])
    if until == 0.0:
        raise TrainConfigError(f"{key}.until must lie in (0, 1], got {value['until']!r}")
    return {"start": start, "until": until}


def budget_fraction(done: float, total: float, elapsed: float, seconds: float | None) -> float:
    """The fraction of a budget spent, whichever of its two parts runs out first.

    ``max(done / total, elapsed / seconds)``: steps or frames ``done`` of ``total``, and wall-clock
    ``elapsed`` of ``seconds`` (None: steps only). Not capped at 1.
    """
    used = done / total
    if seconds is not None:
        used = max(used, elapsed / seconds)
    return float(used)


def curriculum_spread(curriculum: dict[str, float] | None, used: float) -> float:
    """The initial-state spread once the fraction ``used`` of the budget is spent (no curriculum: 1)."""
    if curriculum is None:
        return 1.0
    start, until = curriculum["start"], curriculum["until"]
    return float(start + (1.0 - start) * min(1.0, used / until))


def _check_teams(resolved: dict[str, Any]) -> None:
    """Check ``teams``; pad ``env_kwargs`` (and so every team) to the largest team's slots; one layout for all."""
    teams = resolved["teams"]
    if not isinstance(teams, list) or not all(isinstance(team, dict) for team in teams):
        raise TrainConfigError(f"teams must be a list of mappings of env overrides, got {teams!r}")
    if not teams:
        return
    sizes = []
    for k, (scenario, kw) in enumerate(team_overrides(resolved)):  # each team on its own first, so an error names it
        try:
            sizes.append(make_config(scenario, **kw).n_vessels)  # an unknown preset too
        except ConfigError as err:
            raise TrainConfigError(f"teams[{k}]: {err}") from None
    if "observation_slots" not in resolved["env_kwargs"]:
        base = make_config(resolved["scenario"], **resolved["env_kwargs"]).n_vessels
        resolved["env_kwargs"] = {**resolved["env_kwargs"], "observation_slots": max([base, *sizes]) - 1}
    try:
        reference = make_config(resolved["scenario"], **resolved["env_kwargs"])
    except ConfigError as err:
        raise TrainConfigError(f"env_kwargs: {err}") from None
    layout = (reference.observation_slots, reference.action_level)
    for k, (scenario, kw) in enumerate(team_overrides(resolved)):
        try:
            cfg = make_config(scenario, **kw)
        except ConfigError as err:
            raise TrainConfigError(f"teams[{k}]: {err}") from None
        if (cfg.observation_slots, cfg.action_level) != layout:
            raise TrainConfigError(
                f"teams[{k}] has observation_slots = {cfg.observation_slots} and action_level "
                f"{cfg.action_level!r}, env_kwargs (the scenario of evaluations) {layout[0]} and {layout[1]!r}: "
                "every team needs the same observation length and level"
            )


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
    check_renamed(config)
    resolved = {**copy.deepcopy(SPECIAL_KEYS), **copy.deepcopy(config)}
    cls = algo_class(resolved["algo"])
    allowed = hyperparameter_names(cls)
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
        scenario = make_config(resolved["scenario"], **resolved["env_kwargs"])
    except ConfigError as err:
        raise TrainConfigError(f"env_kwargs: {err}") from None
    resolved["transmit_bias"] = _transmit_bias(resolved["transmit_bias"], scenario.transmit, resolved["algo"])
    if not isinstance(resolved["residual"], bool):
        raise TrainConfigError(f"residual must be true or false, got {resolved['residual']!r}")
    if resolved["residual"] and scenario.transmit:
        raise TrainConfigError(
            "residual: true adds the reference's action, and the reference sends no transmit entry "
            "(the scenario has transmit = true)"
        )
    if not isinstance(resolved["policy_kwargs"], dict):
        raise TrainConfigError(f"policy_kwargs must be a mapping, got {resolved['policy_kwargs']!r}")
    act = resolved["policy_kwargs"].get("activation_fn")
    if act is not None and act not in ACTIVATIONS:
        raise TrainConfigError(f"policy_kwargs.activation_fn must be one of {list(ACTIVATIONS)}, got {act!r}")
    extractor = resolved["policy_kwargs"].get("features_extractor_class")
    if extractor is not None and extractor not in EXTRACTORS:
        raise TrainConfigError(
            f"policy_kwargs.features_extractor_class must be one of {list(EXTRACTORS)}, got {extractor!r}"
        )
    norm = resolved["normalize"]
    normalized = norm is True or (isinstance(norm, dict) and norm.get("norm_obs", True))
    if extractor == "slots" and normalized:
        raise TrainConfigError(
            "policy_kwargs.features_extractor_class 'slots' reads the link bits of raw observations: "
            f"set normalize: {{norm_obs: false}} (got normalize = {norm!r})"
        )
    _check_teams(resolved)
    check_train_reward(resolved)
    resolved["initial_state_curriculum"] = check_curriculum(resolved["initial_state_curriculum"])
    lr = resolved.get("learning_rate")
    if isinstance(lr, str):
        parse_schedule(lr)
    norm = resolved["normalize"]
    if not isinstance(norm, (bool, dict)):
        raise TrainConfigError(f"normalize must be true/false or a mapping of VecNormalize arguments, got {norm!r}")
    _check_policy(resolved, cls)
    _check_hyperparameters(resolved)
    return resolved


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _whole(key: str, value: Any, minimum: int) -> int:
    """``value`` as an int if it is a whole number ≥ ``minimum`` (``1e3`` and ``1000.0`` count), else raise."""
    if _is_number(value) and float(value).is_integer() and value >= minimum:
        return int(value)
    raise TrainConfigError(f"{key} must be a whole number ≥ {minimum}, got {value!r}")


def _is_whole(value: Any) -> bool:
    return _is_number(value) and math.isfinite(value) and float(value).is_integer()


def _number(key: str, value: Any) -> float:
    """``value`` as a float if it is a finite number (not a bool), else raise naming ``key``."""
    if not _is_number(value) or not math.isfinite(value):
        raise TrainConfigError(f"{key} must be a finite number, got {value!r}")
    return float(value)


def _positive(key: str, value: Any) -> float:
    """``value`` as a float if it is a finite number > 0, else raise naming ``key``."""
    number = _number(key, value)
    if number <= 0:
        raise TrainConfigError(f"{key} must be > 0, got {value!r}")
    return number


def _fraction(key: str, value: Any) -> float:
    """``value`` as a float if it is a number in [0, 1] (a discount, a GAE λ), else raise naming ``key``."""
    number = _number(key, value)
    if not 0.0 <= number <= 1.0:
        raise TrainConfigError(f"{key} must lie in [0, 1], got {value!r}")
    return number


def _non_negative(key: str, value: Any) -> float:
    """``value`` as a float if it is a finite number ≥ 0 (an entropy coefficient), else raise naming ``key``."""
    number = _number(key, value)
    if number < 0:
        raise TrainConfigError(f"{key} must be ≥ 0, got {value!r}")
    return number


def check_ppo_keys(cfg: dict[str, Any]) -> None:
    """Check, in place, the PPO keys the TorchRL and RLlib trainers share with SB3 and mean alike:
    ``clip_range`` and ``max_grad_norm`` > 0, ``gamma`` and ``gae_lambda`` in [0, 1], ``ent_coef`` ≥ 0."""
    for key in ("clip_range", "max_grad_norm"):
        cfg[key] = _positive(key, cfg[key])
    for key in ("gamma", "gae_lambda"):
        cfg[key] = _fraction(key, cfg[key])
    cfg["ent_coef"] = _non_negative("ent_coef", cfg["ent_coef"])


def _hidden(value: Any) -> list[int]:
    """Hidden layer sizes: a non-empty list of whole numbers ≥ 1."""
    if not isinstance(value, list) or not value or not all(_is_whole(h) and h >= 1 for h in value):
        raise TrainConfigError(f"hidden must be a non-empty list of whole numbers ≥ 1, got {value!r}")
    return [int(h) for h in value]


def _check_policy(resolved: dict[str, Any], cls: Any) -> None:
    policy = resolved["policy"]
    aliases = sorted(getattr(cls, "policy_aliases", {}))
    if not isinstance(policy, str) or policy not in aliases:
        raise TrainConfigError(f"policy must be one of {aliases} for algo {resolved['algo']!r}, got {policy!r}")
    net_arch = resolved["policy_kwargs"].get("net_arch")
    if net_arch is None:
        return
    heads = ("pi", "vf") if resolved["algo"] in ("ppo", "a2c") else ("pi", "qf")
    expected = f"a list of whole numbers ≥ 1 or a mapping with keys {list(heads)} of such lists"

    def layers(value: Any) -> bool:
        return isinstance(value, list) and all(_is_number(v) and float(v).is_integer() and v >= 1 for v in value)

    if isinstance(net_arch, dict):
        ok = set(net_arch) <= set(heads) and bool(net_arch) and all(layers(v) for v in net_arch.values())
    else:
        ok = layers(net_arch)
    if not ok:
        raise TrainConfigError(f"policy_kwargs.net_arch must be {expected}, got {net_arch!r}")
    if isinstance(net_arch, dict):
        resolved["policy_kwargs"]["net_arch"] = {k: [int(v) for v in vals] for k, vals in net_arch.items()}
    else:
        resolved["policy_kwargs"]["net_arch"] = [int(v) for v in net_arch]


def _check_hyperparameters(resolved: dict[str, Any]) -> None:
    value: Any
    for key in POSITIVE_INTS:
        if key in resolved:
            resolved[key] = _whole(key, resolved[key], 1)
    if "learning_starts" in resolved:
        resolved["learning_starts"] = _whole("learning_starts", resolved["learning_starts"], 0)
    if "gradient_steps" in resolved:
        value = resolved["gradient_steps"]
        if not (_is_number(value) and float(value).is_integer() and (value >= 1 or value == -1)):
            raise TrainConfigError(f"gradient_steps must be a whole number ≥ 1 or -1, got {value!r}")
        resolved["gradient_steps"] = int(value)
    if "train_freq" in resolved:
        value = resolved["train_freq"]
        if isinstance(value, (list, tuple)):
            if len(value) != 2 or value[1] not in ("step", "episode"):
                raise TrainConfigError(f"train_freq must be a whole number ≥ 1 or [n, 'step'|'episode'], got {value!r}")
            resolved["train_freq"] = (_whole("train_freq", value[0], 1), value[1])
        else:
            resolved["train_freq"] = _whole("train_freq", value, 1)
    for key, (low, high) in NUMBER_RANGES.items():
        if key not in resolved:
            continue
        value = resolved[key]
        valid = _is_number(value) and math.isfinite(value)
        if not valid or (low is not None and value < low) or (high is not None and value > high):
            bounds = f"in [{low}, {high}]" if high is not None else f"≥ {low}"
            raise TrainConfigError(f"{key} must be a number {bounds}, got {value!r}")
    for key in POSITIVE_NUMBERS:
        value = resolved.get(key)
        if key not in resolved or (key == "learning_rate" and isinstance(value, str)):
            continue  # 'lin_<x>' schedules are checked above
        if not _is_number(value) or not value > 0:
            raise TrainConfigError(f"{key} must be a number > 0, got {value!r}")
    ent: Any = resolved.get("ent_coef")
    auto = resolved["algo"] == "sac" and isinstance(ent, str) and ent.startswith("auto")
    if "ent_coef" in resolved and not ((_is_number(ent) and ent >= 0) or auto):
        raise TrainConfigError(f"ent_coef must be a number ≥ 0 (or 'auto' for sac), got {ent!r}")


def parse_schedule(value: str) -> float:
    """The start of a ``lin_<rate>`` learning rate (falls linearly to 0); refuses anything else by name."""
    if not value.startswith("lin_"):
        raise TrainConfigError(f"learning_rate must be a number or 'lin_<number>', got {value!r}")
    try:
        start = float(value[4:])
    except ValueError:
        raise TrainConfigError(f"learning_rate must be a number or 'lin_<number>', got {value!r}") from None
    if not start > 0:
        raise TrainConfigError(f"learning_rate must be > 0, got {value!r}")
    return start


def algo_kwargs(resolved: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments for the algorithm (hyperparameters and policy kwargs, built)."""
    import torch

    kwargs = {k: v for k, v in resolved.items() if k not in SPECIAL_KEYS}
    lr = kwargs.get("learning_rate")
    if isinstance(lr, str):
        start = parse_schedule(lr)
        kwargs["learning_rate"] = lambda progress: progress * start
    policy_kwargs = dict(resolved["policy_kwargs"])
    if "activation_fn" in policy_kwargs:
        policy_kwargs["activation_fn"] = {
            "tanh": torch.nn.Tanh,
            "relu": torch.nn.ReLU,
            "elu": torch.nn.ELU,
            "leaky_relu": torch.nn.LeakyReLU,
        }[policy_kwargs["activation_fn"]]
    if policy_kwargs.get("features_extractor_class") == "slots":
        from training.slot_policy import SlotFeatures

        policy_kwargs["features_extractor_class"] = SlotFeatures
    if policy_kwargs:
        kwargs["policy_kwargs"] = policy_kwargs
    return kwargs


def add_run_arguments(parser: Any) -> None:
    """The options every trainer of a run folder takes: ``--config``, ``--set``, ``--seed``, ``--out``, ...

    Shared by ``training.torchrl_ppo`` and ``training.rllib_ppo``; read them back with ``config_from_arguments``.
    """
    parser.add_argument("--config", type=Path, default=None, help="YAML file (a mapping under MarineFormation-v1)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override; dots nest")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="seed of the run (default 0)")
    parser.add_argument("--out", type=Path, required=True, help="run folder")
    parser.add_argument("--overwrite", action="store_true", help="replace the run folder's files")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def config_from_arguments(args: Any, resolve: Any, prog: str) -> dict[str, Any]:
    """The resolved config of ``add_run_arguments``' options (the file, then ``--set``, then ``resolve``).

    A bad file, override or value ends the program with one line naming it (``prog: error: ...``).
    """
    try:
        raw = load_config(args.config) if args.config is not None else {}
        raw = apply_overrides(dict(raw), parse_overrides(args.set, nest=False))
        resolved: dict[str, Any] = resolve(raw, args.seed)
    except (TrainConfigError, ValueError, KeyError, OSError) as err:
        report_error(prog, str(err))
    return resolved
