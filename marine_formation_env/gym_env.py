"""Centralized single-agent view: one gymnasium Env controls the whole formation.

``gymnasium.make("MarineFormation-v1", **overrides)`` returns
``MarineFormationGymEnv``. It is the same simulation as the PettingZoo
env (a one-formation view of ``FormationCore``),
with everything joined:

* observation ``Box((N·dim,), float32)``: the N vessels' *masked* observations
  concatenated in vessel order (vessel ``j`` occupies ``[j·dim, (j+1)·dim)``);
  the layout of each block is the table of
  ``MarineFormationParallelEnv``;
* action ``Box(-1, 1, (N·A,), float32)``: vessel ``j``'s action in
  ``[j·A, (j+1)·A)``, same maps as the ParallelEnv;
* reward: the mean of the vessels' rewards (the shared team reward);
  ``info["vessel_rewards"]`` holds them all, ``info["reward_<term>"]``
  the vessel-averaged terms (they sum to the reward); ``time``,
  ``collision``, ``out_of_bounds`` and (``speed``, ``guidance``) the
  ``commanded_speed`` of each vessel complete the per-formation info schema of
  ``marine_formation_env.frontend``, also returned by ``reset()`` with zeros;
* termination and truncation: as the ParallelEnv (whole formation).

Because each block is masked by the graph, a centralized policy still receives
only what the vessels would; it may however combine the blocks, which a
decentralized one cannot.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from marine_formation_env.actions import action_space
from marine_formation_env.core import StepOutput, reset_output
from marine_formation_env.errors import float_array
from marine_formation_env.frontend import (
    Rendering,
    action_size_hint,
    formation_infos,
    one_entry,
    open_front_end,
    read_reset,
    vessel_mean,
)
from marine_formation_env.observations import observation_space
from marine_formation_env.scenarios import ScenarioConfig, sample_initial_state

__all__ = ["MarineFormationGymEnv"]


class MarineFormationGymEnv(gym.Env[np.ndarray, np.ndarray]):
    """The whole formation as one gymnasium agent (see the module docstring).

    Args:
        scenario: scenario name (``**overrides`` as for ``parallel_env``), or a ready
            ``ScenarioConfig`` (no overrides).
        render_mode: ``"rgb_array"`` or ``"human"``.
        render_speedup: ``metadata["render_fps"]`` is ``render_speedup / dt``: real time at 1.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}  # noqa: RUF012 - gymnasium API

    def __init__(
        self,
        scenario: str | ScenarioConfig = "paper",
        render_mode: str | None = None,
        backend: str = "auto",
        render_speedup: float = 1.0,
        **overrides: Any,
    ) -> None:
        front = open_front_end(type(self).metadata, scenario, overrides, render_mode, render_speedup, backend)
        self.config, self.metadata, self.core = front
        self.render_mode = render_mode
        self.observation_space = observation_space(self.config, joint=True)
        self.action_space = action_space(self.config, joint=True)
        self._rendering = Rendering(self.config, render_mode)
        self._done = True

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode (seeding as ``MarineFormationParallelEnv.reset``).

        ``options={"initial_state": (n, 6)}`` sets the state exactly,
        ``options={"channel_seed": int}`` seeds the channel stream on its own;
        bad input raises as there (``marine_formation_env.frontend``).
        """
        request = read_reset(self.config, seed, options)  # every check before anything changes
        super().reset(seed=request.seeds[0])
        initial = request.initial_state
        if initial is None:
            initial = sample_initial_state(self.config, self.np_random)
        self.core.seed_channel(request.channel_seeds)
        obs = self.core.reset(initial)
        self._done = False
        if self.render_mode == "human":
            self.render()
        return obs[0].reshape(-1), self._info(
            reset_output(obs, self.config.action_level != "force", self.core.messages())
        )

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the joint action ``(N·A,)`` for one control period."""
        if self._done:
            raise RuntimeError("the episode has ended (or never started); call reset() before step()")
        arr = float_array(action, "action")
        if arr.shape != self.action_space.shape:
            n = self.config.n_vessels
            hint = action_size_hint(self.config, arr.size // n) if arr.size % n == 0 else ""
            raise ValueError(f"action must have shape {self.action_space.shape}, got {arr.shape}{hint}")
        out = self.core.step(arr.reshape(1, self.config.n_vessels, self.config.action_dim))
        terminated, truncated = bool(out.terminated[0]), bool(out.truncated[0])
        self._done = terminated or truncated
        if self.render_mode == "human":
            self.render()
        reward = float(vessel_mean(out.reward)[0])
        return out.observation[0].reshape(-1), reward, terminated, truncated, self._info(out)

    def render(self, mode: str | None = None) -> np.ndarray | None:
        """Draw the formation: ``rgb_array`` returns an ``(H, W, 3)`` uint8 image (even H and W);
        ``mode`` is accepted and ignored (the constructor's ``render_mode`` decides)."""
        return self._rendering.frame(self.core)

    @property
    def max_steps(self) -> int:
        """Control periods per episode (``horizon / dt``): the step at which it is truncated."""
        return self.config.max_steps

    def close(self) -> None:
        self._rendering.close()

    def _info(self, out: StepOutput) -> dict[str, Any]:
        """The info in the per-formation schema (``marine_formation_env.frontend``)."""
        return one_entry(formation_infos(out, self.core.time), (0,))
