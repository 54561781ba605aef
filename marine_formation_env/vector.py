"""Gymnasium VectorEnv over the batched core: many formations in one call.

``MarineFormationVectorEnv(num_envs=B, ...)`` steps ``B`` formations of the
scenario at once with ``FormationCore``. It is
the ``vector_entry_point`` of ``MarineFormation-v1``::

    envs = gymnasium.make_vec("MarineFormation-v1", num_envs=64, vectorization_mode="vector_entry_point",
                              action_level="speed", n_vessels=5, topology="ring")

Two layouts of the same simulation:

* ``layout="joint"`` (default): one entry per formation, as the centralized
  ``gymnasium.make("MarineFormation-v1")`` view: observation ``(N·dim,)`` (the
  vessels' masked observations concatenated), action ``(N·A,)``, reward the mean
  of the vessels' rewards. ``num_envs = B``. Infos are the gym view's, stacked:
  ``infos["vessel_rewards"]`` ``(B, N)``, ``infos["reward_<term>"]`` each
  term's ``(B,)`` vessel mean.
* ``layout="agent"``: one entry per vessel (parameter sharing), entry
  ``b·N + j`` is vessel ``j`` of formation ``b``; observation ``(dim,)``,
  action ``(A,)``, reward that vessel's own. ``num_envs = B·N``; a formation's
  vessels terminate, truncate and reset together. Infos are the ParallelEnv's
  per-agent infos, stacked over the ``B·N`` entries.

Both info schemas are documented in ``marine_formation_env.frontend``.

Formation ``b`` is seeded with ``seed + b`` (``reset(seed=int)``) or
``seed[b]`` (a list of B seeds), so it reproduces a single
``parallel_env``/``gymnasium.make`` env reset with that seed, step for step,
its channel's luck included (loss, delays, sensor noise: a separate stream
seeded from the same seed); its generators then carry on across autoresets,
as a single env's do.

Autoreset follows Gymnasium's modes (``metadata["autoreset_mode"]``):
``NEXT_STEP`` (default) resets a finished formation on the following ``step``
call, which ignores that formation's actions and returns its first
observation with zero reward (inside the core's step, compiled with the numba
backend: ``FormationCore.step(restart=…)``); ``SAME_STEP`` resets it within the same call and
puts the last observation in ``infos["final_obs"]`` (mask ``infos["_final_obs"]``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from marine_formation_env.actions import action_space
from marine_formation_env.core import StepOutput, reset_output
from marine_formation_env.errors import float_array
from marine_formation_env.frontend import (
    InitialStates,
    Rendering,
    action_size_hint,
    formation_infos,
    open_front_end,
    read_reset,
    vessel_infos,
    vessel_mean,
)
from marine_formation_env.observations import observation_space
from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["LAYOUTS", "MarineFormationVectorEnv"]

LAYOUTS = ("joint", "agent")


class MarineFormationVectorEnv(VectorEnv):
    """``num_envs`` formations stepped by one batched core (see the module docstring).

    Args:
        num_envs: number of formations B.
        scenario: scenario name (``**overrides`` as for ``parallel_env``), or a ready
            ``ScenarioConfig`` (no overrides).
        layout: ``"joint"`` (an entry per formation) or ``"agent"`` (per vessel).
        autoreset_mode: ``gymnasium.vector.AutoresetMode`` ``NEXT_STEP``
            or ``SAME_STEP`` (or their string values).
        render_mode: ``"rgb_array"`` renders formation 0.
        render_speedup: ``metadata["render_fps"]`` is ``render_speedup / dt``: real time at 1.
        backend: ``"numpy"``, ``"numba"`` or ``"auto"`` (see ``FormationCore``).
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - gymnasium reads it from the class
        "render_modes": ["rgb_array"],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | ScenarioConfig = "paper",
        layout: str = "joint",
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        backend: str = "auto",
        render_speedup: float = 1.0,
        **overrides: Any,
    ) -> None:
        if layout not in LAYOUTS:
            raise ValueError(f"unknown layout {layout!r}; choose one of {list(LAYOUTS)}")
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode must be NEXT_STEP or SAME_STEP, got {mode!r}")
        metadata = {**type(self).metadata, "autoreset_mode": mode}
        front = open_front_end(metadata, scenario, overrides, render_mode, render_speedup, backend, num_envs)
        self.config, self.metadata, self.core = front
        self.num_formations = self.core.num_envs
        self.n_vessels = self.config.n_vessels
        self.layout = layout
        self.autoreset_mode = mode
        self.render_mode = render_mode
        b, joint = self.num_formations, layout == "joint"
        self.num_envs = b if joint else b * self.n_vessels
        self.single_observation_space = observation_space(self.config, joint)
        self.single_action_space = action_space(self.config, joint)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._initial = InitialStates(self.config, b)
        self._needs_reset = np.zeros(b, dtype=bool)
        self._rendering = Rendering(self.config, render_mode)
        self._started = False

    # ------------------------------------------------------------------ reset
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every formation.

        Args:
            seed: an int (formation ``b`` gets ``seed + b``) or a list of B
                seeds; each seeds its formation's initial states and, as a
                separate stream, its channel.
            options: ``{"initial_state": (N, 6) or (B, N, 6)}`` sets the states
                exactly; ``{"channel_seed": int or list}`` seeds the channel
                streams on their own (``+ b`` per formation, like ``seed``).
                Seeds are whole numbers ≥ 0 (Python or numpy integers); bad
                values raise and other keys are ignored with a warning, as in
                the ParallelEnv (``marine_formation_env.frontend``).
        """
        request = read_reset(self.config, seed, options, self.num_formations)  # every check before anything changes
        self._initial.seed(request.seeds)
        initial = request.initial_state
        if initial is None:
            initial = self._initial.draw()
        self.core.seed_channel(request.channel_seeds)
        self.core.reset(initial)
        self._needs_reset[:] = False
        self._started = True
        obs = self.core.observe()
        return self._layout_obs(obs), self._infos(
            reset_output(obs, self.config.action_level != "force", self.core.messages())
        )

    # ------------------------------------------------------------------- step
    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every formation once (see the module docstring for autoreset)."""
        if not self._started:
            raise RuntimeError("step() called before reset()")
        b, n, a = self.num_formations, self.n_vessels, self.config.action_dim
        arr = float_array(actions, "actions")
        if arr.shape != self.action_space.shape:
            hint = action_size_hint(self.config, arr.size // (b * n)) if arr.size % (b * n) == 0 else ""
            raise ValueError(f"actions must have shape {self.action_space.shape}, got {arr.shape}{hint}")
        arr = arr.reshape(b, n, a)
        if self._needs_reset.any():  # NEXT_STEP: they start anew in this call (inside the compiled step)
            pending = np.flatnonzero(self._needs_reset)
            out = self.core.step(arr, restart=self._needs_reset.copy(), initial_state=self._initial.draw(pending))
            self._needs_reset[:] = False
        else:
            out = self.core.step(arr)
        obs = out.observation
        done = out.terminated | out.truncated
        infos: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            ids = np.flatnonzero(done)
            infos["final_obs"] = self._entries_of(self._layout_obs(obs), ids)  # copies, before the reset
            infos["_final_obs"] = self._entry_mask(ids)
            obs[ids] = self._reset_formations(ids)
        elif done.any():
            self._needs_reset |= done
        reward, terminated, truncated = self._layout_scalars(out.reward, out.terminated, out.truncated)
        infos.update(self._infos(out))
        return self._layout_obs(obs), reward, terminated, truncated, infos

    def _reset_formations(self, ids: np.ndarray) -> np.ndarray:
        return self.core.reset(self._initial.draw(ids), env_ids=ids)

    def set_initial_spread(self, scale: float) -> None:
        """Start later resets and autoresets ``scale`` of the way from the formation on its lanes to the scenario's
        initial state (0: in formation; 1, the default: the scenario's own), its noise scaled alike.

        For a curriculum over the initial state (the learner's env only, as
        ``MarineFormationTorchEnv.set_initial_spread``); formations already
        running keep their episode, and seeding is unchanged.

        Raises:
            ConfigError: ``scale`` is not a number in [0, 1].
        """
        self._initial.set_spread(scale)

    # ---------------------------------------------------------------- layouts
    def _layout_obs(self, obs: np.ndarray) -> np.ndarray:
        if self.layout == "joint":
            return obs.reshape(self.num_formations, -1)
        return obs.reshape(self.num_formations * self.n_vessels, -1)

    def _layout_scalars(
        self, reward: np.ndarray, terminated: np.ndarray, truncated: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.layout == "joint":
            return vessel_mean(reward), terminated.copy(), truncated.copy()
        n = self.n_vessels
        return reward.reshape(-1), np.repeat(terminated, n), np.repeat(truncated, n)

    def _entries_of(self, layout_obs: np.ndarray, ids: np.ndarray) -> np.ndarray:
        final = np.full(self.num_envs, None, dtype=object)
        for k in ids:
            if self.layout == "joint":
                final[k] = layout_obs[k].copy()
            else:
                for j in range(self.n_vessels):
                    final[k * self.n_vessels + j] = layout_obs[k * self.n_vessels + j].copy()
        return final

    def _entry_mask(self, ids: np.ndarray) -> np.ndarray:
        mask = np.zeros(self.num_formations, dtype=bool)
        mask[ids] = True
        return mask if self.layout == "joint" else np.repeat(mask, self.n_vessels)

    def _infos(self, out: StepOutput) -> dict[str, Any]:
        """Infos in the schema of ``marine_formation_env.frontend``, stacked over the entries."""
        if self.layout == "joint":
            return formation_infos(out, self.core.time)
        return _flatten_entries(vessel_infos(out, self.core.time))

    # --------------------------------------------------------------- extras
    @property
    def max_steps(self) -> int:
        """Control periods per episode (``horizon / dt``): the step at which a formation is truncated."""
        return self.config.max_steps

    def render(self, mode: str | None = None) -> tuple[np.ndarray, ...] | None:
        """Render formation 0 (``rgb_array``, even height and width); ``mode`` is accepted and ignored."""
        if self.render_mode is None:
            return None
        frame = self._rendering.frame(self.core, 0)
        return None if frame is None else (frame,)

    def close_extras(self, **kwargs: Any) -> None:
        """Close the renderer's figure (if one was opened)."""
        self._rendering.close()


def _flatten_entries(infos: dict[str, Any]) -> dict[str, Any]:
    """``(B, N, …)`` arrays of an info tree as ``(B·N, …)``: one entry per vessel."""
    return {
        key: _flatten_entries(value) if isinstance(value, dict) else value.reshape(-1, *value.shape[2:])
        for key, value in infos.items()
    }
