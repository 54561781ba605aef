"""TorchRL view of the batched core: ``B`` formations as one ``EnvBase`` with a batch size ``[B]``.

``MarineFormationTorchEnv(num_envs=B, scenario="paper", device="cpu", **overrides)``
is a multi-agent TorchRL environment in the layout of TorchRL's ``VmasEnv``:
every formation of the batch is one entry of the tensordict, its vessels are
one agent group ``"vessel"``, and no Python loop runs over formations or vessels
(one ``FormationCore`` step per call, the
numba kernel when it is installed). Install with the ``torchrl`` extra::

    pip install -c constraints.txt -e ".[torchrl]"

    from marine_formation_env.torchrl import MarineFormationTorchEnv
    env = MarineFormationTorchEnv(num_envs=64, scenario="acoustic", action_level="speed")
    rollout = env.rollout(100)   # TensorDict with batch size [64, 100]

Keys (``B`` formations, ``N`` vessels, ``D`` observation entries, ``A`` action entries):

* ``("vessel", "observation")`` ``(B, N, D)`` float32: each vessel's masked
  observation (the ParallelEnv's), bounded;
* ``("vessel", "action")`` ``(B, N, A)`` float32: the normalized action in
  [−1, 1] (the ParallelEnv's action map);
* ``("vessel", "reward")`` ``(B, N, 1)`` float32: each vessel's reward;
* ``("vessel", "info", name)`` ``(B, N, 1)`` float32: the ParallelEnv's infos,
  the reward terms ``reward_cross_track`` … ``reward_terminal`` (they sum to
  the reward), ``time`` [s], ``collision`` and ``out_of_bounds`` (the
  formation's flags, 0/1), ``commanded_speed`` u_c [m/s] (``speed``,
  ``guidance``);
* ``"state"`` ``(B, 6·N + 1)`` float32: the global state for centralized
  critics (``ParallelEnv.state()``);
* ``"done"``, ``"terminated"``, ``"truncated"`` ``(B, 1)`` bool: the
  formation's episode end (collision or out of bounds; time limit).

``group="agents"`` names the group as ``VmasEnv`` does, so scripts written
for VMAS (TorchRL's multi-agent recipes) run with only the constructor swapped.

A formation's vessels end their episode together, so the done flags live at
the root, as in ``VmasEnv``; multi-agent losses that want them per agent
expand them over the group (TorchRL's multi-agent PPO recipe and BenchMARL do).

Resets: ``reset()`` starts every formation; a tensordict with a ``"_reset"``
mask ``(B, 1)`` (what TorchRL's collectors and ``step_and_maybe_reset`` pass)
restarts only the masked formations, the others keep their state and
observation. Seeding replays the PettingZoo env: after ``env.set_seed(s)``,
the next reset gives formation ``b`` the initial state, channel luck
(loss, delays, sensor noise) and therefore the whole trajectory of
``parallel_env(scenario, **overrides).reset(seed=s + b)`` under the same
actions; later restarts of a formation continue its streams, as later
``reset()`` calls of that env do. ``env.set_initial_spread(s)`` starts later
resets ``s`` ∈ [0, 1] of the way from the formation on its lanes to the
scenario's initial state, noise included (a curriculum; 1 restores it).

Physics, rewards and observations are the core's: this module only lays them
out as tensors (``marine_formation_env.frontend`` holds the rules every
front end shares).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from marine_formation_env.core import MESSAGE_KEYS, FormationCore, StepOutput, reset_output
from marine_formation_env.errors import ConfigError, check_seed
from marine_formation_env.frontend import (
    REWARD_INFO_KEYS,
    InitialStates,
    Rendering,
    resolve_config,
    vessel_infos,
)
from marine_formation_env.scenarios import ScenarioConfig

try:
    import torch
    from tensordict import TensorDict, TensorDictBase
    from torchrl.data import Bounded, Categorical, Composite, Unbounded
    from torchrl.envs import EnvBase
except ImportError as error:  # pragma: no cover - the message is the point
    raise ImportError(
        "marine_formation_env.torchrl needs torch, tensordict and torchrl: "
        "pip install -c constraints.txt 'marine-formation-env[torchrl]'"
    ) from error

__all__ = ["GROUP", "INFO_KEYS", "MarineFormationTorchEnv"]

#: The name of the agent group (the vessels of a formation).
GROUP = "vessel"

#: Root keys of the tensordict (a group may not take these names).
_ROOT_KEYS = frozenset({"state", "done", "terminated", "truncated", "next"})

#: The entries of ``("vessel", "info")`` at every level (``commanded_speed`` is added at ``speed``/``guidance``).
INFO_KEYS = (*REWARD_INFO_KEYS, "time", "collision", "out_of_bounds", *MESSAGE_KEYS)


class MarineFormationTorchEnv(EnvBase):
    """``num_envs`` formations of a scenario as a batched multi-agent TorchRL env (see the module docstring).

    Args:
        num_envs: number of formations B (the env's ``batch_size`` is ``[B]``).
        scenario: scenario name (``**overrides`` as for ``parallel_env``), or a
            ready ``ScenarioConfig`` (no overrides).
        device: where the tensordicts live; the simulation runs on the CPU.
        backend: ``"numpy"``, ``"numba"`` or ``"auto"`` (see ``FormationCore``).
        render_mode: ``"rgb_array"`` to render formation 0 (``render()``), or None.
        group: the name of the agent group; ``"agents"`` gives ``VmasEnv``'s keys,
            so scripts written for VMAS (TorchRL's multi-agent recipes) run unchanged.
        seed: if given, ``set_seed`` is called with it (as ``VmasEnv`` does).
        render_width: width of rendered frames in pixels (≥ 320; the height
            follows the workspace, both even). Recorders keep every frame of an
            episode in memory: 800 frames of 640 × 352 take 0.5 GB.
        **overrides: any field of the scenario's settings (``action_level``,
            ``n_vessels``, ``topology``, ``channel``, ...); an unknown key raises
            ``UnknownSettingError`` (a ``TypeError``).

    Attributes:
        config: the resolved scenario.
        core: the batched simulation.
        n_agents: vessels per formation N.
        max_steps: control periods per episode (``horizon / dt``), where a formation is truncated.
    """

    batch_locked = True

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | ScenarioConfig = "paper",
        device: str | torch.device = "cpu",
        backend: str = "auto",
        render_mode: str | None = None,
        group: str = GROUP,
        seed: int | None = None,
        render_width: int = 640,
        **overrides: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ConfigError(f"num_envs must be a whole number ≥ 1, got {num_envs!r}")
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if isinstance(render_width, bool) or not isinstance(render_width, (int, np.integer)) or render_width < 320:
            raise ConfigError(f"render_width must be a whole number of pixels ≥ 320, got {render_width!r}")
        if not isinstance(group, str) or not group or group.startswith("_") or group in _ROOT_KEYS:
            raise ConfigError(f"group must be a non-empty name other than {sorted(_ROOT_KEYS)}, got {group!r}")
        self.config: ScenarioConfig = resolve_config(scenario, overrides)
        super().__init__(device=device, batch_size=torch.Size([int(num_envs)]))
        self.core = FormationCore(self.config, num_envs=int(num_envs), backend=backend)
        self.num_envs = int(num_envs)
        self.n_agents = self.config.n_vessels
        self.render_mode = render_mode
        self._initial = InitialStates(self.config, self.num_envs)
        self._pending_seed: int | None = None
        self._obs = np.zeros((self.num_envs, self.n_agents, self.core.layout.dim), dtype=np.float32)
        self._has_speed = self.config.action_level != "force"
        # drawn only when a frame is asked for; narrower than the ParallelEnv's 1280 px, as evaluation
        # videos hold every step of an episode in memory (800 frames at the speed level)
        self._rendering = Rendering(self.config, "rgb_array", width=int(render_width))
        self.group = group
        self._make_specs()
        if seed is not None:
            self.set_seed(seed)

    # ------------------------------------------------------------------ specs
    def _make_specs(self) -> None:
        b, n, dim, a = self.num_envs, self.n_agents, self.core.layout.dim, self.config.action_dim
        dev = self.device
        info = {key: Unbounded(shape=(b, n, 1), dtype=torch.float32, device=dev) for key in self.info_keys}
        self.observation_spec = Composite(
            {
                self.group: Composite(
                    {
                        "observation": Bounded(
                            low=torch.as_tensor(np.broadcast_to(self.core.obs_low, (b, n, dim)).copy()),
                            high=torch.as_tensor(np.broadcast_to(self.core.obs_high, (b, n, dim)).copy()),
                            shape=(b, n, dim),
                            dtype=torch.float32,
                            device=dev,
                        ),
                        "info": Composite(info, shape=(b, n), device=dev),
                    },
                    shape=(b, n),
                    device=dev,
                ),
                "state": Unbounded(shape=(b, 6 * n + 1), dtype=torch.float32, device=dev),
            },
            shape=(b,),
            device=dev,
        )
        self.action_spec = Composite(
            {
                self.group: Composite(
                    {"action": Bounded(low=-1.0, high=1.0, shape=(b, n, a), dtype=torch.float32, device=dev)},
                    shape=(b, n),
                    device=dev,
                )
            },
            shape=(b,),
            device=dev,
        )
        self.reward_spec = Composite(
            {
                self.group: Composite(
                    {"reward": Unbounded(shape=(b, n, 1), dtype=torch.float32, device=dev)}, shape=(b, n), device=dev
                )
            },
            shape=(b,),
            device=dev,
        )
        flag = Categorical(n=2, shape=(b, 1), dtype=torch.bool, device=dev)
        self.done_spec = Composite(
            {"done": flag.clone(), "terminated": flag.clone(), "truncated": flag.clone()}, shape=(b,), device=dev
        )

    @property
    def info_keys(self) -> tuple[str, ...]:
        """The entries of ``("vessel", "info")``: reward components, time, flags, and u_c where the level has one."""
        return (*INFO_KEYS, "commanded_speed") if self._has_speed else INFO_KEYS

    @property
    def max_steps(self) -> int:
        """Control periods per episode (``horizon / dt``): the step at which a formation is truncated."""
        return self.config.max_steps

    @property
    def group_map(self) -> dict[str, list[str]]:
        """``{group: ["vessel_0", …]}``: the one agent group, its agents named as the ParallelEnv's."""
        return {self.group: [f"vessel_{j}" for j in range(self.n_agents)]}

    # ------------------------------------------------------------------ seeding and reset
    def _set_seed(self, seed: int | None) -> None:
        """Seed the next reset: formation ``b`` gets ``seed + b`` (module docstring)."""
        self._pending_seed = check_seed(seed)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = self._reset_mask(tensordict)
        ids = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        if self._pending_seed is not None:
            seeds = [self._pending_seed + int(b) for b in ids]
            self._pending_seed = None
            self._initial.seed(seeds, ids)
            self.core.seed_channel(seeds, ids)
        if len(ids):
            # a new array: the last step's tensordict shares memory with the old one
            self._obs = self._obs.copy()
            self._obs[ids] = self.core.reset(self._initial.draw(ids), env_ids=ids)
        # the untouched formations report their current observation (TorchRL keeps their entries anyway)
        return self._tensordict(reset_output(self._obs, self._has_speed, self.core.messages()), reward=False)

    def set_initial_spread(self, scale: float) -> None:
        """Start later resets ``scale`` of the way from the formation on its lanes to the scenario's initial state.

        ``scale`` multiplies every initial error of the nominal state (across
        its lane, heading relative to the path, along-path coordination) and
        the ``init_noise`` half-widths
        (``spread_config``): 0 starts every
        formation in formation, 1 (the default) is the scenario's. For a
        curriculum over the initial state; formations already running keep
        their episode, and seeding is unchanged.

        Raises:
            ConfigError: ``scale`` is not a number in [0, 1].
        """
        self._initial.set_spread(scale)

    def _reset_mask(self, tensordict: TensorDictBase | None) -> np.ndarray | None:
        """The formations to restart, ``(B,)`` bool, from a ``"_reset"`` entry (root or group); None: all."""
        if tensordict is None:
            return None
        masks = []
        for key in ("_reset", (self.group, "_reset")):
            value = tensordict.get(key, None)
            if value is not None:
                arr = value.detach().cpu().numpy().reshape(self.num_envs, -1)
                masks.append(arr.any(axis=1))
        if not masks:
            return None
        return np.logical_or.reduce(masks)

    # ------------------------------------------------------------------ step
    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get((self.group, "action"))
        actions = action.detach().to("cpu", torch.float64).numpy()
        out = self.core.step(actions)
        self._obs = out.observation
        return self._tensordict(out, reward=True)

    def _tensordict(self, out: StepOutput, reward: bool) -> TensorDictBase:
        b, n = self.num_envs, self.n_agents
        infos = vessel_infos(out, self.core.time)
        info = {
            key: torch.from_numpy(np.asarray(infos[key], dtype=np.float32).reshape(b, n, 1)) for key in self.info_keys
        }
        group: dict[str, Any] = {
            "observation": torch.from_numpy(out.observation),
            "info": TensorDict(info, batch_size=(b, n)),
        }
        if reward:
            group["reward"] = torch.from_numpy(out.reward.astype(np.float32).reshape(b, n, 1))
        terminated = torch.from_numpy(out.terminated.reshape(b, 1).copy())
        truncated = torch.from_numpy(out.truncated.reshape(b, 1).copy())
        td = TensorDict(
            {
                self.group: TensorDict(group, batch_size=(b, n)),
                "state": torch.from_numpy(self.core.global_state()),
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            },
            batch_size=(b,),
        )
        return td.to(self.device) if self.device is not None and self.device != torch.device("cpu") else td

    # ------------------------------------------------------------------ extras
    def render(self, mode: str | None = None, **ignored: Any) -> np.ndarray | None:
        """Formation 0 as an ``(H, W, 3)`` uint8 frame (even height and width).

        A frame is drawn when the env was made with ``render_mode="rgb_array"``
        or when ``mode="rgb_array"`` is asked for in the call (as ``VmasEnv``
        allows: TorchRL's VMAS recipes record their evaluation videos that
        way); otherwise a warning, as gymnasium's envs give, and None. Other
        renderers' keywords (VMAS's ``agent_index_focus``) are accepted and ignored.
        """
        if self.render_mode is None and mode != "rgb_array":
            warnings.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or render(mode='rgb_array')",
                stacklevel=2,
            )
            return None
        return self._rendering.frame(self.core, 0)

    def close(self, *, raise_if_closed: bool = True) -> None:
        """Close the renderer's figure, if one was opened."""
        self._rendering.close()
        super().close(raise_if_closed=raise_if_closed)

    def __repr__(self) -> str:
        cfg = self.config
        return (
            f"{type(self).__name__}(scenario={cfg.name!r}, num_envs={self.num_envs}, n_agents={self.n_agents}, "
            f"action_level={cfg.action_level!r}, device={self.device})"
        )
