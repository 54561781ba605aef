"""The batched simulation: the state of ``B`` formations of ``N`` vessels and its step.

``FormationCore`` owns the state ``(B, N, 6)``, the time and the step
count, and does, per control period: map the normalized actions to physical
commands (``actions``), integrate ``substeps`` RK4
steps of the closed loop (the built-in inner controllers of the action level
are part of the vector field, so they act at every RK4 stage), then compute
the masked observations, rewards, terminations and truncations as arrays, with
the per-element rules of ``rules``. The numba backend
(``_numba``) runs the same step, channel and
autoreset (``step(restart=…)``) included, as one fused kernel.

Everything else has its own home: the observation layout and bounds
(``observations``), the action maps and spaces
(``actions``), the backend choice
(``backends``), the initial-state draws
(``sample_initial_state``, from a
generator the caller passes in: the core holds none), the channel
(``channel``) and the sensor noise
(``disturbances``). Every front end (PettingZoo env,
gymnasium views, vector env) is a thin view of this class.

Observation of vessel ``j`` (float32, ``10 + 4·(N−1)`` entries, docs/model.md §7;
on a curved path in the path coordinates of docs/paths.md, which on the
paper's straight path are the quantities named first)::

    own   0 e_j = y_j − D_yj                 [m]     (curved: (p_j − P(ℓ_j))·n − D_yj)
          1 ψ_j wrapped to [−π, π)           [rad]   (curved: β_j = ψ_j − γ(ℓ_j), wrapped)
          2 u_j   3 v_j                      [m/s]
          4 r_j                              [rad/s]
          5 u_d(t)                           [m/s]
          6 u̇_d(t)                           [m/s²]
          7 κ(ℓ_j): the path's curvature     [1/m]   (0 on the straight path)
          8 κ(ℓ_j + 100 m), ahead            [1/m]
          9 D_yj, the vessel's lane offset   [m]
    slot k = 0…N−2 holds vessel i = (j + k + 1) mod N:
          0 link bit: 1 iff i ∈ A_j (i transmits to j)
          1 θ_j − θ_i, θ = x − D_x           [m]     (curved: θ = ℓ − D_x; 0 if no link)
          2 ẋ_j − ẋ_i                        [m/s]   (curved: ℓ̇_j − ℓ̇_i; 0 if no link)
          3 age of that data                 [s]     (0: ideal links)

On a curved path (``not config.straight``) the core also follows each
vessel's projection ``ℓ_j`` on the path (``FormationCore.arc``),
continuously: a global search at reset, then Newton steps from the previous
value after every RK4 step (both backends).

With a non-ideal channel, switching topologies or sensor noise
(``not config.ideal_observations``), a ``LinkChannel``
sits between the vessels: the slots then hold the last message received from
``i`` (its θ_i and ẋ_i at sending, compared with j's own values now) and its
age, and the link bit is 1 iff the link exists now and has delivered a
message (module ``marine_formation_env.channel``). With a current, ``u`` and
``v`` are velocities through the water and ẋ in the messages is inertial.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from marine_formation_env.actions import map_actions
from marine_formation_env.backends import resolve_backend
from marine_formation_env.channel import ATTEMPTED, COUNTERS, DELIVERED, SENT, LinkChannel, prediction_error
from marine_formation_env.control import (
    curved_heading_inputs,
    curved_path_following_inputs,
    heading_tracking_inputs,
    integral_los_rate,
    path_following_inputs,
)
from marine_formation_env.disturbances import SensorNoiseSource
from marine_formation_env.dynamics import (
    PSI,
    R,
    U,
    V,
    X,
    Y,
    accelerations,
    current_velocity,
    rk4_step,
    vessel_rhs,
    wrap_angle,
)
from marine_formation_env.errors import checked_array, float_array
from marine_formation_env.observations import ObservationLayout, observation_bounds
from marine_formation_env.paths import PathCoordinates, path_coordinates
from marine_formation_env.rules import (
    COORDINATION,
    CURVATURE,
    CURVATURE_AHEAD,
    LANE_OFFSET,
    LINK,
    LOOKAHEAD,
    MAX_DRIFT,
    VELOCITY,
    along_track,
    cost_term,
    effort_term,
    outside_envelope,
    outside_workspace,
    slot_differences,
    terminal_term,
)
from marine_formation_env.scenarios import ScenarioConfig, min_separation
from marine_formation_env.settings import TRACKING_TERMS
from marine_formation_env.streams import channel_streams

__all__ = ["MESSAGE_KEYS", "REWARD_COMPONENTS", "FormationCore", "StepOutput", "reset_output", "vessel_totals"]

#: Appended to a wrong-shape message of a state array.
COLUMNS_HINT = " (columns x, y, psi, u, v, r)"

REWARD_COMPONENTS = (*TRACKING_TERMS, "effort", "terminal", "communication")
#: The message counters of a control instant (``marine_formation_env.channel``, ``COUNTERS``) as info keys,
#: and the bits sent.
MESSAGE_KEYS = (*(f"messages_{name}" for name in COUNTERS), "bits_sent")


@dataclass
class StepOutput:
    """What one batched step returns (all arrays have leading shape ``(B,)`` or ``(B, N)``).

    Attributes:
        observation: ``(B, N, dim)`` float32 masked observations.
        reward: ``(B, N)`` per-vessel rewards.
        terminated: ``(B,)`` collision or workspace exit.
        truncated: ``(B,)`` time limit reached (and not terminated).
        components: reward components, each ``(B, N)``; they sum to ``reward``.
        commanded_speed: ``(B, N)`` u_c [m/s] applied (``speed``/``guidance``), else None.
        collision: ``(B,)`` two vessels closer than the safety distance.
        out_of_bounds: ``(B,)`` a vessel left the workspace or the envelope
            (|u|, |v| > max_speed, |r| > max_yaw_rate), or the state is not finite.
        messages: the messages of the control instant that ends the step, by
            ``MESSAGE_KEYS``, each ``(B, N)`` int64 (``FormationCore.messages``).
        message_totals: ``(B, len(MESSAGE_KEYS))`` int64: ``messages`` summed over the vessels.
    """

    observation: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    components: dict[str, np.ndarray]
    commanded_speed: np.ndarray | None
    collision: np.ndarray
    out_of_bounds: np.ndarray
    messages: dict[str, np.ndarray]
    message_totals: np.ndarray


def vessel_totals(block: np.ndarray) -> np.ndarray:
    """``(B, N, K)`` → ``(B, K)``: the sum over the vessels, vessel by vessel (a reduction over a short
    axis costs several times more, as for ``frontend.vessel_mean``)."""
    total = block[:, 0].copy()
    for j in range(1, block.shape[1]):
        total += block[:, j]
    return total


def reset_output(
    observation: np.ndarray, has_commanded_speed: bool, messages: dict[str, np.ndarray] | None = None
) -> StepOutput:
    """The ``StepOutput`` of a reset: its observation, and zeros where nothing has happened yet.

    Front ends build ``reset()``'s infos from it with the same code as
    ``step()``'s, so both have the same keys (TorchRL and other wrappers build
    their info specs from ``reset()``): zero rewards and reward components, no
    collision, not out of bounds, not done, and a commanded speed of 0 m/s
    (no command yet) at the levels that have one; ``messages`` are those of
    the reset instant (``FormationCore.messages``; None: none).
    """
    b, n = observation.shape[:2]
    zeros = np.zeros((b, n))
    flags = np.zeros(b, dtype=bool)
    return StepOutput(
        observation=observation,
        reward=zeros.copy(),
        terminated=flags.copy(),
        truncated=flags.copy(),
        components={key: zeros.copy() for key in REWARD_COMPONENTS},
        commanded_speed=zeros.copy() if has_commanded_speed else None,
        collision=flags.copy(),
        out_of_bounds=flags.copy(),
        messages=messages if messages is not None else {key: np.zeros((b, n), dtype=np.int64) for key in MESSAGE_KEYS},
        message_totals=np.zeros((b, len(MESSAGE_KEYS)), dtype=np.int64)
        if messages is None
        else vessel_totals(np.stack([messages[key] for key in MESSAGE_KEYS], axis=-1)),
    )


class FormationCore:
    """``B`` formations of ``N`` vessels stepped together (see module docstring).

    Args:
        config: a validated ``ScenarioConfig``.
        num_envs: number of formations ``B``.
        backend: ``"numpy"`` (the reference implementation), ``"numba"`` (one
            fused compiled kernel per step, ``marine_formation_env._numba``,
            which compiles the same model and controller functions; results
            agree with the numpy path to floating-point rounding, not bit for
            bit, since numpy's vectorized transcendental functions and libm's
            may differ in the last bit on some CPUs: ``tests/test_backends.py``
            says what it checks), or ``"auto"``: numba when it is installed
            (``pip install 'marine-formation-env[fast]'``), else numpy. The
            environment variable ``MARINE_FORMATION_BACKEND`` overrides ``auto``.

    Attributes:
        state: ``(B, N, 6)`` float64, columns ``x, y, psi, u, v, r``.
        time: ``(B,)`` simulated time [s].
        steps: ``(B,)`` control periods since reset.
        channel: the ``LinkChannel``
            between the vessels, or None with the paper's ideal links.
        sensor_noise: the ``SensorNoiseSource``
            of the vessels' measurements of themselves, or None without noise.
    """

    def __init__(self, config: ScenarioConfig, num_envs: int = 1, backend: str = "auto") -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer ≥ 1, got {num_envs!r}")
        self.backend = resolve_backend(backend)
        self._curved = not config.straight
        self.config = config
        self.num_envs = int(num_envs)
        self.n = config.n_vessels
        self.layout = ObservationLayout(self.n, config.observation_slots, transmit=config.transmit)
        self.action_dim = config.action_dim
        n = self.n
        self._dx = np.ascontiguousarray(config.formation[:, 0])
        self._dy = np.ascontiguousarray(config.formation[:, 1])
        self._steer_dy_plain = np.ascontiguousarray(np.broadcast_to(self._dy, (self.num_envs, config.n_vessels)))
        self._slot_index = np.array([self.layout.slot_vessels(j) for j in range(n)], dtype=np.intp).reshape(n, n - 1)
        self._slot_mask = config.graph.adjacency[np.arange(n)[:, None], self._slot_index].astype(float)
        self.obs_low, self.obs_high = observation_bounds(config)
        self.state = np.zeros((self.num_envs, n, 6))
        self.time = np.zeros(self.num_envs)
        self.steps = np.zeros(self.num_envs, dtype=np.int64)
        self._last_u_c = np.zeros((self.num_envs, n))  # previous u_c [m/s] (speed, guidance)
        self.arc = np.zeros((self.num_envs, n))  # ℓ_j: each vessel's projection on a curved path [m]
        self._fresh = np.ones(self.num_envs, dtype=bool)  # no previous command since reset
        self._current: tuple[float, float, float, float, float] | None = (
            None if config.current.is_zero else config.current.coefficients
        )
        self.channel = (
            None
            if config.ideal_observations
            else LinkChannel(
                config.channel,
                n,
                config.dt,
                [(dwell, g.adjacency) for dwell, g in config.topology_schedule] or [(math.inf, config.graph.adjacency)],
                config.max_steps,
                self.num_envs,
                transmit=config.transmit,
            )
        )
        # with ideal links every vessel broadcasts at every control instant and reaches its out-neighbours
        ideal = np.zeros((len(COUNTERS), n), dtype=np.int64)
        ideal[[ATTEMPTED, SENT]] = 1
        ideal[DELIVERED] = config.graph.adjacency.sum(axis=0)
        self._ideal_counts = ideal
        self._ideal_block: np.ndarray | None = None
        self.sensor_noise = (
            None if config.sensor_noise.is_zero else SensorNoiseSource(config.sensor_noise, n, self.num_envs)
        )
        self._measured: np.ndarray | None = None  # with sensor noise only
        self._los_sigma = config.los_integral_gain
        self.los_integral = np.zeros((self.num_envs, n))  # e_int of integral LOS [s] (speed level)
        self._kernel: Any = None
        self._no_starts = np.empty((self.num_envs, n, 6))  # the kernel's initial states when nothing restarts
        if self.backend == "numba":
            from marine_formation_env import _numba

            if self.sensor_noise is not None:
                self._measured = self.state.copy()  # the kernel writes the measurements here
            self._kernel = _numba.StepKernel(
                config,
                self.num_envs,
                self._slot_index,
                self._slot_mask,
                self.obs_low,
                self.obs_high,
                self.channel,
                self.sensor_noise,
                self._measured,
            )

    @property
    def measured(self) -> np.ndarray:
        """``(B, N, 6)``: what each vessel measured of itself at the last control
        instant: the state plus sensor noise (the state itself without noise)."""
        return self.state if self._measured is None else self._measured

    # ------------------------------------------------------------------ reset
    def seed_channel(self, seeds: Sequence[int | None], env_ids: np.ndarray | None = None) -> None:
        """Seed the channel stream (loss, delays, failures, sensor noise) of formations ``env_ids``.

        One seed per formation (all formations if ``env_ids`` is None); ``None``
        keeps that formation's stream running. Call it before ``reset``. A
        no-op with the paper's ideal links, which draw nothing.
        """
        index = np.arange(self.num_envs) if env_ids is None else np.asarray(env_ids)
        if len(seeds) != len(index):
            raise ValueError(f"seed_channel needs {len(index)} seeds (one per formation), got {len(seeds)}")
        if self.channel is None:
            return
        for b, seed in zip(index, seeds, strict=True):
            if seed is not None:
                uniforms, normals = channel_streams(int(seed))
                self.channel.seed(int(b), uniforms)
                if self.sensor_noise is not None:
                    self.sensor_noise.seed(int(b), normals)

    def reset(self, initial_state: np.ndarray, env_ids: np.ndarray | slice | None = None) -> np.ndarray:
        """Set the state of formations ``env_ids`` (all if None) and return their observations.

        The channel of those formations forgets every message and transmits
        at once (control instant 0).

        Args:
            initial_state: ``(N, 6)`` or ``(len(env_ids), N, 6)`` finite array.
            env_ids: which formations to reset.
        """
        ids = slice(None) if env_ids is None else env_ids
        target_shape = self.state[ids].shape
        arr = checked_array(initial_state, "initial_state", [(self.n, 6), target_shape], hint=COLUMNS_HINT)
        self.state[ids] = arr
        self.time[ids] = 0.0
        self.steps[ids] = 0
        if self._curved:
            self.arc[ids] = self.config.path.closest(self.state[ids][..., X], self.state[ids][..., Y])
        self._fresh[ids] = True  # the first command after a reset is held, not ramped
        self.los_integral[ids] = 0.0
        index = np.arange(self.num_envs)[ids]
        if self.channel is not None and len(index):
            self.channel.reset(index)
            self._sense(index)
        return self.observe(ids)

    def _sense(self, ids: np.ndarray) -> None:
        """A control instant for the channel: measure (with noise), transmit, deliver."""
        assert self.channel is not None
        if self.sensor_noise is not None:
            if self._measured is None:
                self._measured = self.state.copy()
            self._measured[ids] = self.state[ids] + self.sensor_noise.draw(ids)
        s, time = self.measured[ids], self.time[ids]
        theta, x_dot = self._along_track(s, time, inertial=True, ids=ids)
        self.channel.update(ids, self.steps[ids], time, theta, x_dot, self.state[ids][..., :2])

    # ------------------------------------------------------------------- step
    def step(
        self, actions: np.ndarray, restart: np.ndarray | None = None, initial_state: np.ndarray | None = None
    ) -> StepOutput:
        """Advance every formation by one control period, or restart some of them (autoreset).

        Formations in ``restart`` start a new episode from ``initial_state``
        instead of stepping, exactly as ``reset`` would start it: their
        actions are ignored and their output is the new episode's first
        observation, with zero reward and nothing terminated or truncated.
        The compiled backend does this inside its kernel, so formations that
        end at different times cost no extra pass.

        Args:
            actions: ``(B, N, A)`` normalized actions; finite values outside
                [−1, 1] are clipped.
            restart: ``(B,)`` booleans, or None (no formation restarts).
            initial_state: ``(number restarting, N, 6)`` their initial states,
                in formation order (required with ``restart``).

        Raises:
            ValueError: wrong shape or a non-finite entry (named by index).
        """
        cfg = self.config
        actions = float_array(actions, "actions")
        expected = (self.num_envs, self.n, self.action_dim)
        if actions.shape != expected:
            raise ValueError(
                f"actions must have shape {expected} (formations, vessels, action dim), got {actions.shape}"
            )
        restart_ids, initial = self._restarts(restart, initial_state)
        if len(restart_ids):
            actions = actions.copy()
            actions[restart_ids] = 0.0  # ignored
        if not np.all(np.isfinite(actions)):
            bad = tuple(int(i) for i in np.argwhere(~np.isfinite(actions))[0])
            raise ValueError(f"actions must be finite, but actions{list(bad)} = {actions[bad]}")
        clipped = np.clip(actions, -1.0, 1.0)
        commands = map_actions(cfg, clipped)
        if cfg.transmit:
            assert self.channel is not None
            self.channel.wants[:] = clipped[..., -1] > 0.0
            clipped = np.ascontiguousarray(clipped[..., : cfg.control_dim])  # the effort term charges the commands
        if self._fresh.any():
            fresh = self._fresh
            if "u_c" in commands:
                self._last_u_c[fresh] = commands["u_c"][fresh]
            self._fresh[:] = False
        e_start = self._cross_track(self.state) if self._los_sigma > 0 else None
        if self._kernel is not None:
            out = self._step_compiled(clipped, commands, restart_ids, initial)
        else:
            rhs = self.closed_loop(commands)
            h = cfg.dt / cfg.substeps
            state = self.state
            for k in range(cfg.substeps):
                state = rk4_step(rhs, state, h, k * h)
                if self._curved:  # follow the projections: Newton from where they were
                    self.arc = cfg.path.project(state[..., X], state[..., Y], self.arc)
            self.state = state
            self.time = self.time + cfg.dt
            self.steps = self.steps + 1
            self._restart(restart_ids, initial)
            if self.channel is not None:
                self._sense(np.arange(self.num_envs))
            out = self._outputs(clipped, commands.get("u_c"))
            if len(restart_ids):  # the first output of an episode: no reward, nothing ended
                for field in (out.reward, out.terminated, out.truncated, out.collision, out.out_of_bounds):
                    field[restart_ids] = 0
                for value in out.components.values():
                    value[restart_ids] = 0.0
        block = self._message_block()
        out.messages = {key: block[..., k] for k, key in enumerate(MESSAGE_KEYS)}
        out.message_totals = vessel_totals(block)
        sent = out.messages["messages_sent"]
        if cfg.reward.message_cost > 0:
            cost = -cfg.reward.message_cost * sent
            cost[restart_ids] = 0.0  # a new episode's first output has no reward
            out.reward = out.reward + cost
        else:
            cost = np.zeros(sent.shape)
        out.components["communication"] = cost
        if "u_c" in commands:
            self._last_u_c = commands["u_c"]
        if e_start is not None:  # integral LOS: one Euler step of its integrator per control period
            rate = integral_los_rate(e_start, self.los_integral, self._los_sigma, cfg.gains.delta)
            self.los_integral = self.los_integral + cfg.dt * rate
        if len(restart_ids):
            self._fresh[restart_ids] = True  # their first command is held, not ramped
            self.los_integral[restart_ids] = 0.0
        return out

    def _restarts(self, restart: np.ndarray | None, initial_state: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Check ``step``'s autoreset arguments: the restarting formations' indices and initial states."""
        if restart is None:
            if initial_state is not None:
                raise ValueError("step got an initial_state without restart (which formations start anew?)")
            return np.empty(0, dtype=np.intp), np.empty((0, self.n, 6))
        mask = np.asarray(restart)
        if mask.dtype != bool or mask.shape != (self.num_envs,):
            raise ValueError(f"restart must be ({self.num_envs},) booleans, got {mask.dtype} {mask.shape}")
        ids = np.flatnonzero(mask)
        if initial_state is None:
            if len(ids):
                raise ValueError(f"step needs the initial_state of the {len(ids)} restarting formation(s)")
            return ids, np.empty((0, self.n, 6))
        return ids, checked_array(initial_state, "initial_state", [(len(ids), self.n, 6)], hint=COLUMNS_HINT)

    def _restart(self, ids: np.ndarray, initial: np.ndarray) -> None:
        """Start formations ``ids`` anew from ``initial`` (time 0, step 0; the channel forgets everything)."""
        if not len(ids):
            return
        self.state[ids] = initial
        self.time[ids] = 0.0
        self.steps[ids] = 0
        if self._curved:
            self.arc[ids] = self.config.path.closest(initial[..., X], initial[..., Y])
        if self.channel is not None:
            self.channel.reset(ids)

    def _steer_dy(self) -> np.ndarray:
        """The path offset the speed level's LOS steers to: ``D_y``, or ``D_y − σ·e_int`` (integral LOS).

        LOS on ``e + σ·e_int`` with ``e = y − D_y`` is LOS on ``y − (D_y − σ·e_int)``.
        """
        if self._los_sigma > 0:
            return self._dy - self._los_sigma * self.los_integral  # type: ignore[no-any-return]
        return self._steer_dy_plain

    def _step_compiled(
        self, actions: np.ndarray, commands: dict[str, np.ndarray], restart_ids: np.ndarray, initial: np.ndarray
    ) -> StepOutput:
        """The same step as the numpy path, channel included, in one fused numba kernel (``backend="numba"``)."""
        cfg = self.config
        b, n = self.num_envs, self.n
        cmd = np.zeros((b, n, 2))
        if cfg.action_level == "force":
            cmd[..., 0], cmd[..., 1] = commands["tau_u"], commands["tau_r"]
        else:
            cmd[..., 0] = commands["u_c"]
            if cfg.action_level == "guidance":
                cmd[..., 1] = commands["psi_d"]
        time0, steer_dy = self.time, self._steer_dy()
        self.time = self.time + cfg.dt
        self.steps = self.steps + 1
        restart = np.zeros(b, dtype=bool)
        starts = np.empty((b, n, 6)) if len(restart_ids) else self._no_starts
        if len(restart_ids):
            restart[restart_ids] = True
            starts[restart_ids] = initial
            self.time[restart_ids] = 0.0
            self.steps[restart_ids] = 0
            if self._curved:  # a new episode's projections: a global search, as at reset
                self.arc[restart_ids] = cfg.path.closest(initial[..., X], initial[..., Y])
        obs, comps, reward, flags = self._kernel.run(
            self.state, cmd, self._last_u_c, time0, steer_dy, self.time, self.steps, actions, restart, starts, self.arc
        )
        components = dict(zip(REWARD_COMPONENTS[:-1], comps, strict=True))  # communication: ``step`` adds it
        if cfg.transmit:  # the kernel writes the own part and the slots
            self._traffic(obs, slice(None), *self._kernel.sent_track)
        terminated = flags[:, 0] | flags[:, 1]
        return StepOutput(
            observation=obs,
            reward=reward,
            terminated=terminated,
            truncated=(self.steps >= cfg.max_steps) & ~terminated,
            components=components,
            commanded_speed=None if "u_c" not in commands else np.array(commands["u_c"], copy=True),
            collision=flags[:, 0].copy(),
            out_of_bounds=flags[:, 1].copy(),
            messages={},
            message_totals=np.empty(0),
        )

    def closed_loop(self, commands: dict[str, np.ndarray]) -> Callable[[float, np.ndarray], np.ndarray]:
        """The vector field ``rhs(t, state)`` of the vessels over one control period.

        The inner loops' inputs are saturated at ±tau_u_max, ±tau_r_max, the
        actuator limits of the ``force`` level. ``force`` inputs and the
        ``guidance`` heading ψ_d are held. The commanded
        speed u_c (``speed``, ``guidance``) is ramped from the previous period's
        to the new one (first-order hold) and (11) receives the ramp's slope as
        ``u̇_c``; the first command after a reset is held (zero slope).
        """
        cfg = self.config
        p, gains, printed = cfg.params, cfg.gains, cfg.paper_as_printed
        sea = self._current_at(self.time)
        if self._curved and cfg.action_level != "force":
            return self._closed_loop_curved(commands, sea)
        if cfg.action_level == "force":
            tau_u, tau_r = commands["tau_u"], commands["tau_r"]
            return lambda t, s: vessel_rhs(p, s, tau_u, tau_r, None, sea(t))
        clip, tu_max, tr_max = np.clip, cfg.tau_u_max, cfg.tau_r_max  # actuator limits apply at every level
        u_c0 = self._last_u_c
        u_c_dot = (commands["u_c"] - u_c0) / cfg.dt
        if cfg.action_level == "guidance":
            psi_d = commands["psi_d"]

            def rhs_guidance(t: float, s: np.ndarray) -> np.ndarray:
                psi, u, v, r = s[..., PSI], s[..., U], s[..., V], s[..., R]
                acc = accelerations(p, u, v, r)
                tau_u, tau_r = heading_tracking_inputs(
                    p, gains, psi_d, psi, u, v, r, u_c0 + u_c_dot * t, u_c_dot, printed, acc
                )
                return vessel_rhs(p, s, clip(tau_u, -tu_max, tu_max), clip(tau_r, -tr_max, tr_max), acc, sea(t))

            return rhs_guidance
        dy = self._steer_dy()

        def rhs_speed(t: float, s: np.ndarray) -> np.ndarray:
            psi, u, v, r = s[..., PSI], s[..., U], s[..., V], s[..., R]
            acc = accelerations(p, u, v, r)
            tau_u, tau_r = path_following_inputs(
                p, gains, s[..., Y] - dy, psi, u, v, r, u_c0 + u_c_dot * t, u_c_dot, printed, acc
            )
            return vessel_rhs(p, s, clip(tau_u, -tu_max, tu_max), clip(tau_r, -tr_max, tr_max), acc, sea(t))

        return rhs_speed

    def _closed_loop_curved(
        self, commands: dict[str, np.ndarray], sea: Callable[[float], tuple[Any, Any] | None]
    ) -> Callable[[float, np.ndarray], np.ndarray]:
        """``closed_loop`` on a curved path (``speed``, ``guidance``): the loops of docs/paths.md.

        At every RK4 stage the vessels' path coordinates are computed from the
        stage's state, projecting from the step's start (``arc``, which
        the step moves on only after each RK4 step). At
        ``guidance`` the heading command is relative to the path, ``ψ_d = γ(ℓ) + β_d``.
        """
        cfg = self.config
        p, gains, path = cfg.params, cfg.gains, cfg.path
        clip, tu_max, tr_max = np.clip, cfg.tau_u_max, cfg.tau_r_max
        u_c0 = self._last_u_c
        u_c_dot = (commands["u_c"] - u_c0) / cfg.dt
        beta_d = commands.get("psi_d")
        steer_dy = self._steer_dy()

        def rhs_curved(t: float, s: np.ndarray) -> np.ndarray:
            psi, u, v, r = s[..., PSI], s[..., U], s[..., V], s[..., R]
            c = path_coordinates(path, s[..., X], s[..., Y], psi, u, v, self.arc)
            acc = accelerations(p, u, v, r)
            u_c = u_c0 + u_c_dot * t
            if beta_d is None:  # speed: LOS on the error it steers on (D_y shifted by integral LOS)
                tau_u, tau_r = curved_path_following_inputs(
                    p, gains, c.offset - steer_dy, c.beta, c.kappa, c.metric, u, v, r, u_c, u_c_dot, acc
                )
            else:
                tau_u, tau_r = curved_heading_inputs(
                    p, gains, beta_d, c.beta, c.kappa, c.metric, u, v, r, u_c, u_c_dot, acc
                )
            return vessel_rhs(p, s, clip(tau_u, -tu_max, tu_max), clip(tau_r, -tr_max, tr_max), acc, sea(t))

        return rhs_curved

    # ------------------------------------------------------------ observation
    def _coordinates(self, s: np.ndarray, guess: np.ndarray, time: np.ndarray | None = None) -> PathCoordinates:
        """Path coordinates of states ``s`` ``(b, N, 6)`` on a curved path, projecting from ``guess``.

        With ``time``, ℓ̇ is over ground (the current's component along the path added).
        """
        current = None
        if time is not None and self._current is not None:
            current = current_velocity(*self._current, np.asarray(time)[:, None])
        return path_coordinates(
            self.config.path, s[..., X], s[..., Y], s[..., PSI], s[..., U], s[..., V], guess, current
        )

    def _cross_track(self, s: np.ndarray) -> np.ndarray:
        """``(B, N)`` cross-track errors e of states ``s`` of every formation."""
        if not self._curved:
            return s[..., Y] - self._dy  # type: ignore[no-any-return]
        return self._coordinates(s, self.arc).offset - self._dy  # type: ignore[no-any-return]

    def _current_at(self, t0: np.ndarray) -> Callable[[float], tuple[Any, Any] | None]:
        """The current ``(V_x, V_y)`` ``(B, 1)`` at ``t0 + t`` as a function of ``t`` (None: still water)."""
        if self._current is None:
            return lambda _t: None
        speed, amplitude, omega, cos_dir, sin_dir = self._current
        start = t0[:, None]
        return lambda t: current_velocity(speed, amplitude, omega, cos_dir, sin_dir, start + t)

    def _along_track(
        self, s: np.ndarray, time: np.ndarray | None = None, inertial: bool = False, ids: Any = slice(None)
    ) -> tuple[np.ndarray, np.ndarray]:
        """θ = x − D_x and ẋ of states ``s`` ``(b, N, 6)`` of formations ``ids``.

        ẋ is through the water (``u cos ψ − v sin ψ``), or with ``inertial`` over
        ground, adding the current's V_x at ``time`` ``(b,)``. On a curved path:
        θ = ℓ − D_x and ℓ̇ (docs/paths.md).
        """
        if self._curved:
            c = self._coordinates(s, self.arc[ids], time if inertial else None)
            return c.ell - self._dx, c.ell_dot
        theta, x_dot = along_track(s[..., X], self._dx, s[..., PSI], s[..., U], s[..., V])
        if inertial and self._current is not None:
            x_dot = x_dot + current_velocity(*self._current, np.asarray(time)[:, None])[0]
        return theta, x_dot

    def observe(self, env_ids: np.ndarray | slice | None = None) -> np.ndarray:
        """Masked per-agent observations ``(B, N, dim)`` float32 (module docstring).

        With ``env_ids``, only those formations' observations ``(len(env_ids), N, dim)``.
        """
        cfg = self.config
        ids = slice(None) if env_ids is None else env_ids
        s, time = self.measured[ids], self.time[ids]
        b, n = s.shape[0], self.n
        out = np.zeros((b, n, self.layout.dim), dtype=np.float32)
        coords = None
        if self._curved:
            coords = self._coordinates(s, self.arc[ids], time if self.channel is not None else None)
            out[..., 0] = coords.offset - self._dy
            out[..., 1] = wrap_angle(coords.beta)
            out[..., CURVATURE] = coords.kappa
            out[..., CURVATURE_AHEAD] = cfg.path.curvature(coords.ell + LOOKAHEAD)
        else:
            out[..., 0] = s[..., Y] - self._dy
            out[..., 1] = wrap_angle(s[..., PSI])
        out[..., 2:5] = s[..., U : R + 1]
        out[..., 5] = cfg.u_d.value(time)[:, None]
        out[..., 6] = cfg.u_d.rate(time)[:, None]
        out[..., LANE_OFFSET] = self._dy
        # the n − 1 vessels' slots (padding slots beyond them stay 0: not linked)
        slots = out[..., self.layout.own : self.layout.slots_end].reshape(b, n, self.layout.slots, self.layout.slot)[
            :, :, : n - 1
        ]
        if coords is not None:
            theta, x_dot = coords.ell - self._dx, coords.ell_dot
        if self.channel is None:
            if coords is None:
                theta, x_dot = self._along_track(s)
            idx = self._slot_index
            slots[..., LINK] = self._slot_mask
            slots[..., COORDINATION], slots[..., VELOCITY] = slot_differences(
                self._slot_mask, theta[:, :, None], theta[:, idx], x_dot[:, :, None], x_dot[:, idx]
            )
        else:
            if coords is None:
                theta, x_dot = self._along_track(s, time, inertial=True)
            for k, feature in enumerate(self.channel.slots(ids, self._slot_index, time, theta, x_dot)):
                slots[..., k] = feature
            if cfg.transmit:
                self._traffic(out, ids, theta, x_dot)
        return np.clip(out, self.obs_low, self.obs_high, out=out)

    def messages(self, env_ids: np.ndarray | slice | None = None) -> dict[str, np.ndarray]:
        """The messages of the last control instant per vessel, by ``MESSAGE_KEYS``, each ``(B, N)`` int64
        (with ``env_ids``, those formations'). With ideal links every vessel broadcasts once and reaches
        each out-neighbour of the graph."""
        block = self._message_block(env_ids)
        return {key: block[..., k] for k, key in enumerate(MESSAGE_KEYS)}

    def _message_block(self, env_ids: np.ndarray | slice | None = None) -> np.ndarray:
        """``(B, N, len(MESSAGE_KEYS))`` int64: the counters and the bits, a new array (read-only and made
        once for all formations with ideal links, where it is the same at every step)."""
        ids = slice(None) if env_ids is None else env_ids
        if self.channel is None:
            b = len(self.time[ids])
            if b == self.num_envs and self._ideal_block is not None:
                return self._ideal_block
            block = self._counted(np.broadcast_to(self._ideal_counts, (b, *self._ideal_counts.shape)))
            if b == self.num_envs:
                block.setflags(write=False)
                self._ideal_block = block
            return block
        return self._counted(self.channel.counts[ids])

    def _counted(self, counts: np.ndarray) -> np.ndarray:
        """``(B, len(COUNTERS), N)`` counters and the bits they sent as one new ``(B, N, len(MESSAGE_KEYS))``."""
        block = np.empty((counts.shape[0], counts.shape[2], len(MESSAGE_KEYS)), dtype=np.int64)
        block[..., :-1] = counts.transpose(0, 2, 1)
        np.multiply(counts[:, SENT], self.config.channel.message_bits, out=block[..., -1])
        return block

    def _traffic(self, obs: np.ndarray, ids: np.ndarray | slice, theta: np.ndarray, x_dot: np.ndarray) -> None:
        """Write ``TRANSMIT_FEATURES`` into the last entries of observations ``obs`` of formations ``ids``,
        whose vessels measure ``theta``, ``x_dot`` ``(len(ids), N)`` of themselves (what they would send)."""
        channel = self.channel
        assert channel is not None
        elapsed = self.time[ids][:, None] - channel.sent_time[ids]
        obs[..., -3] = channel.tokens[ids] / channel.channel.bucket
        obs[..., -2] = np.minimum(elapsed, self.config.horizon)
        drift = prediction_error(theta, x_dot, channel.sent_theta[ids], channel.sent_xdot[ids], elapsed)
        obs[..., -1] = np.minimum(drift, MAX_DRIFT)  # ∞ before a vessel's first broadcast

    def links_up(self, b: int) -> np.ndarray:
        """``(N, N)`` booleans of formation ``b``: ``[j, i]`` iff the link i → j exists now."""
        if self.channel is None:
            return self.config.graph.adjacency.copy()
        return self.channel.up[b].copy()

    def global_state(self) -> np.ndarray:
        """``(B, N·6 + 1)`` float32: every vessel's state (ψ wrapped) and the time [s]."""
        s = self.state.copy()
        s[..., PSI] = wrap_angle(s[..., PSI])
        return np.concatenate([s.reshape(self.num_envs, -1), self.time[:, None]], axis=1).astype(np.float32)

    def _outputs(self, actions: np.ndarray, u_c: np.ndarray | None) -> StepOutput:
        cfg, w = self.config, self.config.reward
        s = self.state
        if self._curved:
            c = self._coordinates(s, self.arc)
            theta, x_dot, e, heading = c.ell - self._dx, c.ell_dot, c.offset - self._dy, c.beta
        else:
            theta, x_dot = self._along_track(s)
            e, heading = s[..., Y] - self._dy, s[..., PSI]
        u_d = cfg.u_d.value(self.time)[:, None]
        dt = cfg.dt
        # the tracking errors, in TRACKING_TERMS order
        errors = (e, wrap_angle(heading), theta - theta.mean(axis=1, keepdims=True), x_dot - u_d)
        components = {
            term: cost_term(weight, error, sigma, dt, share, w.fine_scale)
            for term, weight, error, sigma, share in zip(
                TRACKING_TERMS, w.tracking_weights, errors, w.tracking_sigmas, w.fine_shares, strict=True
            )
        }
        components["effort"] = effort_term(w.effort, np.mean(np.square(actions), axis=-1), dt)
        out_of_bounds = np.any(
            outside_workspace(s[..., X], s[..., Y], *cfg.workspace)
            | outside_envelope(s[..., U], s[..., V], s[..., R], cfg.max_speed, cfg.max_yaw_rate),
            axis=1,
        )
        out_of_bounds |= ~np.all(np.isfinite(s), axis=(1, 2))  # an unstable state ends the episode too
        if self._curved:  # a vessel far from its lane is out of bounds
            out_of_bounds |= np.any(np.abs(e) > cfg.corridor, axis=1)
        collision = min_separation(s) < cfg.safety_distance
        terminated = out_of_bounds | collision
        components["terminal"] = np.broadcast_to(
            terminal_term(terminated, w.terminal_rate, cfg.horizon - self.time)[:, None], (self.num_envs, self.n)
        ).copy()
        reward = sum(components.values())
        truncated = (self.steps >= cfg.max_steps) & ~terminated
        return StepOutput(
            observation=self.observe(),
            reward=np.asarray(reward),
            terminated=terminated,
            truncated=truncated,
            components=components,
            commanded_speed=None if u_c is None else np.array(u_c, copy=True),
            collision=collision,
            out_of_bounds=out_of_bounds,
            messages={},
            message_totals=np.empty(0),
        )
