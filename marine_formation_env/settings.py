"""What a user writes: the settings of a scenario, the named presets, and overrides.

``Settings`` is a plain record of every knob, in the units and forms a
user writes them (a preset name or an adjacency matrix for the graph, a number
or a ``SpeedProfile`` for the speed, mappings for the nested settings).
It checks nothing by itself: ``marine_formation_env.scenarios.resolve``
turns it into the typed ``ScenarioConfig``
the simulation runs, validating it against the paper's assumptions on the way.

A *scenario* is a named set of settings (``SCENARIOS``);
``make_settings`` applies keyword overrides on top of one. Override keys
are the field names of ``Settings``; an unknown key raises an error that
lists the valid ones.
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
from marine_formation_env.errors import ConfigError, UnknownSettingError, check_bool, check_number
from marine_formation_env.params import Gains
from marine_formation_env.paths import CirclePath, LawnmowerPath, Path, StraightPath

__all__ = [
    "ACTION_LEVELS",
    "FORMATIONS",
    "GENERATED_INIT_NOISE",
    "PAPER_INITIAL_STATE",
    "SCENARIOS",
    "TRACKING_TERMS",
    "InitNoise",
    "RewardConfig",
    "Settings",
    "SpeedProfile",
    "make_settings",
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

#: Formation patterns (D_x, D_y) [m] for ``formation_offsets``.
FORMATIONS = ("paper", "v", "line_abreast", "column")

ALONG_SPACING = 100.0  # [m] between rows of the generated formations
ACROSS_SPACING = 50.0  # [m] between paths of the generated formations


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


#: The tracking terms of the reward, in the order the backends compute them.
TRACKING_TERMS = ("cross_track", "heading", "coordination", "speed")


@dataclass(frozen=True)
class RewardConfig:
    """Weights and scales of the per-agent reward (see the env docstring).

    Each error ``e`` with scale ``σ`` gives the bounded cost
    ``c(e) = (e/σ)² / (1 + (e/σ)²) ∈ [0, 1)``; the step reward of vessel j is
    ``−dt·Σ_k w_k·c_k``. A formation that terminates early (collision or leaving
    the workspace) receives ``−(Σ_k w_k)·(time left)``, the worst reward the rest
    of the episode could have given, so ending an episode never pays.

    ``fine_share`` f ∈ [0, 1] charges that share of each tracking term named
    in ``fine_terms`` (by default all four: cross-track, heading, coordination,
    speed) at the finer scale ``fine_scale·σ_k`` instead:
    ``c_k = (1 − f)·c(e; σ_k) + f·c(e; fine_scale·σ_k)``, still in [0, 1), so
    the terminal penalty is unchanged; the terms not named keep ``c(e; σ_k)``.
    It is off (0) in the benchmark's reward; a learner may train with it
    (``train_reward``) to see a slope near the goal that the broad scales leave
    almost flat. The default ``fine_scale`` 0.05 puts the fine scales at 1 m,
    0.01 rad, 1 m and 0.05 m/s.

    ``message_cost`` charges each vessel that much reward per broadcast it
    sends (the ``communication`` term); 0 by default, so the benchmark's
    reward does not price messages.
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
    fine_share: float = 0.0
    fine_scale: float = 0.05
    fine_terms: tuple[str, ...] = TRACKING_TERMS
    terminal_penalty: bool = True
    message_cost: float = 0.0

    def __post_init__(self) -> None:
        check_bool("reward", "terminal_penalty", self.terminal_penalty)
        terms = self.fine_terms
        if isinstance(terms, str) or not isinstance(terms, (list, tuple)):
            raise ConfigError(f"reward.fine_terms must be a list of term names {list(TRACKING_TERMS)}, got {terms!r}")
        for term in terms:
            if term not in TRACKING_TERMS:
                raise ConfigError(
                    f"reward.fine_terms: unknown term {term!r}; the tracking terms are {list(TRACKING_TERMS)}"
                )
        if len(set(terms)) != len(terms):
            raise ConfigError(f"reward.fine_terms names a term twice: {list(terms)!r}")
        object.__setattr__(self, "fine_terms", tuple(terms))  # a YAML or JSON list, kept hashable
        for f in dataclasses.fields(self):
            if f.name in ("terminal_penalty", "fine_terms"):
                continue
            strict = f.name == "fine_scale" or f.name.startswith("sigma_")
            check_number("reward", f.name, getattr(self, f.name), strict=strict)
        if self.fine_share > 1.0:
            raise ConfigError(f"reward.fine_share must be a share in [0, 1], got {self.fine_share!r}")

    @property
    def tracking_weights(self) -> tuple[float, ...]:
        """The tracking terms' weights w_k, in ``TRACKING_TERMS`` order."""
        return tuple(getattr(self, term) for term in TRACKING_TERMS)

    @property
    def tracking_sigmas(self) -> tuple[float, ...]:
        """The tracking terms' scales σ_k, in ``TRACKING_TERMS`` order."""
        return tuple(getattr(self, f"sigma_{term}") for term in TRACKING_TERMS)

    @property
    def fine_shares(self) -> tuple[float, ...]:
        """Each tracking term's fine share, in ``TRACKING_TERMS`` order (0 for a term not in ``fine_terms``)."""
        f = self.fine_share
        return tuple(f if term in self.fine_terms else 0.0 for term in TRACKING_TERMS)

    @property
    def total_weight(self) -> float:
        """Σ_k w_k: the largest cost rate [1/s]."""
        return sum(self.tracking_weights) + self.effort

    @property
    def terminal_rate(self) -> float:
        """The rate [1/s] an early end charges per second left: Σ_k w_k with ``terminal_penalty``, else 0."""
        return self.total_weight if self.terminal_penalty else 0.0


@dataclass(frozen=True, eq=False)
class Settings:
    """Every setting of a scenario, as a user writes it (nothing is checked here).

    Build it with ``make_settings`` (a preset plus overrides);
    ``resolve`` checks it and returns the
    ``ScenarioConfig`` the simulation runs.

    Attributes:
        name: scenario name.
        n_vessels: number of vessels n ≥ 2.
        formation: ``(n, 2)`` desired offsets (D_x, D_y) [m], or a pattern name
            (``FORMATIONS``).
        topology: communication graph: a preset name (``make_graph``), a
            ``CommGraph``, or an ``(n, n)`` adjacency matrix
            (``A[j, i] = 1`` iff i transmits to j).
        topology_schedule: switching topologies: a sequence of ``(dwell [s],
            graph)`` pairs (graphs as for ``topology``) that repeats
            periodically; excludes ``topology``, which then becomes the union
            of the scheduled graphs (the links that ever exist). Needs
            reachability of the union only (joint connectivity).
        topology_seed: seed of the ``random`` topology preset.
        allow_unreachable: accept a graph without a globally reachable node
            (consensus then is not guaranteed).
        vessel: vessel parameter set (name or ``VesselParams``).
        gains: controller gains and consensus saturation ``a``.
        u_d: desired formation speed [m/s] (number or ``SpeedProfile``).
        u_min, u_max: the controllability band (U_min, U_max) [m/s].
        action_level: ``force``, ``guidance`` or ``speed`` (docs/model.md §6).
        dt: control period [s]; default depends on the level (``ACTION_LEVELS``).
        substeps: RK4 steps per control period; default ``ceil(dt / 0.1)``.
        horizon: episode length [s]; truncation after ``round(horizon/dt)`` steps.
        paper_as_printed: run (11) and (14) exactly as printed (docs/model.md §3).
        initial_state: nominal ``(n, 6)`` initial state, or None for the
            formation slots at speed u_d(0) heading along the path. Its
            columns are in the path's frame: arc length ℓ, offset along the
            path's normal, heading relative to the path's tangent, u, v, r
            (on the straight path, the inertial x, y, ψ, u, v, r).
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
        channel: the communication channel (``ChannelConfig``, or a
            mapping of its fields): loss, latency, update rate, TDMA, range,
            random link failures. The default is the paper's ideal links.
        current: an ocean current (``Current`` or a mapping); its speed
            plus amplitude must stay below u_min, or a vessel at the slowest
            allowed speed could not hold its path.
        sensor_noise: noise on each vessel's measurement of itself
            (``SensorNoise`` or a mapping).
        path: the reference path (``marine_formation_env.paths``): a
            ``Path``, a kind name, or a
            mapping with ``kind`` (``{"kind": "circle", "radius": 400.0}``);
            a mapping without ``kind`` updates the scenario's path field by
            field. Default: the paper's straight line.
        corridor: on a curved path, the largest cross-track error |e| [m]
            before a vessel is out of bounds (terminates); None: half the
            distance from the outermost lane to the tightest centre of
            curvature, at most 250 m. The straight path has no corridor (the
            workspace's y-extent bounds |e|).
        los_integral_gain: σ [m/s] of integral LOS in the ``speed`` level's
            built-in path follower (our extension, Børhaug, Pavlov and
            Pettersen, CDC 2008): it steers on ``e + σ·e_int`` with
            ``ė_int = Δ·e/((e + σ·e_int)² + Δ²)``, integrated once per control
            period, which removes the steady cross-track error a current
            leaves. 0: the paper's LOS (12). Choose σ above the largest cross
            current. Only at ``speed``; at the other levels the policy steers.
        observation_slots: number of slots in each observation; None (the
            default): one per other vessel, n − 1. A larger number pads the
            observation with empty slots (every entry 0, so ``linked`` = 0,
            as for a vessel it does not hear), which gives teams of different
            sizes one observation length: a policy over slots (attention, a
            graph network) trains on several team sizes at once.
        transmit: each vessel's policy decides when it broadcasts: its action
            gets a last entry, ``transmit`` (> 0: broadcast now), and its
            observation three last entries, the share of its budget left, the
            time since its last broadcast [s] and how far its neighbours'
            prediction of it has drifted since [m] (``marine_formation_env.channel``).
            False: the channel's rule decides (periodic or event-triggered).
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
    path: Any = field(default_factory=StraightPath)
    corridor: Any = None
    observation_slots: Any = None
    transmit: bool = False


#: The lawnmower route of the ``survey`` presets (docs/paths.md).
SURVEY_ROUTE = LawnmowerPath(legs=4, leg_length=2000.0, spacing=600.0, turn_radius=300.0, first_turn="left")

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

#: Named scenarios: defaults that ``make_config`` starts from. Besides the
#: paper's own, three presets put its scenario into the sea the paper is
#: motivated by (numbers and reasons in docs/channel.md, "Presets"):
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
#: * ``circle``, ``survey``, ``survey_acoustic``: the paper's formation on a circle of
#:   300 m, on a lawnmower survey (4 legs of 2 km), and on that survey over ``acoustic``
#:   links (docs/paths.md).
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
    # Curved paths (docs/paths.md). The paper's formation, gains and initial state (carried onto the
    # path: the state's columns are in the path's frame). With D_y = ±50 m, u_d = 5 m/s, a = 1 m/s and
    # U_max = 7 m/s, the generalized (19) needs every radius ≥ 300 m: the circle is the tightest admissible.
    "circle": {**_PAPER, "name": "circle", "path": CirclePath(radius=300.0, turn="left")},
    # A lawnmower survey: 4 legs of 2 km, joined by half circles of the smallest admissible radius
    # (spacing = 2·turn_radius): 9.0 km of route from the first waypoint to the last, which the formation
    # passes after about 1820 s at 5 m/s; the episode ends 180 s later, on the last leg run on.
    "survey": {**_PAPER, "name": "survey", "path": SURVEY_ROUTE, "horizon": 2000.0},
}
#: Bandwidth budgets that periodic broadcasting exceeds several times over (docs/channel.md, "Budgets"):
#:
#: * ``paper_budget``: the paper's links with a token bucket of 48 bit/s, one 96-bit message every 2 s, and a
#:   burst of 4 messages; periodic broadcasting at dt = 0.5 s would need 192 bit/s, 4 times as much.
#: * ``acoustic_budget``: the ``acoustic`` links with 96 bit per 36 s, one message every 36 s, and a burst of
#:   2 messages; TDMA's slot every 12 s would need 3 times as much.
SCENARIOS["paper_budget"] = {
    **_PAPER,
    "name": "paper_budget",
    "channel": ChannelConfig(budget_rate=48.0, budget_burst=384.0),
}
SCENARIOS["acoustic_budget"] = {
    **SCENARIOS["acoustic"],
    "name": "acoustic_budget",
    "channel": dataclasses.replace(SCENARIOS["acoustic"]["channel"], budget_rate=96.0 / 36.0, budget_burst=192.0),
}
SCENARIOS["survey_acoustic"] = {
    **SCENARIOS["survey"],
    "name": "survey_acoustic",
    "channel": SCENARIOS["acoustic"]["channel"],
}

#: Initial-state noise used when the formation is generated (n differs from the
#: scenario's): around the slots, ±40 m along, ±20 m across, ±0.3 rad, ±1 m/s.
GENERATED_INIT_NOISE = InitNoise(x=40.0, y=20.0, psi=0.3, u=1.0)


def make_settings(scenario: str = "paper", **overrides: Any) -> Settings:
    """The settings of a named scenario with keyword overrides applied (nothing resolved yet).

    Overriding ``n_vessels`` away from the scenario's value without giving
    ``formation`` / ``initial_state`` switches to a generated ``v`` formation
    and random initial states around its slots (``GENERATED_INIT_NOISE``),
    with the default collision check (the ``paper`` scenario turns it off for
    its own initial state only).

    A mapping given for a field that holds a dataclass (``channel``,
    ``current``, ``sensor_noise``, ``gains``, ``reward``, ``init_noise``,
    ``u_d``) updates the scenario's value field by field:
    ``make_settings("acoustic", channel={"latency": 3.0})`` keeps the rest of
    the acoustic channel. Giving ``topology_schedule`` without ``topology``
    replaces the scenario's fixed graph by the schedule.

    Raises:
        ConfigError: unknown scenario; ``UnknownSettingError``
            (a ``ConfigError`` and a ``TypeError``) for an unknown key.
    """
    if not isinstance(scenario, str) or scenario not in SCENARIOS:
        raise ConfigError(f"unknown scenario {scenario!r}; known scenarios: {sorted(SCENARIOS)}")
    base = dict(SCENARIOS[scenario])
    valid = {f.name for f in dataclasses.fields(Settings)}
    unknown = sorted(set(overrides) - valid)
    if unknown:
        others = f" (and {unknown[1:]})" if len(unknown) > 1 else ""
        raise UnknownSettingError(
            f"scenario {scenario!r} got an unexpected keyword argument {unknown[0]!r}{others}; "
            f"valid keys: {sorted(valid)}"
        )
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
    defaults = {f.name: f for f in dataclasses.fields(Settings)}
    for key, value in overrides.items():
        current = base.get(key)
        factory = defaults[key].default_factory
        if current is None and callable(factory):
            current = factory()
        if isinstance(current, Path) and isinstance(value, Mapping):
            # a mapping updates the scenario's path field by field, unless it names another kind
            same_kind = value.get("kind", current.kind) == current.kind
            base[key] = {**current.to_dict(), **value} if same_kind else dict(value)
        elif isinstance(value, Mapping) and dataclasses.is_dataclass(current) and not isinstance(current, type):
            # unknown keys are reported when ScenarioConfig builds the merged mapping
            base[key] = {**{f.name: getattr(current, f.name) for f in dataclasses.fields(current)}, **value}
        else:
            base[key] = value
    return Settings(**base)
