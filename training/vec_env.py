"""Parameter sharing for Stable-Baselines3 without SuperSuit.

``SharedPolicyVecEnv`` is an SB3 ``VecEnv`` in which every vessel of
every formation copy is one entry, so a single PPO/SAC policy drives all the
vessels, each from its own masked observation. It is a thin adapter over the
batched ``marine_formation_env.vector.MarineFormationVectorEnv`` in its
``agent`` layout with ``SAME_STEP`` autoreset: one batched physics path.

Entry ``b·N + j`` is vessel ``j`` of formation ``b``. A formation's vessels
finish together; their infos then carry ``terminal_observation`` (SB3's
convention) and ``TimeLimit.truncated``, and the returned observations are
already those of the next episode. ``seed(s)`` makes formation ``b`` start from
``s + b`` at the next ``reset()``, exactly as ``parallel_env(...).reset(seed=s + b)``.

``TeamsVecEnv`` puts several of them side by side (teams of different
sizes or graphs whose observations share one length, ``observation_slots``):
one policy trains on all of them at once.

``ResidualVecEnv`` makes the policy's action the learned part of a residual
policy (``baselines.residual``): each entry's env receives the extrapolating
reference's action, from the entry's own observation, plus the policy's,
gated by how far that observation is from formation (``residual_actions``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvStepReturn,
    VecEnvWrapper,
)

from baselines.residual import residual_actions, residual_base
from marine_formation_env.frontend import REWARD_INFO_KEYS
from marine_formation_env.scenarios import ScenarioConfig
from marine_formation_env.vector import MarineFormationVectorEnv

__all__ = ["ResidualVecEnv", "SharedPolicyVecEnv", "TeamsVecEnv"]


class SharedPolicyVecEnv(VecEnv):
    """``n_formations`` formations, one SB3 env entry per vessel (see the module docstring).

    Args:
        n_formations: number of formation copies B.
        scenario: scenario name; ``**overrides`` as for ``parallel_env``.
    """

    def __init__(self, n_formations: int = 1, scenario: str = "paper", **overrides: Any) -> None:
        self.venv = MarineFormationVectorEnv(
            num_envs=n_formations,
            scenario=scenario,
            layout="agent",
            autoreset_mode=AutoresetMode.SAME_STEP,
            **overrides,
        )
        self.config = self.venv.config
        self.dt = self.config.dt
        self.n_formations = n_formations
        self.n_vessels = self.config.n_vessels
        self.render_mode = None
        self._actions: np.ndarray | None = None
        self._formation_seed: int | None = None
        super().__init__(self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space)

    # -------------------------------------------------------------- stepping
    def reset(self) -> np.ndarray:
        obs, _ = self.venv.reset(seed=self._formation_seed)
        self._formation_seed = None
        self._reset_seeds()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        obs, reward, terminated, truncated, infos = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        final = infos.get("final_obs")
        components = {key: infos[key] for key in REWARD_INFO_KEYS}
        entry_infos: list[dict[str, Any]] = []
        for k in range(self.num_envs):
            info: dict[str, Any] = {key: float(v[k]) for key, v in components.items()}
            if dones[k]:
                info["terminal_observation"] = final[k] if final is not None else obs[k]
                info["TimeLimit.truncated"] = bool(truncated[k] and not terminated[k])
            entry_infos.append(info)
        return obs, reward.astype(np.float32), dones, entry_infos

    def set_initial_spread(self, scale: float) -> None:
        """The initial-state spread of later (auto)resets (a curriculum; ``MarineFormationVectorEnv``)."""
        self.venv.set_initial_spread(scale)

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset: formation ``b`` starts from ``seed + b`` (all its vessels share it)."""
        if seed is None:
            seed = int(np.random.default_rng().integers(0, 2**31 - 1))
        self._formation_seed = int(seed)
        return [seed + k // self.n_vessels for k in range(self.num_envs)]

    def close(self) -> None:
        self.venv.close()

    # ------------------------------------------------------------ attributes
    def _count(self, indices: VecEnvIndices) -> int:
        return len(list(self._get_indices(indices)))

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of the shared simulation, once per requested entry."""
        if attr_name == "render_mode":
            return [self.render_mode] * self._count(indices)
        return [getattr(self.venv, attr_name)] * self._count(indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the shared simulation (all entries share it)."""
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call a method of the shared simulation once; its result is returned for each requested entry."""
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result] * self._count(indices)

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * self._count(indices)

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs

    def _get_indices(self, indices: VecEnvIndices) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices


class TeamsVecEnv(VecEnv):
    """Several ``SharedPolicyVecEnv`` (teams) as one SB3 ``VecEnv``: their entries one after the other.

    Every team must have the same action space, control period and observation length (pad
    the observations with ``observation_slots``); the observation space is
    the smallest box that holds every team's (each team's bounds follow its
    workspace and formation). ``seed(s)`` seeds team ``k``
    with ``s + 100 000·k``, so no two teams' formations share a seed.

    Args:
        teams: the teams, in entry order.
    """

    #: Seed offset between consecutive teams.
    SEED_STRIDE = 100_000

    def __init__(self, teams: Sequence[SharedPolicyVecEnv]) -> None:
        if not teams:
            raise ValueError("TeamsVecEnv needs at least one team")
        first = teams[0]
        for k, team in enumerate(teams):
            shape = team.observation_space.shape
            if shape != first.observation_space.shape or team.action_space != first.action_space:
                raise ValueError(
                    f"team {k} has observations of shape {shape} and action space {team.action_space}, team 0 "
                    f"{first.observation_space.shape} and {first.action_space}: pad with observation_slots"
                )
        periods = sorted({team.dt for team in teams})
        if len(periods) > 1:
            raise ValueError(f"every team must have the same control period dt, got {periods}")
        boxes = [team.observation_space for team in teams]
        if not all(isinstance(box, gym.spaces.Box) for box in boxes):
            raise ValueError("every team's observation space must be a Box")
        low = np.min([box.low for box in boxes if isinstance(box, gym.spaces.Box)], axis=0)
        high = np.max([box.high for box in boxes if isinstance(box, gym.spaces.Box)], axis=0)
        self.teams = list(teams)
        self.dt = first.dt
        self.bounds = np.cumsum([0] + [team.num_envs for team in teams])
        self.render_mode = None
        space = gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        super().__init__(int(self.bounds[-1]), space, first.action_space)

    def reset(self) -> np.ndarray:
        obs = np.concatenate([team.reset() for team in self.teams])
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions)
        for k, team in enumerate(self.teams):
            team.step_async(actions[self.bounds[k] : self.bounds[k + 1]])

    def step_wait(self) -> VecEnvStepReturn:
        parts = [team.step_wait() for team in self.teams]
        infos: list[dict[str, Any]] = []
        for part in parts:
            infos.extend(part[3])
        return (
            np.concatenate([p[0] for p in parts]),
            np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] for p in parts]),
            infos,
        )

    def set_initial_spread(self, scale: float) -> None:
        """The initial-state spread of every team's later (auto)resets."""
        for team in self.teams:
            team.set_initial_spread(scale)

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        if seed is None:
            seed = int(np.random.default_rng().integers(0, 2**31 - 1 - self.SEED_STRIDE * len(self.teams)))
        out: list[int | None] = []
        for k, team in enumerate(self.teams):
            out.extend(team.seed(seed + self.SEED_STRIDE * k))
        return out

    def close(self) -> None:
        for team in self.teams:
            team.close()

    def _entries(self, indices: VecEnvIndices) -> list[tuple[SharedPolicyVecEnv, int]]:
        if indices is None:
            chosen: Iterable[int] = range(self.num_envs)
        elif isinstance(indices, int):
            chosen = [indices]
        else:
            chosen = indices
        out = []
        for i in chosen:
            k = int(np.searchsorted(self.bounds, i, side="right")) - 1
            out.append((self.teams[k], i - int(self.bounds[k])))
        return out

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [team.get_attr(attr_name, local)[0] for team, local in self._entries(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute on every team holding one of ``indices`` (a team's entries share one simulation)."""
        for team in {id(t): t for t, _ in self._entries(indices)}.values():
            team.set_attr(attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        return [team.env_method(method_name, *method_args, indices=local, **method_kwargs)[0]
                for team, local in self._entries(indices)]  # fmt: skip

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._entries(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs


class ResidualVecEnv(VecEnvWrapper):
    """The env of a residual policy's learned part: the policy's action is the correction ``residual_actions`` adds.

    Args:
        venv: a ``SharedPolicyVecEnv`` or ``TeamsVecEnv`` (raw observations: wrap it before ``VecNormalize``).
        config: the policy's training configuration (``baselines.residual.residual_base``).
    """

    def __init__(self, venv: VecEnv, config: ScenarioConfig) -> None:
        super().__init__(venv)
        self.base = residual_base(config)
        self._obs: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        obs = np.asarray(self.venv.reset())
        self._obs = obs
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        if self._obs is None:
            raise RuntimeError("step_async() called before reset()")
        self.venv.step_async(residual_actions(self.base, self._obs, actions))

    def step_wait(self) -> VecEnvStepReturn:
        obs, reward, dones, infos = self.venv.step_wait()
        # after an autoreset, the next episode's first observation: what the next action reads
        self._obs = np.asarray(obs)
        return obs, reward, dones, infos
