"""The scenario the simulation runs: typed, resolved and checked against the paper's assumptions.

``make_config`` is the usual entry point: a named scenario plus keyword
overrides (``marine_formation_env.settings``, what a user writes), resolved
by ``resolve`` into a ``ScenarioConfig`` whose every field has its
final type (a ``CommGraph``, a
``VesselParams``, floats in SI units, …).
Resolution is a sequence of small named steps; each refuses a value that breaks
the paper's assumptions with a ``ConfigError`` that names it, so an
environment is never built from a configuration that silently breaks them.
Every front end (the PettingZoo env, the gymnasium views, the vector env) is
built from a ``ScenarioConfig``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from marine_formation_env.channel import ChannelConfig
from marine_formation_env.control import lane_speed
from marine_formation_env.disturbances import Current, SensorNoise
from marine_formation_env.errors import (
    ConfigError,
    build_config,
    check_bool,
    check_number,
    check_seed,
    checked_array,
    whole_periods,
)
from marine_formation_env.graph import CommGraph, GraphError, make_graph
from marine_formation_env.params import Gains, ParameterError, VesselParams, get_vessel
from marine_formation_env.paths import Path, make_path, path_coordinates
from marine_formation_env.settings import (
    ACROSS_SPACING,
    ACTION_LEVELS,
    ALONG_SPACING,
    FORMATIONS,
    GENERATED_INIT_NOISE,
    MAX_RK4_STEP,
    PAPER_INITIAL_STATE,
    SCENARIOS,
    InitNoise,
    RewardConfig,
    Settings,
    SpeedProfile,
    make_settings,
)

__all__ = [
    "ACTION_LEVELS",
    "FORMATIONS",
    "GENERATED_INIT_NOISE",
    "PAPER_INITIAL_STATE",
    "SCENARIOS",
    "ConfigError",
    "InitNoise",
    "RewardConfig",
    "ScenarioConfig",
    "Settings",
    "SpeedProfile",
    "config_from_dict",
    "cross_track_errors",
    "formation_offsets",
    "initial_state_problem",
    "make_config",
    "make_settings",
    "min_separation",
    "path_to_inertial",
    "resolve",
    "sample_initial_state",
    "sample_initial_states",
]


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


@dataclass(frozen=True, eq=False)
class ScenarioConfig:
    """Everything that defines an episode, resolved; build it with ``make_config`` or ``resolve``.

    The fields are those of ``Settings``
    (which documents each), with their final types.

    Attributes:
        name: scenario name.
        n_vessels: number of vessels n ≥ 2.
        formation: ``(n, 2)`` read-only desired offsets (D_x, D_y) [m].
        topology: the communication graph (with ``topology_schedule``: the
            union of the scheduled graphs, the links that ever exist).
        topology_seed: seed of the ``random`` graph preset.
        allow_unreachable: a graph without a globally reachable node was allowed.
        vessel: the vessel parameters.
        gains: controller gains and the consensus saturation ``a``.
        u_d: the desired formation speed profile.
        u_min, u_max: the controllability band (U_min, U_max) [m/s].
        action_level: ``force``, ``guidance`` or ``speed``.
        dt: control period [s].
        substeps: RK4 steps per control period.
        horizon: episode length [s].
        paper_as_printed: run (11) and (14) as printed.
        initial_state: ``(n, 6)`` read-only nominal initial state, in the
            path's frame (``start_state`` is the same in the inertial frame).
        init_noise: half-widths of the initial-state noise.
        safety_distance: collision distance [m] (0: no check).
        workspace: ``(x_min, x_max, y_min, y_max)`` [m].
        tau_u_max, tau_r_max: actuator limits [m/s², rad/s²].
        psi_max: ``guidance``-level heading range ±psi_max [rad].
        max_speed: envelope of |u|, |v| [m/s]. max_yaw_rate: envelope of |r| [rad/s].
        reward: reward weights and scales.
        channel: the communication channel. current: the ocean current.
        sensor_noise: the noise on each vessel's measurement of itself.
        topology_schedule: ``((dwell [s], graph), …)``, empty for a fixed graph.
        los_integral_gain: σ [m/s] of the speed level's integral LOS (0: plain LOS).
        path: the reference path (``marine_formation_env.paths``).
        corridor: on a curved path, the largest |e| [m] before a vessel is
            out of bounds (``inf`` on the straight path).
        observation_slots: slots per observation (≥ n − 1; beyond n − 1 empty).
        transmit: the policies decide when each vessel broadcasts (an action
            entry and two observation entries more).
    """

    name: str
    n_vessels: int
    formation: np.ndarray
    topology: CommGraph
    topology_seed: int
    allow_unreachable: bool
    vessel: VesselParams
    gains: Gains
    u_d: SpeedProfile
    u_min: float
    u_max: float
    action_level: str
    dt: float
    substeps: int
    horizon: float
    paper_as_printed: bool
    initial_state: np.ndarray
    init_noise: InitNoise
    safety_distance: float
    workspace: tuple[float, float, float, float]
    tau_u_max: float
    tau_r_max: float
    psi_max: float
    max_speed: float
    max_yaw_rate: float
    reward: RewardConfig
    channel: ChannelConfig
    current: Current
    sensor_noise: SensorNoise
    topology_schedule: tuple[tuple[float, CommGraph], ...]
    los_integral_gain: float
    path: Path
    corridor: float
    observation_slots: int
    transmit: bool

    # --------------------------------------------------------------- derived
    @functools.cached_property
    def start_state(self) -> np.ndarray:
        """``(n, 6)`` read-only nominal initial state in the inertial frame (columns x, y, ψ, u, v, r).

        ``initial_state`` carried from the path's frame: position
        ``P(ℓ) + offset·n(ℓ)``, heading ``γ(ℓ) + relative heading``. On the
        straight path the two frames coincide and this is ``initial_state``.
        """
        return _readonly(path_to_inertial(self.path, self.initial_state))

    @property
    def straight(self) -> bool:
        """The paper's straight path (the simulation runs the paper's code unchanged)."""
        return self.path.is_straight

    @property
    def ideal_observations(self) -> bool:
        """Ideal links, one fixed graph and noise-free measurements: the paper's information."""
        ideal = self.channel.is_ideal and not self.topology_schedule and self.sensor_noise.is_zero
        return ideal and not self.transmit

    @property
    def graph(self) -> CommGraph:
        """The communication graph (the union of the schedule's graphs with ``topology_schedule``)."""
        return self.topology

    @property
    def params(self) -> VesselParams:
        """The vessel parameters."""
        return self.vessel

    @property
    def max_steps(self) -> int:
        """Control periods per episode (truncation)."""
        return max(1, round(self.horizon / self.dt))

    @property
    def control_dim(self) -> int:
        """The level's commands in each vessel's action: 2 (force, guidance) or 1 (speed)."""
        return 1 if self.action_level == "speed" else 2

    @property
    def action_dim(self) -> int:
        """Per-vessel action size: ``control_dim``, plus the ``transmit`` entry when the policies decide."""
        return self.control_dim + int(self.transmit)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-friendly description (resolved values; an infinite number is the string ``"inf"``)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, CommGraph):
                value = {"name": value.name, "links": value.links}
            elif f.name == "topology_schedule":
                value = [{"dwell": dwell, "name": g.name, "links": g.links} for dwell, g in value]
            elif isinstance(value, Path):
                value = value.to_dict()
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


def make_config(scenario: str = "paper", **overrides: Any) -> ScenarioConfig:
    """Build a validated ``ScenarioConfig`` from a scenario name and overrides.

    ``resolve(make_settings(scenario, **overrides))``: see
    ``make_settings`` for how overrides
    combine with a preset (a mapping for a nested setting updates it field by
    field; changing ``n_vessels`` switches to a generated formation).

    Raises:
        ConfigError: unknown scenario or key, or any invalid value.
    """
    return resolve(make_settings(scenario, **overrides))


def resolve(settings: Settings) -> ScenarioConfig:
    """Check ``settings`` and turn every field into its final type (module docstring).

    Raises:
        ConfigError: the first invalid value, named, in the order of the steps below.
    """
    s = settings
    n, topology_seed = _resolve_identity(s)
    offsets = _resolve_formation(s.formation, n)
    schedule, graph = _resolve_graphs(s, n, topology_seed)
    vessel, gains, profile = _resolve_vessel_and_speeds(s)
    path, corridor = _resolve_path(s, offsets, vessel, gains, profile)
    dt, substeps = _resolve_timing(s, schedule)
    noise, nominal = _resolve_initial_state(s, n, offsets, profile)
    reward = _resolve_part(s.reward, RewardConfig, "reward")
    workspace = _resolve_workspace(s, path_to_inertial(path, nominal), noise, offsets, path, corridor)
    channel, current, sensor_noise = _resolve_sea_and_links(s, dt, n)
    config = ScenarioConfig(
        name=s.name,
        n_vessels=n,
        formation=_readonly(offsets),
        topology=graph,
        topology_seed=topology_seed,
        allow_unreachable=s.allow_unreachable,
        vessel=vessel,
        gains=gains,
        u_d=profile,
        u_min=float(s.u_min),
        u_max=float(s.u_max),
        action_level=s.action_level,
        dt=dt,
        substeps=substeps,
        horizon=float(s.horizon),
        paper_as_printed=s.paper_as_printed,
        initial_state=_readonly(nominal),
        init_noise=noise,
        safety_distance=float(s.safety_distance),
        workspace=workspace,
        tau_u_max=float(s.tau_u_max),
        tau_r_max=float(s.tau_r_max),
        psi_max=float(s.psi_max),
        max_speed=float(s.max_speed),
        max_yaw_rate=float(s.max_yaw_rate),
        reward=reward,
        channel=channel,
        current=current,
        sensor_noise=sensor_noise,
        topology_schedule=schedule,
        los_integral_gain=float(s.los_integral_gain),
        path=path,
        corridor=corridor,
        observation_slots=_resolve_slots(s.observation_slots, n),
        transmit=_resolve_transmit(s.transmit),
    )
    problem = initial_state_problem(config, config.start_state, noise.as_array())
    if problem is not None:
        raise ConfigError(f"initial_state: {problem}")
    return config


def _resolve_identity(s: Settings) -> tuple[int, int]:
    """``n_vessels`` and ``topology_seed`` as ints; ``name``, ``action_level`` and the switches checked."""
    n = s.n_vessels
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ConfigError(f"n_vessels must be an integer ≥ 2, got {n!r}")
    if not isinstance(s.name, str):
        raise ConfigError(f"name must be a string, got {s.name!r}")
    if not isinstance(s.action_level, str) or s.action_level not in ACTION_LEVELS:
        raise ConfigError(f"unknown action_level {s.action_level!r}; choose one of {list(ACTION_LEVELS)}")
    for key in ("paper_as_printed", "allow_unreachable"):
        if not isinstance(getattr(s, key), bool):
            raise ConfigError(f"{key} must be True or False, got {getattr(s, key)!r}")
    try:
        seed = check_seed(s.topology_seed, "topology_seed", allow_none=False)
    except (TypeError, ValueError) as err:
        raise ConfigError(str(err)) from None
    assert seed is not None
    return int(n), seed


def _resolve_transmit(transmit: Any) -> bool:
    """``transmit``: True or False."""
    check_bool("settings", "transmit", transmit)
    return bool(transmit)


def _resolve_slots(slots: Any, n: int) -> int:
    """``observation_slots``: None → n − 1; else a whole number ≥ n − 1."""
    if slots is None:
        return n - 1
    if isinstance(slots, bool) or not isinstance(slots, (int, np.integer)) or slots < n - 1:
        raise ConfigError(
            f"observation_slots must be None or a whole number ≥ n_vessels − 1 = {n - 1} (one slot per other "
            f"vessel), got {slots!r}"
        )
    return int(slots)


def _resolve_formation(formation: Any, n: int) -> np.ndarray:
    """The ``(n, 2)`` offsets (D_x, D_y) [m] of a pattern name or an array; distinct."""
    if isinstance(formation, str):
        offsets = formation_offsets(formation, n)
    else:
        offsets = _float_array(formation, "formation", (n, 2))
    if len({(float(a), float(b)) for a, b in offsets}) < n:
        raise ConfigError(f"formation offsets must be distinct, got {offsets.tolist()}")
    return offsets


def _resolve_graphs(s: Settings, n: int, topology_seed: int) -> tuple[tuple[tuple[float, CommGraph], ...], CommGraph]:
    """The schedule of graphs (empty for a fixed graph) and the graph of the links that ever exist."""
    schedule = _resolve_schedule(s.topology_schedule, n, topology_seed)
    if schedule:
        if s.topology is not None:
            raise ConfigError(
                f"give either topology ({s.topology!r}) or topology_schedule, not both: with a schedule the "
                "links come from the scheduled graphs"
            )
        union = np.logical_or.reduce([g.adjacency for _, g in schedule])
        graph = CommGraph(union, name="union of topology_schedule")
    elif s.topology is None:
        raise ConfigError("topology must be a preset name, a CommGraph or an (n, n) adjacency matrix, got None")
    else:
        graph = _resolve_graph(s.topology, "topology", n, topology_seed)
    if not s.allow_unreachable:
        try:
            graph.require_globally_reachable()
        except GraphError as err:
            raise ConfigError(f"{'topology_schedule' if schedule else 'topology'}: {err}") from None
    return schedule, graph


def _resolve_graph(spec: Any, name: str, n: int, topology_seed: int) -> CommGraph:
    try:
        if isinstance(spec, CommGraph):
            graph = spec
        elif isinstance(spec, str):
            graph = make_graph(spec, n, seed=topology_seed)
        else:
            graph = CommGraph.from_adjacency(spec)
    except GraphError as err:
        raise ConfigError(f"{name}: {err}") from None
    if graph.n != n:
        raise ConfigError(f"{name} has {graph.n} vessels but n_vessels = {n}")
    return graph


def _resolve_schedule(raw: Any, n: int, topology_seed: int) -> tuple[tuple[float, CommGraph], ...]:
    if raw is None or (isinstance(raw, (tuple, list)) and len(raw) == 0):
        return ()
    if isinstance(raw, (str, Mapping)) or not isinstance(raw, (tuple, list)):
        raise ConfigError(f"topology_schedule must be a sequence of (dwell_seconds, graph) pairs, got {raw!r}")
    out = []
    for k, entry in enumerate(raw):
        if not isinstance(entry, (tuple, list)) or len(entry) != 2:
            raise ConfigError(f"topology_schedule[{k}] must be a (dwell_seconds, graph) pair, got {entry!r}")
        dwell, spec = entry
        check_number(f"topology_schedule[{k}]", "dwell [s]", dwell, strict=True)
        out.append((float(dwell), _resolve_graph(spec, f"topology_schedule[{k}]", n, topology_seed)))
    return tuple(out)


def _resolve_vessel_and_speeds(s: Settings) -> tuple[VesselParams, Gains, SpeedProfile]:
    """The vessel, the gains and u_d(t), checked against assumption (19) and the sway bound of Proposition 1."""
    try:
        vessel = get_vessel(s.vessel)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    if isinstance(s.gains, Gains):
        gains = s.gains
    elif isinstance(s.gains, Mapping):
        gains = build_config(Gains, s.gains, "gains")
    else:
        raise ConfigError(f"gains must be a Gains or a mapping, got {s.gains!r}")
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
        value = getattr(s, key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{key} must be a finite number, got {value!r}")
    if not s.u_min > 0:
        raise ConfigError(f"U_min must be > 0 (the vessels are uncontrollable at rest), got u_min = {s.u_min}")
    if not s.u_max > s.u_min:
        raise ConfigError(f"u_max = {s.u_max} must exceed u_min = {s.u_min}")
    if isinstance(s.u_d, SpeedProfile):
        profile = s.u_d
    elif isinstance(s.u_d, Mapping):
        profile = build_config(SpeedProfile, s.u_d, "u_d")
    else:
        profile = SpeedProfile(mean=s.u_d)
    lo, hi = profile.bounds
    a = gains.a
    if lo < s.u_min + a - 1e-12 or hi > s.u_max - a + 1e-12:
        raise ConfigError(
            f"u_d(t) ranges over [{lo:g}, {hi:g}] m/s but assumption (19) needs it inside "
            f"[U_min + a, U_max − a] = [{s.u_min + a:g}, {s.u_max - a:g}] m/s "
            f"(u_min = {s.u_min:g}, u_max = {s.u_max:g}, gains.a = {a:g})"
        )
    try:
        vessel.validate_speed_band(s.u_min, s.u_max, gains.delta)
    except ParameterError as err:
        raise ConfigError(str(err)) from None
    return vessel, gains, profile


def _resolve_path(
    s: Settings, offsets: np.ndarray, vessel: VesselParams, gains: Gains, profile: SpeedProfile
) -> tuple[Path, float]:
    """The path and the corridor, checked against the lanes and the generalized assumption (19).

    Lane ``j`` (offset ``D_yj``) on a part of curvature ``κ`` needs
    ``1 − κ·D_yj > 0`` (inside the radius of curvature) and, for the surge
    command ``(1 − κ·D_yj)·w`` with ``w ∈ (u_d − a, u_d + a)``,
    ``(1 − κ·D_yj)·(u_d ± a)`` inside ``[U_min, U_max]`` for every ``u_d(t)``,
    the lower end computed with the sway of the turn as the lane's surge
    command is (``lane_speed``; docs/paths.md,
    "The generalized assumption (19)").
    """
    try:
        path = make_path(s.path)
    except TypeError as err:
        raise ConfigError(f"path: {err}") from None
    if not path.is_straight and s.paper_as_printed:
        raise ConfigError(
            "paper_as_printed runs the printed (11) and (14), which are written for the paper's straight path; "
            f"it cannot be combined with a curved path ({path.kind!r})"
        )
    if path.is_straight:
        if s.corridor is not None:
            raise ConfigError(
                f"corridor = {s.corridor!r} applies to curved paths; on the straight path the workspace's "
                "y-extent bounds |e| (set workspace instead)"
            )
        return path, math.inf
    lo, hi = profile.bounds
    a = gains.a
    for kappa in path.curvatures:
        if kappa == 0.0:
            continue
        radius = 1.0 / abs(float(kappa))
        side = "left" if kappa > 0 else "right"
        for j, d_y in enumerate(offsets[:, 1]):
            factor = 1.0 - float(kappa) * float(d_y)
            where = f"the lane of vessel_{j} (D_y = {d_y:g} m) on the {side} turn of radius {radius:g} m"
            if factor <= 0.0:
                raise ConfigError(
                    f"{where} lies beyond the turn's centre of curvature: every |D_y| must be < {radius:g} m"
                )
            # the lane's surge command (the sway takes part of the lane speed) at the slowest and fastest w
            slow = float(lane_speed(vessel, np.float64(lo - a), 0.0, np.float64(kappa), float(d_y))[0])
            fast = factor * (hi + a)
            if slow < s.u_min - 1e-9 or fast > s.u_max + 1e-9:
                raise ConfigError(
                    f"{where} needs surge speeds (1 − κ·D_y)·(u_d ± a) from {slow:.4g} to {fast:.4g} m/s, outside the "
                    f"band [U_min, U_max] = [{s.u_min:g}, {s.u_max:g}] m/s: the generalized assumption (19) fails "
                    f"(use a larger radius, a narrower formation or a wider band)"
                )
    room = path.min_radius - float(np.max(np.abs(offsets[:, 1])))
    if s.corridor is None:
        corridor = min(250.0, 0.5 * room)
    else:
        check_number("scenario", "corridor", s.corridor, strict=True)
        corridor = float(s.corridor)
        if corridor >= room:
            raise ConfigError(
                f"corridor = {corridor:g} m reaches past the tightest centre of curvature: the outermost lane is "
                f"{room:g} m from it (radius {path.min_radius:g} m); choose corridor < {room:g} m"
            )
    return path, corridor


def path_to_inertial(path: Path, state: np.ndarray) -> np.ndarray:
    """``(..., 6)`` states from the path's frame (ℓ, normal offset, relative heading, u, v, r) to the inertial one.

    The identity on the straight path (the same array values, exactly).
    """
    state = np.asarray(state, dtype=float)
    if path.is_straight:
        return np.array(state)
    out = np.array(state)
    out[..., 0], out[..., 1], gamma = path.lane_point(state[..., 0], state[..., 1])
    out[..., 2] = state[..., 2] + np.mod(gamma + np.pi, 2.0 * np.pi) - np.pi
    return out


def _resolve_timing(s: Settings, schedule: tuple[tuple[float, CommGraph], ...]) -> tuple[float, int]:
    """``dt`` (the level's default when None) and ``substeps``; the horizon and the limits checked."""
    dt = ACTION_LEVELS[s.action_level] if s.dt is None else s.dt
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (math.isfinite(dt) and dt > 0):
        raise ConfigError(f"dt (control period) must be a finite number > 0 s, got {dt!r}")
    dt = float(dt)
    if not s.horizon >= dt:
        raise ConfigError(f"horizon = {s.horizon} s must be at least one control period dt = {dt} s")
    substeps = max(1, math.ceil(dt / MAX_RK4_STEP - 1e-9)) if s.substeps is None else s.substeps
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ConfigError(f"substeps must be an integer ≥ 1, got {substeps!r}")
    for k, (dwell, _) in enumerate(schedule):
        whole_periods(dwell, dt, f"topology_schedule[{k}] dwell")
    for key in ("tau_u_max", "tau_r_max", "psi_max", "max_yaw_rate"):
        if not getattr(s, key) > 0:
            raise ConfigError(f"{key} must be > 0, got {getattr(s, key)!r}")
    if not s.max_speed > s.u_max:
        raise ConfigError(f"max_speed = {s.max_speed} m/s must exceed u_max = {s.u_max} m/s")
    if s.safety_distance < 0:
        raise ConfigError(f"safety_distance must be ≥ 0 m, got {s.safety_distance!r}")
    return dt, int(substeps)


def _resolve_initial_state(
    s: Settings, n: int, offsets: np.ndarray, profile: SpeedProfile
) -> tuple[InitNoise, np.ndarray]:
    """The initial-state noise and the nominal ``(n, 6)`` state (the formation slots at u_d(0) when None)."""
    noise = s.init_noise
    if not isinstance(noise, InitNoise):
        if isinstance(noise, Mapping):
            noise = build_config(InitNoise, noise, "init_noise")
        else:
            values = _float_array(noise, "init_noise", (4,))
            noise = InitNoise(*map(float, values))
    if s.initial_state is None:
        nominal = np.zeros((n, 6))
        nominal[:, :2] = offsets
        nominal[:, 3] = float(profile.value(0.0))
    else:
        nominal = _float_array(s.initial_state, "initial_state", (n, 6))
    return noise, nominal


def _resolve_part(value: Any, cls: type, name: str) -> Any:
    """A nested setting: an instance of ``cls`` as it is, or a mapping of its fields."""
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        return build_config(cls, dict(value), name)
    article = "an" if cls.__name__[0] in "AEIOU" else "a"
    raise ConfigError(f"{name} must be {article} {cls.__name__} or a mapping of its fields, got {value!r}")


def _resolve_workspace(
    s: Settings, nominal: np.ndarray, noise: InitNoise, offsets: np.ndarray, path: Path, corridor: float
) -> tuple[float, float, float, float]:
    """The workspace box; by default one that holds the whole nominal run with margins of 500 m and 250 m.

    On a curved path: the box around the path from behind the start to as
    far as a vessel could go in the horizon, widened by the lanes, the
    corridor and 250 m.
    """
    # how far a vessel can go along the path in the horizon: ℓ̇ can exceed u on an inner lane of a curved
    # path, so twice u_max·horizon is a generous bound there (and the straight box needs less)
    reach = 2.0 * s.u_max * s.horizon
    if s.workspace is None and not np.isfinite(reach + 1e3):
        raise ConfigError(
            f"horizon = {s.horizon} s at u_max = {s.u_max} m/s is too long for the default workspace, which must "
            "hold the whole run: give a shorter horizon or an explicit workspace"
        )
    if s.workspace is None and not path.is_straight:
        spread = noise.as_array()
        ell = path.closest(nominal[:, 0], nominal[:, 1])
        points = path.points(float(np.min(ell)) - spread[0] - 500.0, float(np.max(ell)) + spread[0] + reach)
        margin = float(np.max(np.abs(offsets[:, 1]))) + corridor + float(spread[1]) + 250.0
        return (
            float(points[:, 0].min()) - margin,
            float(points[:, 0].max()) + margin,
            float(points[:, 1].min()) - margin,
            float(points[:, 1].max()) + margin,
        )
    if s.workspace is None:
        spread = noise.as_array()
        x_lo = float(np.min(nominal[:, 0]) - spread[0]) - 500.0
        x_hi = float(np.max(nominal[:, 0]) + spread[0]) + s.u_max * s.horizon + 500.0
        y_ext = float(max(np.max(np.abs(nominal[:, 1])) + spread[1], np.max(np.abs(offsets[:, 1])))) + 250.0
        return (x_lo, x_hi, -y_ext, y_ext)
    x0, x1, y0, y1 = (float(v) for v in _float_array(s.workspace, "workspace", (4,)))
    if not (x0 < x1 and y0 < y1):
        raise ConfigError(f"workspace (x_min, x_max, y_min, y_max) must have min < max, got {(x0, x1, y0, y1)}")
    return (x0, x1, y0, y1)


def _resolve_sea_and_links(s: Settings, dt: float, n: int) -> tuple[ChannelConfig, Current, SensorNoise]:
    """The channel, the current and the sensor noise (our extensions), checked against dt and the speed band."""
    channel = _resolve_part(s.channel, ChannelConfig, "channel")
    current = _resolve_part(s.current, Current, "current")
    sensor_noise = _resolve_part(s.sensor_noise, SensorNoise, "sensor_noise")
    channel.validate(dt, n)
    check_number("scenario", "los_integral_gain", s.los_integral_gain)
    if s.los_integral_gain > 0 and s.action_level != "speed":
        raise ConfigError(
            f"los_integral_gain = {s.los_integral_gain} applies to the speed level's built-in LOS; at "
            f"action_level {s.action_level!r} the policy steers (ReferencePolicy(env, integral_los=σ) does ILOS)"
        )
    strongest = current.speed + current.amplitude
    if strongest >= s.u_min:
        raise ConfigError(
            f"current speed + amplitude = {strongest:g} m/s must stay below u_min = {s.u_min:g} m/s: a vessel "
            "at the slowest allowed speed could not hold its path against it"
        )
    return channel, current, sensor_noise


def initial_state_problem(config: ScenarioConfig, state: np.ndarray, noise: np.ndarray | None = None) -> str | None:
    """Why an ``(n, 6)`` initial state would end the episode at its first step, or None.

    A vessel outside the workspace or outside the envelope (|u|, |v| >
    max_speed, |r| > max_yaw_rate), or two vessels closer than the safety
    distance, terminate the formation before any policy acts: such a start is
    an error in the scenario, not an episode. ``noise`` (half-widths of the
    columns, as ``InitNoise.as_array``) widens each value to the range the
    reset can draw; the separation check uses the nominal positions (draws
    that bring two vessels too close are rejected at reset).
    """
    state = np.asarray(state, dtype=float)
    spread = np.zeros(6) if noise is None else np.asarray(noise, dtype=float)
    across = float(spread[1])  # on a curved path the noise's x and y are along and across the path
    if not config.straight:
        spread = spread.copy()
        spread[0] = spread[1] = math.hypot(spread[0], spread[1])  # how far a drawn start can move in x or y
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
    if not config.straight:
        e = cross_track_errors(config, state)
        reach = np.abs(e) + across  # the noise's y is across the path (sample_initial_state)
        bad = np.flatnonzero(reach > config.corridor)
        if bad.size:
            j = int(bad[0])
            return (
                f"vessel_{j} starts {e[j]:+.4g} m off its lane (± init_noise {across:g} m), "
                f"outside the corridor |e| ≤ {config.corridor:g} m; the episode would end at its first step"
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


def cross_track_errors(config: ScenarioConfig, state: np.ndarray) -> np.ndarray:
    """``(..., N)`` cross-track errors ``e_j`` [m] of inertial states ``(..., N, 6)``, by a global search on the path.

    For a start (or any state without history); the simulation follows the
    projection continuously instead (``project``).
    """
    x, y, psi, u, v = (state[..., k] for k in range(5))
    found = path_coordinates(config.path, x, y, psi, u, v, config.path.closest(x, y))
    return found.offset - config.formation[:, 1]  # type: ignore[no-any-return]


def sample_initial_state(config: ScenarioConfig, rng: np.random.Generator) -> np.ndarray:
    """The nominal initial state plus uniform ``init_noise``, shape ``(N, 6)``, drawn from ``rng``.

    The noise is added in the path's frame (x along the path, y across it, ψ
    relative to it), then the state is carried to the inertial frame; on the
    straight path the two frames are one.

    Draws are rejected (up to 100 times) while two vessels start closer than
    twice the safety distance.

    Raises:
        RuntimeError: no acceptable draw in 100 tries (names the noise and the distance).
    """
    if config.init_noise.is_zero:
        return np.array(config.start_state)
    half_widths = config.init_noise.as_array()
    for _ in range(100):
        # in the path's frame (along, across the path; the inertial frame on the straight path)
        noisy = config.initial_state + rng.uniform(-1.0, 1.0, size=config.initial_state.shape) * half_widths
        candidate = path_to_inertial(config.path, noisy)
        if min_separation(candidate[None])[0] > 2.0 * config.safety_distance:
            return candidate
    raise RuntimeError(
        f"could not draw an initial state with vessels more than {2 * config.safety_distance} m apart "
        f"in 100 tries; reduce init_noise ({config.init_noise}) or safety_distance"
    )


def spread_config(config: ScenarioConfig, scale: float) -> ScenarioConfig:
    """``config`` with its initial states ``scale`` of the way from the formation on its lanes to its own.

    The formation on its lanes is the nominal initial state with every error
    at zero, in the path's frame: each vessel on its lane (``y = D_y``),
    aligned with the path (``ψ = 0`` relative to it) and coordinated
    (``x = D_x + mean θ``, ``θ_j = x_j − D_xj`` of the nominal state), at its
    nominal ``u, v, r``. The new nominal state is that plus ``scale`` × the
    scenario's errors, and the ``init_noise`` half-widths are ``scale`` × the
    scenario's: 0 starts every formation in formation, 1 is ``config``. A
    curriculum over the initial state (the learner's env only) grows it.

    Raises:
        ConfigError: ``scale`` is not a number in [0, 1].
    """
    if (
        isinstance(scale, bool)
        or not isinstance(scale, (int, float, np.integer, np.floating))
        or not (0.0 <= float(scale) <= 1.0)
    ):
        raise ConfigError(f"the initial-state spread must be a number in [0, 1], got {scale!r}")
    s = float(scale)
    if s == 1.0:
        return config
    nominal = config.initial_state
    in_formation = np.array(nominal)
    in_formation[:, 0] = config.formation[:, 0] + float(np.mean(nominal[:, 0] - config.formation[:, 0]))
    in_formation[:, 1] = config.formation[:, 1]
    in_formation[:, 2] = 0.0
    noise = config.init_noise
    return dataclasses.replace(
        config,
        initial_state=_readonly(in_formation + s * (nominal - in_formation)),
        init_noise=InitNoise(x=s * noise.x, y=s * noise.y, psi=s * noise.psi, u=s * noise.u),
    )


def sample_initial_states(config: ScenarioConfig, rngs: Sequence[np.random.Generator]) -> np.ndarray:
    """One initial state per generator, ``(len(rngs), N, 6)`` (see ``sample_initial_state``)."""
    if config.init_noise.is_zero:
        return np.broadcast_to(config.start_state, (len(rngs), config.n_vessels, 6)).copy()
    return np.stack([sample_initial_state(config, rng) for rng in rngs])


def min_separation(state: np.ndarray) -> np.ndarray:
    """``(B,)`` the smallest distance [m] between two vessels of each formation of ``state`` ``(B, N, 6)``."""
    i, j = _pairs(state.shape[1])
    return np.hypot(state[:, i, 0] - state[:, j, 0], state[:, i, 1] - state[:, j, 1]).min(axis=1)  # type: ignore[no-any-return]


@functools.lru_cache(maxsize=64)
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The index pairs ``i < j`` of ``n`` vessels (computed once per n: the numpy step needs them every step)."""
    return np.triu_indices(n, k=1)  # type: ignore[return-value]


def config_from_dict(data: Mapping[str, Any]) -> ScenarioConfig:
    """Rebuild a ``ScenarioConfig`` from ``ScenarioConfig.to_dict`` (e.g. a JSON report's ``config``).

    ``config_from_dict(cfg.to_dict()).to_dict() == cfg.to_dict()`` for every
    valid configuration (tests/test_input_errors.py checks it on random input).

    Raises:
        ConfigError: ``data`` is not such a description, or the values are invalid.
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"a scenario description must be a mapping, got {data!r}")
    values = _from_json(dict(data))
    unknown = sorted(set(values) - {f.name for f in dataclasses.fields(Settings)})
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
        if "corridor" in values and values["corridor"] == math.inf:
            values["corridor"] = None  # the straight path's (none)
        vessel = values.get("vessel")
        if isinstance(vessel, Mapping):
            values["vessel"] = VesselParams(**vessel)
    except (KeyError, TypeError, GraphError, ParameterError) as err:
        raise ConfigError(f"not a scenario description written by ScenarioConfig.to_dict: {err!r}") from None
    return resolve(Settings(**values))


def _from_json(value: Any) -> Any:
    """Inverse of ``_finite_json``: ``"inf"``/``"-inf"`` back to floats (names stay strings)."""
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
    """``checked_array`` with every refusal a ``ConfigError``."""
    try:
        return checked_array(value, name, [shape], ConfigError)
    except TypeError as err:
        raise ConfigError(str(err)) from None
