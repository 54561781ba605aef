"""Scenario configuration: one frozen dataclass holding everything an episode needs.

A *scenario* is a named set of defaults (:data:`SCENARIOS`); :func:`make_config`
applies keyword overrides on top of it and validates the result against the
paper's assumptions, so an environment is never built from a configuration that
silently breaks them. Every front end (the PettingZoo env, the gymnasium views,
the vector env) is built from a :class:`ScenarioConfig`.

Override keys are the field names of :class:`ScenarioConfig`; an unknown key
raises an error that lists the valid ones.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from marine_formation_env.channel import ChannelConfig, GilbertElliott
from marine_formation_env.disturbances import Current, SensorNoise
from marine_formation_env.errors import (
    ConfigError,
    build_config,
    check_bool,
    check_number,
    check_seed,
    whole_periods,
)
from marine_formation_env.graph import CommGraph, GraphError, make_graph
from marine_formation_env.params import Gains, ParameterError, VesselParams, get_vessel

__all__ = [
    "ACTION_LEVELS",
    "FORMATIONS",
    "PAPER_INITIAL_STATE",
    "SCENARIOS",
    "ConfigError",
    "InitNoise",
    "RewardConfig",
    "ScenarioConfig",
    "SpeedProfile",
    "config_from_dict",
    "formation_offsets",
    "initial_state_problem",
    "make_config",
]

#: What a policy controls (docs/model.md §6), with the default control period dt [s].
ACTION_LEVELS: dict[str, float] = {"force": 0.1, "guidance": 0.5, "speed": 0.5}

#: Largest RK4 step [s] used when ``substeps`` is not given: ``substeps = ceil(dt/0.1)``.
MAX_RK4_STEP = 0.1

#: docs/model.md §5 initial state (columns x [m], y [m], ψ [rad], u [m/s], v [m/s], r [rad/s]).
PAPER_INITIAL_STATE = np.array(
    [
        [-50.0, 20.0, 0.0, 3.0, 0.0, 0.0],
        [-60.0, 30.0, 0.3, 3.0, 0.0, 0.0],
        [-120.0, -10.0, -0.2, 3.0, 0.0, 0.0],
    ]
)

#: Formation patterns (D_x, D_y) [m] for :func:`formation_offsets`.
FORMATIONS = ("paper", "v", "line_abreast", "column")

ALONG_SPACING = 100.0  # [m] between rows of the generated formations
ACROSS_SPACING = 50.0  # [m] between paths of the generated formations


def formation_offsets(pattern: str, n: int) -> np.ndarray:
    """Desired offsets ``(D_x, D_y)`` [m] of ``n`` vessels, shape ``(n, 2)``.

    * ``paper``: the paper's V of three vessels, (−100, 50), (0, 0), (−100, −50).
    * ``v``: vessel 0 leads at (0, 0); vessels 2k−1 and 2k sit at
      (−100k, +50k) and (−100k, −50k).
    * ``line_abreast``: side by side, 50 m apart, centred on y = 0.
    * ``column``: in line on y = 0, 100 m apart.
    """
    if pattern == "paper":
        if n != 3:
            raise ConfigError(f"formation 'paper' is defined for 3 vessels, got n_vessels = {n}")
        return np.array([[-100.0, 50.0], [0.0, 0.0], [-100.0, -50.0]])
    if pattern == "v":
        rows = [(0.0, 0.0)]
        for j in range(1, n):
            k = (j + 1) // 2
            side = 1.0 if j % 2 else -1.0
            rows.append((-ALONG_SPACING * k, side * ACROSS_SPACING * k))
        return np.array(rows)
    if pattern == "line_abreast":
        return np.column_stack([np.zeros(n), ACROSS_SPACING * (np.arange(n) - (n - 1) / 2.0)])
    if pattern == "column":
        return np.column_stack([-ALONG_SPACING * np.arange(n), np.zeros(n)])
    raise ConfigError(f"unknown formation {pattern!r}; known formations: {list(FORMATIONS)}")


@dataclass(frozen=True)
class SpeedProfile:
    """Desired formation speed ``u_d(t) = mean + amplitude·sin(2πt/period)`` [m/s].

    A constant speed has ``amplitude = 0``. Assumption (19) requires
    ``u_d(t) ∈ [U_min + a, U_max − a]``, i.e. ``mean ± amplitude`` inside it.
    """

    mean: float = 5.0
    amplitude: float = 0.0
    period: float = 200.0

    def __post_init__(self) -> None:
        for key in ("mean", "amplitude", "period"):
            check_number("u_d", key, getattr(self, key), minimum=None)
        if self.amplitude < 0 or self.period <= 0:
            raise ConfigError(
                f"u_d needs amplitude ≥ 0 and period > 0, got amplitude={self.amplitude}, period={self.period}"
            )

    def value(self, t: np.ndarray | float) -> np.ndarray:
        """u_d(t) [m/s]."""
        return self.mean + self.amplitude * np.sin(2.0 * np.pi * np.asarray(t) / self.period)

    def rate(self, t: np.ndarray | float) -> np.ndarray:
        """u̇_d(t) [m/s²]."""
        w = 2.0 * np.pi / self.period
        return self.amplitude * w * np.cos(w * np.asarray(t))

    @property
    def bounds(self) -> tuple[float, float]:
        """``(min, max)`` of u_d over all t [m/s]."""
        return self.mean - self.amplitude, self.mean + self.amplitude


@dataclass(frozen=True)
class InitNoise:
    """Half-widths of the uniform noise added to the nominal initial state at reset.

    Attributes:
        x, y: position [m]. psi: heading [rad]. u: surge speed [m/s].
    """

    x: float = 0.0
    y: float = 0.0
    psi: float = 0.0
    u: float = 0.0

    def __post_init__(self) -> None:
        for key in ("x", "y", "psi", "u"):
            check_number("init_noise", key, getattr(self, key))

    def as_array(self) -> np.ndarray:
        """Half-widths for the state columns ``x, y, psi, u, v, r`` (v, r: 0)."""
        return np.array([self.x, self.y, self.psi, self.u, 0.0, 0.0])

    @property
    def is_zero(self) -> bool:
        return not np.any(self.as_array())


@dataclass(frozen=True)
class RewardConfig:
    """Weights and scales of the per-agent reward (see the env docstring).

    Each error ``e`` with scale ``σ`` gives the bounded cost
    ``c(e) = (e/σ)² / (1 + (e/σ)²) ∈ [0, 1)``; the step reward of vessel j is
    ``−dt·Σ_k w_k·c_k``. A formation that terminates early (collision or leaving
    the workspace) receives ``−(Σ_k w_k)·(time left)``, the worst reward the rest
    of the episode could have given, so ending an episode never pays.
    """

    cross_track: float = 1.0
    heading: float = 0.25
    coordination: float = 1.0
    speed: float = 0.5
    effort: float = 0.0
    sigma_cross_track: float = 20.0
    sigma_heading: float = 0.2
    sigma_coordination: float = 20.0
    sigma_speed: float = 1.0
    terminal_penalty: bool = True

    def __post_init__(self) -> None:
        check_bool("reward", "terminal_penalty", self.terminal_penalty)
        for f in dataclasses.fields(self):
            if f.name == "terminal_penalty":
                continue
            value = getattr(self, f.name)
            check_number("reward", f.name, value)
            if f.name.startswith("sigma_") and value == 0:
                raise ConfigError(f"reward.{f.name} must be > 0, got {value!r}")

    @property
    def total_weight(self) -> float:
        """Σ_k w_k: the largest cost rate [1/s]."""
        return self.cross_track + self.heading + self.coordination + self.speed + self.effort


@dataclass(frozen=True, eq=False)
class ScenarioConfig:
    """Everything that defines an episode; build it with :func:`make_config`.

    Attributes:
        name: scenario name.
        n_vessels: number of vessels n ≥ 2.
        formation: ``(n, 2)`` desired offsets (D_x, D_y) [m], or a pattern name
            (:data:`FORMATIONS`).
        topology: communication graph: a preset name (:func:`make_graph`), a
            :class:`CommGraph`, or an ``(n, n)`` adjacency matrix
            (``A[j, i] = 1`` iff i transmits to j).
        topology_schedule: switching topologies: a sequence of ``(dwell [s],
            graph)`` pairs (graphs as for ``topology``) that repeats
            periodically; excludes ``topology``, which then becomes the union
            of the scheduled graphs (the links that ever exist). Needs
            reachability of the union only (joint connectivity).
        topology_seed: seed of the ``random`` topology preset.
        allow_unreachable: accept a graph without a globally reachable node
            (consensus then is not guaranteed).
        vessel: vessel parameter set (name or :class:`VesselParams`).
        gains: controller gains and consensus saturation ``a``.
        u_d: desired formation speed [m/s] (number or :class:`SpeedProfile`).
        u_min, u_max: the controllability band (U_min, U_max) [m/s].
        action_level: ``force``, ``guidance`` or ``speed`` (docs/model.md §6).
        dt: control period [s]; default depends on the level (:data:`ACTION_LEVELS`).
        substeps: RK4 steps per control period; default ``ceil(dt / 0.1)``.
        horizon: episode length [s]; truncation after ``round(horizon/dt)`` steps.
        paper_as_printed: run (11) and (14) exactly as printed (docs/model.md §3).
        initial_state: nominal ``(n, 6)`` initial state, or None for the
            formation slots at speed u_d(0) heading along the path.
        init_noise: uniform noise added to the nominal initial state at reset.
        safety_distance: two vessels closer than this [m] collide (terminates).
        workspace: ``(x_min, x_max, y_min, y_max)`` [m]; None derives a box that
            holds the whole nominal run with margins of 500 m (x) and 250 m (y).
        tau_u_max, tau_r_max: actuator limits [m/s², rad/s²]: the ``force``-level
            action range, and the saturation of the built-in loops at the other levels.
        psi_max: ``guidance``-level heading command range ±psi_max [rad].
        max_speed: envelope of |u| and |v| [m/s]; beyond it the formation
            terminates (the model is not meant for it). Must exceed u_max.
        max_yaw_rate: envelope of |r| [rad/s]; beyond it the formation terminates.
        reward: reward weights and scales.
        channel: the communication channel (:class:`ChannelConfig`, or a
            mapping of its fields): loss, latency, update rate, TDMA, range,
            random link failures. The default is the paper's ideal links.
        current: an ocean current (:class:`Current` or a mapping); its speed
            plus amplitude must stay below u_min, or a vessel at the slowest
            allowed speed could not hold its path.
        sensor_noise: noise on each vessel's measurement of itself
            (:class:`SensorNoise` or a mapping).
        los_integral_gain: σ [m/s] of integral LOS in the ``speed`` level's
            built-in path follower (our extension, Børhaug, Pavlov and
            Pettersen, CDC 2008): it steers on ``e + σ·e_int`` with
            ``ė_int = Δ·e/((e + σ·e_int)² + Δ²)``, integrated once per control
            period, which removes the steady cross-track error a current
            leaves. 0: the paper's LOS (12). Choose σ above the largest cross
            current. Only at ``speed``; at the other levels the policy steers.
    """

    name: str = "custom"
    n_vessels: int = 3
    formation: Any = "v"
    topology: Any = "chain"
    topology_seed: int = 0
    allow_unreachable: bool = False
    vessel: Any = "supply"
    gains: Gains = field(default_factory=Gains)
    u_d: Any = 5.0
    u_min: float = 3.0
    u_max: float = 7.0
    action_level: str = "speed"
    dt: Any = None  # resolved to float: the level's default when None
    substeps: Any = None  # resolved to int: ceil(dt / 0.1 s) when None
    horizon: float = 400.0
    paper_as_printed: bool = False
    initial_state: Any = None
    init_noise: Any = field(default_factory=InitNoise)
    safety_distance: float = 5.0
    workspace: Any = None
    tau_u_max: float = 3.0
    tau_r_max: float = 2.0
    psi_max: float = math.pi / 2
    max_speed: float = 14.0
    max_yaw_rate: float = 1.0
    reward: Any = field(default_factory=RewardConfig)
    channel: Any = field(default_factory=ChannelConfig)
    current: Any = field(default_factory=Current)
    sensor_noise: Any = field(default_factory=SensorNoise)
    topology_schedule: Any = ()
    los_integral_gain: float = 0.0

    def __post_init__(self) -> None:
        set_ = lambda key, value: object.__setattr__(self, key, value)
        n = self.n_vessels
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
            raise ConfigError(f"n_vessels must be an integer ≥ 2, got {n!r}")
        set_("n_vessels", int(n))
        if not isinstance(self.name, str):
            raise ConfigError(f"name must be a string, got {self.name!r}")
        if not isinstance(self.action_level, str) or self.action_level not in ACTION_LEVELS:
            raise ConfigError(f"unknown action_level {self.action_level!r}; choose one of {list(ACTION_LEVELS)}")
        for key in ("paper_as_printed", "allow_unreachable"):
            if not isinstance(getattr(self, key), bool):
                raise ConfigError(f"{key} must be True or False, got {getattr(self, key)!r}")
        try:
            set_("topology_seed", check_seed(self.topology_seed, "topology_seed", allow_none=False))
        except (TypeError, ValueError) as err:
            raise ConfigError(str(err)) from None

        # formation offsets
        if isinstance(self.formation, str):
            offsets = formation_offsets(self.formation, n)
        else:
            offsets = _float_array(self.formation, "formation", (n, 2))
        if len({(float(a), float(b)) for a, b in offsets}) < n:
            raise ConfigError(f"formation offsets must be distinct, got {offsets.tolist()}")
        set_("formation", _readonly(offsets))

        # communication graph(s)
        schedule = self._resolve_schedule()
        if schedule:
            if self.topology is not None:
                raise ConfigError(
                    f"give either topology ({self.topology!r}) or topology_schedule, not both: with a schedule the "
                    "links come from the scheduled graphs"
                )
            union = np.logical_or.reduce([g.adjacency for _, g in schedule])
            graph = CommGraph(union, name="union of topology_schedule")
        elif self.topology is None:
            raise ConfigError("topology must be a preset name, a CommGraph or an (n, n) adjacency matrix, got None")
        else:
            graph = self._resolve_graph(self.topology, "topology")
        if not self.allow_unreachable:
            try:
                graph.require_globally_reachable()
            except GraphError as err:
                raise ConfigError(f"{'topology_schedule' if schedule else 'topology'}: {err}") from None
        set_("topology", graph)

        # vessel, gains, speeds: the paper's assumptions
        try:
            vessel = get_vessel(self.vessel)
        except ValueError as err:
            raise ConfigError(str(err)) from None
        set_("vessel", vessel)
        if not isinstance(self.gains, Gains):
            if isinstance(self.gains, Mapping):
                set_("gains", build_config(Gains, self.gains, "gains"))
            else:
                raise ConfigError(f"gains must be a Gains or a mapping, got {self.gains!r}")
        for key in (
            "u_min",
            "u_max",
            "horizon",
            "safety_distance",
            "tau_u_max",
            "tau_r_max",
            "psi_max",
            "max_speed",
            "max_yaw_rate",
        ):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{key} must be a finite number, got {value!r}")
        if not self.u_min > 0:
            raise ConfigError(f"U_min must be > 0 (the vessels are uncontrollable at rest), got u_min = {self.u_min}")
        if not self.u_max > self.u_min:
            raise ConfigError(f"u_max = {self.u_max} must exceed u_min = {self.u_min}")
        if isinstance(self.u_d, SpeedProfile):
            profile = self.u_d
        elif isinstance(self.u_d, Mapping):
            profile = build_config(SpeedProfile, self.u_d, "u_d")
        else:
            profile = SpeedProfile(mean=self.u_d)
        set_("u_d", profile)
        lo, hi = profile.bounds
        a = self.gains.a
        if lo < self.u_min + a - 1e-12 or hi > self.u_max - a + 1e-12:
            raise ConfigError(
                f"u_d(t) ranges over [{lo:g}, {hi:g}] m/s but assumption (19) needs it inside "
                f"[U_min + a, U_max − a] = [{self.u_min + a:g}, {self.u_max - a:g}] m/s "
                f"(u_min = {self.u_min:g}, u_max = {self.u_max:g}, gains.a = {a:g})"
            )
        try:
            vessel.validate_speed_band(self.u_min, self.u_max, self.gains.delta)
        except ParameterError as err:
            raise ConfigError(str(err)) from None

        # timing
        dt = ACTION_LEVELS[self.action_level] if self.dt is None else self.dt
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (math.isfinite(dt) and dt > 0):
            raise ConfigError(f"dt (control period) must be a finite number > 0 s, got {dt!r}")
        set_("dt", float(dt))
        substeps = max(1, math.ceil(self.dt / MAX_RK4_STEP - 1e-9)) if self.substeps is None else self.substeps
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise ConfigError(f"substeps must be an integer ≥ 1, got {substeps!r}")
        set_("substeps", int(substeps))
        for k, (dwell, _) in enumerate(schedule):
            whole_periods(dwell, self.dt, f"topology_schedule[{k}] dwell")
        if not self.horizon >= self.dt:
            raise ConfigError(f"horizon = {self.horizon} s must be at least one control period dt = {self.dt} s")
        for key in ("tau_u_max", "tau_r_max", "psi_max", "max_yaw_rate"):
            if not getattr(self, key) > 0:
                raise ConfigError(f"{key} must be > 0, got {getattr(self, key)!r}")
        if not self.max_speed > self.u_max:
            raise ConfigError(f"max_speed = {self.max_speed} m/s must exceed u_max = {self.u_max} m/s")
        if self.safety_distance < 0:
            raise ConfigError(f"safety_distance must be ≥ 0 m, got {self.safety_distance!r}")

        # initial state
        noise = self.init_noise
        if not isinstance(noise, InitNoise):
            if isinstance(noise, Mapping):
                noise = build_config(InitNoise, noise, "init_noise")
            else:
                values = _float_array(noise, "init_noise", (4,))
                noise = InitNoise(*map(float, values))
            set_("init_noise", noise)
        if self.initial_state is None:
            nominal = np.zeros((n, 6))
            nominal[:, :2] = offsets
            nominal[:, 3] = float(profile.value(0.0))
        else:
            nominal = _float_array(self.initial_state, "initial_state", (n, 6))
        set_("initial_state", _readonly(nominal))

        if not isinstance(self.reward, RewardConfig):
            if isinstance(self.reward, Mapping):
                set_("reward", build_config(RewardConfig, self.reward, "reward"))
            else:
                raise ConfigError(f"reward must be a RewardConfig or a mapping, got {self.reward!r}")

        # workspace
        if self.workspace is None:
            spread = noise.as_array()
            x_lo = float(np.min(nominal[:, 0]) - spread[0]) - 500.0
            x_hi = float(np.max(nominal[:, 0]) + spread[0]) + self.u_max * self.horizon + 500.0
            y_ext = float(max(np.max(np.abs(nominal[:, 1])) + spread[1], np.max(np.abs(offsets[:, 1])))) + 250.0
            box = (x_lo, x_hi, -y_ext, y_ext)
        else:
            x0, x1, y0, y1 = (float(v) for v in _float_array(self.workspace, "workspace", (4,)))
            box = (x0, x1, y0, y1)
            if not (box[0] < box[1] and box[2] < box[3]):
                raise ConfigError(f"workspace (x_min, x_max, y_min, y_max) must have min < max, got {box}")
        set_("workspace", box)

        # the sea and the channel (our extensions)
        for key, cls in (("channel", ChannelConfig), ("current", Current), ("sensor_noise", SensorNoise)):
            value = getattr(self, key)
            if not isinstance(value, cls):
                if not isinstance(value, Mapping):
                    raise ConfigError(f"{key} must be a {cls.__name__} or a mapping of its fields, got {value!r}")
                set_(key, build_config(cls, dict(value), key))
        self.channel.validate(self.dt, n)
        check_number("scenario", "los_integral_gain", self.los_integral_gain)
        if self.los_integral_gain > 0 and self.action_level != "speed":
            raise ConfigError(
                f"los_integral_gain = {self.los_integral_gain} applies to the speed level's built-in LOS; at "
                f"action_level {self.action_level!r} the policy steers (ReferencePolicy(env, integral_los=σ) does ILOS)"
            )
        strongest = self.current.speed + self.current.amplitude
        if strongest >= self.u_min:
            raise ConfigError(
                f"current speed + amplitude = {strongest:g} m/s must stay below u_min = {self.u_min:g} m/s: a vessel "
                "at the slowest allowed speed could not hold its path against it"
            )
        problem = initial_state_problem(self, nominal, noise.as_array())
        if problem is not None:
            raise ConfigError(f"initial_state: {problem}")

    def _resolve_graph(self, spec: Any, name: str) -> CommGraph:
        n = self.n_vessels
        try:
            if isinstance(spec, CommGraph):
                graph = spec
            elif isinstance(spec, str):
                graph = make_graph(spec, n, seed=self.topology_seed)
            else:
                graph = CommGraph.from_adjacency(spec)
        except GraphError as err:
            raise ConfigError(f"{name}: {err}") from None
        if graph.n != n:
            raise ConfigError(f"{name} has {graph.n} vessels but n_vessels = {n}")
        return graph

    def _resolve_schedule(self) -> tuple[tuple[float, CommGraph], ...]:
        raw = self.topology_schedule
        if raw is None or (isinstance(raw, (tuple, list)) and len(raw) == 0):
            object.__setattr__(self, "topology_schedule", ())
            return ()
        if isinstance(raw, (str, Mapping)) or not isinstance(raw, (tuple, list)):
            raise ConfigError(f"topology_schedule must be a sequence of (dwell_seconds, graph) pairs, got {raw!r}")
        out = []
        for k, entry in enumerate(raw):
            if not isinstance(entry, (tuple, list)) or len(entry) != 2:
                raise ConfigError(f"topology_schedule[{k}] must be a (dwell_seconds, graph) pair, got {entry!r}")
            dwell, spec = entry
            check_number(f"topology_schedule[{k}]", "dwell [s]", dwell, strict=True)
            out.append((float(dwell), self._resolve_graph(spec, f"topology_schedule[{k}]")))
        schedule = tuple(out)
        object.__setattr__(self, "topology_schedule", schedule)
        return schedule

    # --------------------------------------------------------------- derived
    @property
    def ideal_observations(self) -> bool:
        """Ideal links, one fixed graph and noise-free measurements: the paper's information."""
        return self.channel.is_ideal and not self.topology_schedule and self.sensor_noise.is_zero

    @property
    def graph(self) -> CommGraph:
        """The resolved communication graph."""
        return self.topology  # type: ignore[no-any-return]

    @property
    def params(self) -> VesselParams:
        """The resolved vessel parameters."""
        return self.vessel  # type: ignore[no-any-return]

    @property
    def max_steps(self) -> int:
        """Control periods per episode (truncation)."""
        return max(1, round(self.horizon / self.dt))

    @property
    def action_dim(self) -> int:
        """Per-vessel action size: 2 (force, guidance) or 1 (speed)."""
        return 1 if self.action_level == "speed" else 2

    def to_dict(self) -> dict[str, Any]:
        """A JSON-friendly description (resolved values; an infinite number is the string ``"inf"``)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, CommGraph):
                value = {"name": value.name, "links": value.links}
            elif f.name == "topology_schedule":
                value = [{"dwell": dwell, "name": g.name, "links": g.links} for dwell, g in value]
            elif isinstance(value, VesselParams):
                value = dataclasses.asdict(value)
            elif dataclasses.is_dataclass(value) and not isinstance(value, type):
                value = dataclasses.asdict(value)
            elif isinstance(value, np.ndarray):
                value = value.tolist()
            elif isinstance(value, tuple):
                value = list(value)
            out[f.name] = _finite_json(value)
        return out


def initial_state_problem(config: ScenarioConfig, state: np.ndarray, noise: np.ndarray | None = None) -> str | None:
    """Why an ``(n, 6)`` initial state would end the episode at its first step, or None.

    A vessel outside the workspace or outside the envelope (|u|, |v| >
    max_speed, |r| > max_yaw_rate), or two vessels closer than the safety
    distance, terminate the formation before any policy acts: such a start is
    an error in the scenario, not an episode. ``noise`` (half-widths of the
    columns, as :meth:`InitNoise.as_array`) widens each value to the range the
    reset can draw; the separation check uses the nominal positions (draws
    that bring two vessels too close are rejected at reset).
    """
    state = np.asarray(state, dtype=float)
    spread = np.zeros(6) if noise is None else np.asarray(noise, dtype=float)
    x_lo, x_hi, y_lo, y_hi = config.workspace
    bounds = (
        ("x", 0, x_lo, x_hi, "m", "the workspace"),
        ("y", 1, y_lo, y_hi, "m", "the workspace"),
        ("u", 3, -config.max_speed, config.max_speed, "m/s", "the envelope |u| ≤ max_speed"),
        ("v", 4, -config.max_speed, config.max_speed, "m/s", "the envelope |v| ≤ max_speed"),
        ("r", 5, -config.max_yaw_rate, config.max_yaw_rate, "rad/s", "the envelope |r| ≤ max_yaw_rate"),
    )
    for name, col, lo, hi, unit, what in bounds:
        low, high = state[:, col] - spread[col], state[:, col] + spread[col]
        bad = np.flatnonzero((low < lo) | (high > hi))
        if bad.size:
            j = int(bad[0])
            value = low[j] if low[j] < lo else high[j]
            drawn = f" (nominal {state[j, col]:g} ± init_noise {spread[col]:g})" if spread[col] else ""
            return (
                f"vessel_{j} starts at {name} = {value:g} {unit}{drawn}, outside {what}: "
                f"{name} ∈ [{lo:g}, {hi:g}] {unit}; the episode would end at its first step"
            )
    if config.safety_distance > 0:
        first, second = np.triu_indices(state.shape[0], k=1)
        dist = np.hypot(state[first, 0] - state[second, 0], state[first, 1] - state[second, 1])
        close = np.flatnonzero(dist < config.safety_distance)
        if close.size:
            k = int(close[0])
            return (
                f"vessel_{first[k]} and vessel_{second[k]} start {dist[k]:g} m apart, closer than safety_distance = "
                f"{config.safety_distance:g} m; the episode would end at its first step"
            )
    return None


def config_from_dict(data: Mapping[str, Any]) -> ScenarioConfig:
    """Rebuild a :class:`ScenarioConfig` from :meth:`ScenarioConfig.to_dict` (e.g. a JSON report's ``config``).

    ``config_from_dict(cfg.to_dict()).to_dict() == cfg.to_dict()`` for every
    valid configuration (tests/test_input_errors.py checks it on random input).

    Raises:
        ConfigError: ``data`` is not such a description, or the values are invalid.
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"a scenario description must be a mapping, got {data!r}")
    values = _from_json(dict(data))
    unknown = sorted(set(values) - {f.name for f in dataclasses.fields(ScenarioConfig)})
    if unknown:
        raise ConfigError(f"unknown scenario key(s) {unknown} in the description")
    n = values.get("n_vessels", 3)
    try:
        schedule = values.get("topology_schedule") or []
        if schedule:
            values["topology"] = None  # the union of the scheduled graphs is derived again
            values["topology_schedule"] = [
                (entry["dwell"], CommGraph.from_links(n, entry["links"], entry["name"])) for entry in schedule
            ]
        topology = values.get("topology")
        if isinstance(topology, Mapping):
            values["topology"] = CommGraph.from_links(n, topology["links"], topology["name"])
        vessel = values.get("vessel")
        if isinstance(vessel, Mapping):
            values["vessel"] = VesselParams(**vessel)
    except (KeyError, TypeError, GraphError, ParameterError) as err:
        raise ConfigError(f"not a scenario description written by ScenarioConfig.to_dict: {err!r}") from None
    return ScenarioConfig(**values)


def _from_json(value: Any) -> Any:
    """Inverse of :func:`_finite_json`: ``"inf"``/``"-inf"`` back to floats (names stay strings)."""
    if isinstance(value, dict):
        return {k: v if k == "name" else _from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_from_json(v) for v in value]
    if value == "inf" or value == "-inf":
        return float(value)
    return value


def _finite_json(value: Any) -> Any:
    """``value`` with tuples as lists and every infinite float as ``"inf"``/``"-inf"`` (strict JSON has no infinity)."""
    if isinstance(value, dict):
        return {k: _finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_json(v) for v in value]
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return value


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=float)
    arr.setflags(write=False)
    return arr


def _float_array(value: Any, name: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a numeric array of shape {shape}, got {value!r}") from None
    if arr.shape != shape:
        raise ConfigError(f"{name} must have shape {shape}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ConfigError(f"{name} must be finite, but {name}[{', '.join(map(str, bad))}] = {arr[tuple(bad)]}")
    return arr


#: The paper's scenario (docs/model.md §5).
_PAPER: dict[str, Any] = {
    "name": "paper",
    "n_vessels": 3,
    "formation": "paper",
    "topology": "paper",
    "initial_state": PAPER_INITIAL_STATE,
    # The docs/model.md §5 initial state makes vessel_0 and vessel_1 cross paths: under
    # the paper's controller they pass 0.5-0.7 m apart (as point masses). The
    # paper does not model collisions, so the check is off in this scenario.
    "safety_distance": 0.0,
}

#: Named scenarios: defaults that :func:`make_config` starts from. Besides the
#: paper's own, three presets put its scenario into the sea the paper is
#: motivated by (numbers and reasons in the README, "Beyond the paper"):
#:
#: * ``acoustic``: underwater acoustic modems. One shared channel in TDMA with
#:   4 s slots (a short acoustic frame at tens to hundreds of bit/s takes
#:   seconds), so each vessel updates every 12 s; 1-2 s from sending to
#:   arrival (frame duration plus sound at ~1500 m/s, decoding); bursty loss
#:   (Gilbert–Elliott, 20 % of messages lost on average, bad spells of about
#:   3 messages); 2 km range.
#: * ``radio``: surface radio. One shared channel in TDMA with 0.5 s slots
#:   (each vessel updates every 1.5 s), 5 % independent loss, 50 ms latency
#:   (delivered at the next control instant, as a message never arrives
#:   before it could), 5 km range.
#: * ``current``: a 0.5 m/s cross current (towards +y), constant, over ideal links.
SCENARIOS: dict[str, dict[str, Any]] = {
    "paper": _PAPER,
    "acoustic": {
        **_PAPER,
        "name": "acoustic",
        "channel": ChannelConfig(
            burst=GilbertElliott(p_good_to_bad=0.1, p_bad_to_good=0.35, loss_good=0.05, loss_bad=0.75),
            latency=1.0,
            jitter=1.0,
            tdma_slot=4.0,
            range=2000.0,
        ),
    },
    "radio": {
        **_PAPER,
        "name": "radio",
        "channel": ChannelConfig(loss=0.05, latency=0.05, tdma_slot=0.5, range=5000.0),
    },
    "current": {**_PAPER, "name": "current", "current": Current(speed=0.5, direction=math.pi / 2)},
}

#: Initial-state noise used when the formation is generated (n differs from the
#: scenario's): around the slots, ±40 m along, ±20 m across, ±0.3 rad, ±1 m/s.
GENERATED_INIT_NOISE = InitNoise(x=40.0, y=20.0, psi=0.3, u=1.0)


def make_config(scenario: str = "paper", **overrides: Any) -> ScenarioConfig:
    """Build a validated :class:`ScenarioConfig` from a scenario name and overrides.

    Overriding ``n_vessels`` away from the scenario's value without giving
    ``formation`` / ``initial_state`` switches to a generated ``v`` formation
    and random initial states around its slots (:data:`GENERATED_INIT_NOISE`),
    with the default collision check (the ``paper`` scenario turns it off for
    its own initial state only).

    A mapping given for a field that holds a dataclass (``channel``,
    ``current``, ``sensor_noise``, ``gains``, ``reward``, ``init_noise``,
    ``u_d``) updates the scenario's value field by field:
    ``make_config("acoustic", channel={"latency": 3.0})`` keeps the rest of
    the acoustic channel. Giving ``topology_schedule`` without ``topology``
    replaces the scenario's fixed graph by the schedule.

    Raises:
        ConfigError: unknown scenario or key, or any invalid value.
    """
    if not isinstance(scenario, str) or scenario not in SCENARIOS:
        raise ConfigError(f"unknown scenario {scenario!r}; known scenarios: {sorted(SCENARIOS)}")
    base = dict(SCENARIOS[scenario])
    valid = {f.name for f in dataclasses.fields(ScenarioConfig)}
    unknown = sorted(set(overrides) - valid)
    if unknown:
        raise ConfigError(f"unknown override(s) {unknown}; valid keys: {sorted(valid)}")
    n_default = base.get("n_vessels", 3)
    if "n_vessels" in overrides and overrides["n_vessels"] != n_default:
        if "formation" not in overrides:
            base["formation"] = "v"
        if "initial_state" not in overrides:
            base["initial_state"] = None
            base.pop("safety_distance", None)  # the scenario's value belongs to its own initial state
            base.setdefault("init_noise", GENERATED_INIT_NOISE)
            if isinstance(base["init_noise"], InitNoise) and base["init_noise"].is_zero:
                base["init_noise"] = GENERATED_INIT_NOISE
    if overrides.get("topology_schedule") and "topology" not in overrides:
        base["topology"] = None
    defaults = {f.name: f for f in dataclasses.fields(ScenarioConfig)}
    for key, value in overrides.items():
        current = base.get(key)
        factory = defaults[key].default_factory
        if current is None and callable(factory):
            current = factory()
        if isinstance(value, Mapping) and dataclasses.is_dataclass(current) and not isinstance(current, type):
            # unknown keys are reported when ScenarioConfig builds the merged mapping
            base[key] = {**{f.name: getattr(current, f.name) for f in dataclasses.fields(current)}, **value}
        else:
            base[key] = value
    return ScenarioConfig(**base)
