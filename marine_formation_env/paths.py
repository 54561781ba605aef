"""Reference paths: the paper's straight line, circles, waypoint routes and lawnmower surveys.

The paper's vessels follow parallel straight lines. Survey formations run
routes: long legs joined by turns. A ``Path`` is a curve ``P(ℓ)``
parametrized by its arc length ``ℓ`` [m], with tangent angle ``γ(ℓ)`` [rad]
and curvature ``κ(ℓ) = dγ/dℓ`` [1/m] (positive when the path turns left,
towards +y of a path heading along +x). Vessel ``j`` follows the *lane*
``P(ℓ) + D_yj·n(ℓ)`` with the unit normal ``n = (−sin γ, cos γ)``; for the
straight path (the default) the lane of ``D_y`` is the paper's line
``y = D_y``. docs/paths.md gives the path coordinates, the kinematics and the
controllers built on them.

Every path here is a chain of *segments* of constant curvature (straight
lines, ``κ = 0``, and circular arcs, ``κ = ±1/R``), so ``γ`` is continuous and
``κ`` is piecewise constant. Before its start a path continues along its first
segment, after its end along its last one (a route's last leg goes on as a
straight line; a circle goes on turning), so ``P(ℓ)`` is defined for every
``ℓ``: vessels that start behind the route's first waypoint, as the paper's
formation does, have well-defined path coordinates.

All evaluations are batched: ``Path.frame``, ``Path.project`` and
``Path.closest`` take arrays of any shape.

Kinds (``path=`` takes an instance or a mapping with ``kind``, the way
``channel=`` takes one; ``--set path.radius=500`` on the command line):

=============  ====================================================================
``straight``   ``StraightPath``: the paper's path, ``P(ℓ) = (ℓ, 0)``
``circle``     ``CirclePath``: a circle of ``radius`` [m] turning ``left`` or
               ``right``, starting at the origin heading along +x
``waypoints``  ``WaypointPath``: straight legs between ``waypoints`` joined by
               circular arcs of ``turn_radius`` [m]
``lawnmower``  ``LawnmowerPath``: ``legs`` parallel legs of ``leg_length`` [m],
               ``spacing`` [m] apart, joined by turns of ``turn_radius`` [m]
=============  ====================================================================
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

from marine_formation_env.errors import ConfigError, check_number

__all__ = [
    "PATH_KINDS",
    "CirclePath",
    "LawnmowerPath",
    "Path",
    "PathCoordinates",
    "Segments",
    "StraightPath",
    "WaypointPath",
    "make_path",
    "path_coordinates",
    "segment_frame",
    "segment_project",
]

#: Newton iterations of ``Path.project`` (each is exact on a line; on an arc
#: of radius R the error after one is O(step³/R²): three are at rounding level
#: for the distances a vessel moves in a control period).
PROJECTION_ITERATIONS = 3
#: Smallest value of ``1 − κ·d`` used in a Newton step, so that a point near a
#: centre of curvature cannot send the iteration to infinity.
MIN_METRIC = 0.05


@dataclass(frozen=True)
class Segments:
    """A path as a chain of constant-curvature segments (arrays of length K).

    Attributes:
        start: arc length [m] at which each segment starts (increasing; the
            first segment also serves ℓ < start[0], the last every ℓ past it).
        x0, y0: the segment's first point [m]. gamma0: its tangent angle there [rad].
        kappa: its curvature [1/m] (0: a line).
        length: each segment's length [m] (the last one's is the route's
            remainder up to its end, ``inf`` for paths without an end).
    """

    start: np.ndarray
    x0: np.ndarray
    y0: np.ndarray
    gamma0: np.ndarray
    kappa: np.ndarray
    length: np.ndarray


class Path:
    """A reference path ``P(ℓ)`` (module docstring). Subclasses define ``_build``."""

    kind: ClassVar[str] = ""

    def _build(self) -> Segments:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    @functools.cached_property
    def segments(self) -> Segments:
        """The chain of constant-curvature segments (built once)."""
        return self._build()

    @property
    def is_straight(self) -> bool:
        """The paper's straight path ``P(ℓ) = (ℓ, 0)``: the simulation then runs the paper's code unchanged."""
        return False

    @property
    def length(self) -> float:
        """The route's length [m] from its start to its end (``inf``: the path has no end)."""
        seg = self.segments
        return float(seg.start[-1] + seg.length[-1])

    @property
    def curvatures(self) -> np.ndarray:
        """The distinct curvatures [1/m] on the path (0 included where it has a straight part)."""
        return np.unique(self.segments.kappa)

    @property
    def min_radius(self) -> float:
        """The smallest radius of curvature [m] (``inf`` for a straight path)."""
        k = float(np.max(np.abs(self.segments.kappa)))
        return math.inf if k == 0.0 else 1.0 / k

    @property
    def segment_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(start, x0, y0, gamma0, kappa)``: the segments as the scalar functions and the kernel take them."""
        seg = self.segments
        return tuple(np.ascontiguousarray(a, dtype=float) for a in (seg.start, seg.x0, seg.y0, seg.gamma0, seg.kappa))  # type: ignore[return-value]

    def to_dict(self) -> dict[str, Any]:
        """``{"kind": …, field: value, …}``: what ``make_path`` takes back."""
        out: dict[str, Any] = {"kind": self.kind}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            out[f.name] = [list(p) for p in value] if isinstance(value, tuple) else value
        return out

    # ------------------------------------------------------------ evaluation
    def _segment_of(self, ell: np.ndarray) -> np.ndarray:
        start = self.segments.start
        if len(start) == 1:
            return np.zeros(np.shape(ell), dtype=np.intp)
        return np.clip(np.searchsorted(start, ell, side="right") - 1, 0, len(start) - 1)  # type: ignore[no-any-return]

    def frame(self, ell: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(x, y, γ, κ)`` of the path at arc lengths ``ell`` (any shape) [m, m, rad, 1/m].

        ``γ`` is not wrapped: on a circle it grows with ``ℓ``.
        """
        ell = np.asarray(ell, dtype=float)
        seg = self.segments
        k = self._segment_of(ell)
        s = ell - seg.start[k]
        g0, kappa = seg.gamma0[k], seg.kappa[k]
        gamma = g0 + kappa * s
        arc = kappa != 0.0
        safe = np.where(arc, kappa, 1.0)
        x = seg.x0[k] + np.where(arc, (np.sin(gamma) - np.sin(g0)) / safe, s * np.cos(g0))
        y = seg.y0[k] + np.where(arc, (np.cos(g0) - np.cos(gamma)) / safe, s * np.sin(g0))
        return x, y, gamma, kappa

    def curvature(self, ell: Any) -> np.ndarray:
        """``κ(ℓ)`` [1/m] (piecewise constant)."""
        return self.segments.kappa[self._segment_of(np.asarray(ell, dtype=float))]  # type: ignore[no-any-return]

    def project(self, x: Any, y: Any, guess: Any, iterations: int = PROJECTION_ITERATIONS) -> np.ndarray:
        """The arc length ``ℓ`` of the projection of ``(x, y)`` on the path, by Newton's method from ``guess``.

        Solves ``(p − P(ℓ))·t(ℓ) = 0`` (the foot of the normal through ``p``)
        with the step ``ℓ ← ℓ + (p − P)·t / (1 − κ·d)``, ``d = (p − P)·n``:
        exact in one step on a line, quadratic on an arc. Starting from the
        previous instant's value keeps ``ℓ`` continuous in time, with no global
        search (a route's legs can pass close to each other).
        """
        ell = np.array(guess, dtype=float)
        for _ in range(iterations):
            px, py, gamma, kappa = self.frame(ell)
            dx, dy = x - px, y - py
            c, s = np.cos(gamma), np.sin(gamma)
            along, normal = dx * c + dy * s, dy * c - dx * s
            ell = ell + along / np.maximum(1.0 - kappa * normal, MIN_METRIC)
        return ell

    def closest(self, x: Any, y: Any) -> np.ndarray:
        """The arc length of the nearest point of the path to ``(x, y)``: a global search over the segments.

        Used once per episode, at reset (afterwards ``project`` follows the
        projection continuously). On a circle the answer is within half a lap of
        the start, ``ℓ ∈ [−πR, πR)``.
        """
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        seg = self.segments
        best_ell = np.zeros(np.broadcast_shapes(x.shape, y.shape))
        best_dist = np.full(best_ell.shape, np.inf)
        last = len(seg.start) - 1
        for k in range(last + 1):
            lo = -np.inf if k == 0 else 0.0
            hi = np.inf if k == last else float(seg.length[k])
            g0, kappa = float(seg.gamma0[k]), float(seg.kappa[k])
            dx, dy = x - seg.x0[k], y - seg.y0[k]
            if kappa == 0.0:
                s = dx * math.cos(g0) + dy * math.sin(g0)
            else:
                radius = 1.0 / abs(kappa)
                sign = 1.0 if kappa > 0 else -1.0
                # centre of the arc, and the angle swept from the segment's start to p (in the turn's sense)
                cx, cy = -math.sin(g0) / kappa, math.cos(g0) / kappa
                start_angle = math.atan2(-cy, -cx)
                swept = sign * (np.arctan2(dy - cy, dx - cx) - start_angle)
                if math.isinf(hi):  # an endless arc (circle): within half a lap of its start
                    swept = np.mod(swept + math.pi, 2.0 * math.pi) - math.pi
                else:
                    swept = np.mod(swept, 2.0 * math.pi)
                    # past the arc's end: the nearer of its two ends
                    past = swept * radius > hi
                    swept = np.where(past & (2.0 * math.pi - swept < swept - hi / radius), 0.0, swept)
                s = swept * radius
            s = np.clip(s, lo, hi)
            px, py, _, _ = self.frame(seg.start[k] + s)
            dist = np.hypot(x - px, y - py)
            better = dist < best_dist
            best_ell = np.where(better, seg.start[k] + s, best_ell)
            best_dist = np.where(better, dist, best_dist)
        return best_ell

    def lane_point(self, ell: Any, offset: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x, y, γ)``: the point ``P(ℓ) + offset·n(ℓ)`` of the lane ``offset`` [m] and the tangent angle there."""
        x, y, gamma, _ = self.frame(ell)
        return x - offset * np.sin(gamma), y + offset * np.cos(gamma), gamma

    def points(self, ell_from: float, ell_to: float, offset: float = 0.0, spacing: float = 5.0) -> np.ndarray:
        """``(M, 2)`` points of the lane ``P(ℓ) + offset·n(ℓ)`` for ``ℓ`` from ``ell_from`` to ``ell_to`` (drawing)."""
        count = max(2, math.ceil(abs(ell_to - ell_from) / spacing) + 1)
        x, y, _ = self.lane_point(np.linspace(ell_from, ell_to, count), offset)
        return np.column_stack([x, y])


def _point(p: np.ndarray) -> tuple[float, float]:
    """A waypoint as plain floats (for messages)."""
    return (float(p[0]), float(p[1]))


def _chain(pieces: list[tuple[float, float]], x0: float = 0.0, y0: float = 0.0, gamma0: float = 0.0) -> Segments:
    """Segments from ``(length, curvature)`` pieces laid end to end from ``(x0, y0)`` heading ``gamma0``."""
    starts, xs, ys, gammas, kappas, lengths = [], [], [], [], [], []
    ell, x, y, gamma = 0.0, x0, y0, gamma0
    for length, kappa in pieces:
        starts.append(ell)
        xs.append(x)
        ys.append(y)
        gammas.append(gamma)
        kappas.append(kappa)
        lengths.append(length)
        if math.isinf(length):
            break
        end = gamma + kappa * length
        if kappa == 0.0:
            x, y = x + length * math.cos(gamma), y + length * math.sin(gamma)
        else:
            x, y = x + (math.sin(end) - math.sin(gamma)) / kappa, y + (math.cos(gamma) - math.cos(end)) / kappa
        ell, gamma = ell + length, end
    return Segments(*(np.array(v, dtype=float) for v in (starts, xs, ys, gammas, kappas, lengths)))


@dataclass(frozen=True)
class StraightPath(Path):
    """The paper's path: the x axis, ``P(ℓ) = (ℓ, 0)``, ``γ = 0``, ``κ = 0``; lanes ``y = D_y``."""

    kind: ClassVar[str] = "straight"

    @property
    def is_straight(self) -> bool:
        return True

    def _build(self) -> Segments:
        return _chain([(math.inf, 0.0)])


@dataclass(frozen=True)
class CirclePath(Path):
    """A circle of ``radius`` [m] turning ``left`` (counter-clockwise, ``κ = 1/R``) or ``right``.

    It starts at the origin heading along +x (tangent to the paper's path
    there), so its centre is ``(0, ±radius)``; ``ℓ`` grows without bound as
    the formation goes round.
    """

    radius: float = 300.0
    turn: str = "left"

    kind: ClassVar[str] = "circle"

    def __post_init__(self) -> None:
        check_number("path", "radius", self.radius, strict=True)
        if self.turn not in ("left", "right"):
            raise ConfigError(f"path.turn must be 'left' or 'right', got {self.turn!r}")

    def _build(self) -> Segments:
        sign = 1.0 if self.turn == "left" else -1.0
        return _chain([(math.inf, sign / float(self.radius))])


@dataclass(frozen=True)
class WaypointPath(Path):
    """Straight legs between ``waypoints`` [m], each corner rounded by an arc of ``turn_radius`` [m].

    The arc at a corner that turns by ``φ`` is tangent to both legs, at
    ``turn_radius·tan(|φ|/2)`` from the corner; legs must be long enough for
    the arcs at both their ends. The path runs on past the last waypoint along
    the last leg, and before the first one along the first leg.
    """

    waypoints: tuple[tuple[float, float], ...] = ((0.0, 0.0), (1000.0, 0.0))
    turn_radius: float = 300.0

    kind: ClassVar[str] = "waypoints"

    def __post_init__(self) -> None:
        try:
            points = np.array(self.waypoints, dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(f"path.waypoints must be a list of (x, y) pairs, got {self.waypoints!r}") from None
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2 or not np.all(np.isfinite(points)):
            raise ConfigError(f"path.waypoints must be at least two finite (x, y) pairs, got {self.waypoints!r}")
        object.__setattr__(self, "waypoints", tuple((float(a), float(b)) for a, b in points))
        check_number("path", "turn_radius", self.turn_radius, strict=True)
        self._build()  # refuse legs too short for their turns now, not at the first step

    def _build(self) -> Segments:
        points = np.array(self.waypoints)
        legs = np.diff(points, axis=0)
        lengths = np.hypot(legs[:, 0], legs[:, 1])
        for k, length in enumerate(lengths):
            if length == 0.0:
                raise ConfigError(
                    f"path.waypoints {k} and {k + 1} coincide at {_point(points[k])}: a leg needs a length"
                )
        headings = np.arctan2(legs[:, 1], legs[:, 0])
        turns = np.mod(np.diff(headings) + math.pi, 2.0 * math.pi) - math.pi
        radius = float(self.turn_radius)
        for k, turn in enumerate(turns):
            if abs(abs(turn) - math.pi) < 1e-9:
                raise ConfigError(
                    f"path.waypoints turn back on themselves at waypoint {k + 1} {_point(points[k + 1])}: a 180° "
                    "corner cannot be rounded by one arc (put two waypoints, at least 2·turn_radius apart, across it)"
                )
        tangent = np.concatenate([[0.0], radius * np.tan(np.abs(turns) / 2.0), [0.0]])
        pieces: list[tuple[float, float]] = []
        for k, length in enumerate(lengths):
            straight = length - tangent[k] - tangent[k + 1]
            if straight < -1e-9 * max(1.0, length):
                raise ConfigError(
                    f"path.waypoints: leg {k} from {_point(points[k])} to {_point(points[k + 1])} is {length:g} m "
                    f"long, but the turns at its ends need {tangent[k]:g} m + {tangent[k + 1]:g} m of it at "
                    f"turn_radius = {radius:g} m (reduce turn_radius or move the waypoints apart)"
                )
            if k == len(lengths) - 1:
                pieces.append((math.inf, 0.0))
            elif straight > 0.0 or k == 0:  # the first leg always: before the start the path runs along it
                pieces.append((max(float(straight), 0.0), 0.0))
            if k < len(turns) and turns[k] != 0.0:
                pieces.append((radius * abs(float(turns[k])), math.copysign(1.0 / radius, float(turns[k]))))
        segments = _chain(pieces, float(points[0, 0]), float(points[0, 1]), float(headings[0]))
        # the last leg's length up to the last waypoint (it runs on past it)
        remainder = float(lengths[-1] - tangent[-2]) if len(lengths) > 1 else float(lengths[0])
        segments.length[-1] = remainder
        return segments

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "waypoints": [list(p) for p in self.waypoints], "turn_radius": self.turn_radius}


@dataclass(frozen=True)
class LawnmowerPath(Path):
    """A lawnmower survey: ``legs`` parallel legs of ``leg_length`` [m], ``spacing`` [m] apart.

    The first leg starts at the origin heading along +x; the next legs lie
    towards +y (``first_turn="left"``) or −y, and alternate in direction. The
    legs are joined by turns of ``turn_radius``: two quarter circles and a
    straight of ``spacing − 2·turn_radius`` between them (a half circle when
    ``spacing = 2·turn_radius``). It is the ``WaypointPath`` through the
    legs' ends.
    """

    legs: int = 4
    leg_length: float = 2000.0
    spacing: float = 600.0
    turn_radius: float = 300.0
    first_turn: str = "left"

    kind: ClassVar[str] = "lawnmower"

    def __post_init__(self) -> None:
        if isinstance(self.legs, bool) or not isinstance(self.legs, (int, np.integer)) or self.legs < 1:
            raise ConfigError(f"path.legs must be an integer ≥ 1, got {self.legs!r}")
        for key in ("leg_length", "spacing", "turn_radius"):
            check_number("path", key, getattr(self, key), strict=True)
        if self.first_turn not in ("left", "right"):
            raise ConfigError(f"path.first_turn must be 'left' or 'right', got {self.first_turn!r}")
        if self.spacing < 2.0 * self.turn_radius - 1e-9:
            raise ConfigError(
                f"path.spacing = {self.spacing:g} m is less than 2·turn_radius = {2 * self.turn_radius:g} m: the "
                "turn between two legs cannot be flown at that radius"
            )
        object.__setattr__(self, "legs", int(self.legs))  # a numpy integer too: the description stays JSON
        if self.legs > 1 and self.leg_length < 2.0 * self.turn_radius - 1e-9:
            raise ConfigError(
                f"path.leg_length = {self.leg_length:g} m is shorter than the two turns at its ends need "
                f"(2·turn_radius = {2 * self.turn_radius:g} m)"
            )

    def waypoint_path(self) -> WaypointPath:
        """The equivalent ``WaypointPath``."""
        side = 1.0 if self.first_turn == "left" else -1.0
        points = [(0.0, 0.0)]
        for k in range(self.legs):
            x_end = float(self.leg_length) if k % 2 == 0 else 0.0
            y = side * k * float(self.spacing)
            points.append((x_end, y))
            if k < self.legs - 1:
                points.append((x_end, y + side * float(self.spacing)))
        return WaypointPath(tuple(points), float(self.turn_radius))

    def _build(self) -> Segments:
        return self.waypoint_path().segments


#: The path kinds, by the name a mapping's ``kind`` gives.
PATH_KINDS: dict[str, type[Path]] = {cls.kind: cls for cls in (StraightPath, CirclePath, WaypointPath, LawnmowerPath)}


def make_path(spec: Any) -> Path:
    """A ``Path`` from a path, a kind name (its defaults), a mapping with ``kind``, or None (straight).

    Raises:
        ConfigError: unknown kind or field, or an invalid value (named).
    """
    if spec is None:
        return StraightPath()
    if isinstance(spec, Path):
        return spec
    if isinstance(spec, str):
        spec = {"kind": spec}
    if not isinstance(spec, Mapping):
        raise ConfigError(f"path must be a Path, a kind name or a mapping with 'kind', got {spec!r}")
    values = dict(spec)
    kind = values.pop("kind", None)
    if kind not in PATH_KINDS:
        raise ConfigError(f"path.kind must be one of {sorted(PATH_KINDS)}, got {kind!r}")
    cls = PATH_KINDS[kind]
    valid = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(values) - set(valid))
    if unknown:
        raise ConfigError(f"path of kind {kind!r} got unknown key(s) {unknown}; valid keys: {valid}")
    if "waypoints" in values and isinstance(values["waypoints"], list):
        values["waypoints"] = tuple(tuple(p) if isinstance(p, list) else p for p in values["waypoints"])
    try:
        return cls(**values)
    except TypeError as err:
        raise ConfigError(f"path of kind {kind!r}: {err}") from None


class PathCoordinates(NamedTuple):
    """Where vessels are relative to a path (arrays of one shape; docs/paths.md, "Path coordinates").

    Attributes:
        ell: arc length ℓ of the projection [m].
        offset: signed distance d from the path along its normal [m] (``e = d − D_y``).
        beta: heading relative to the path's tangent, ``ψ − γ(ℓ)`` [rad] (not wrapped).
        kappa: curvature κ(ℓ) [1/m].
        metric: ``1 − κ·d`` [-] (positive inside the radius of curvature).
        ell_dot: ``ℓ̇ = (u cos β − v sin β + V·t)/(1 − κ·d)`` [m/s], with ``V·t`` the
            current along the tangent when one is given (over ground), else 0 (through the water).
    """

    ell: np.ndarray
    offset: np.ndarray
    beta: np.ndarray
    kappa: np.ndarray
    metric: np.ndarray
    ell_dot: np.ndarray


def path_coordinates(
    path: Path,
    x: np.ndarray,
    y: np.ndarray,
    psi: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    guess: np.ndarray,
    current: tuple[Any, Any] | None = None,
) -> PathCoordinates:
    """``PathCoordinates`` of vessels at ``(x, y, ψ, u, v)``, projecting from ``guess`` (``Path.project``).

    ``current``: ``(V_x, V_y)`` [m/s] to make ``ℓ̇`` over ground.
    """
    ell = path.project(x, y, guess)
    px, py, gamma, kappa = path.frame(ell)
    c, s = np.cos(gamma), np.sin(gamma)
    offset = (y - py) * c - (x - px) * s
    beta = psi - gamma
    metric = 1.0 - kappa * offset
    along = u * np.cos(beta) - v * np.sin(beta)
    if current is not None:
        along = along + current[0] * c + current[1] * s
    return PathCoordinates(ell, offset, beta, kappa, metric, along / metric)


# ----------------------------------------------------------------------------- one point at a time
# The same evaluations for one arc length, on the segment arrays of Path.segment_arrays, in plain
# arithmetic: the compiled kernel (marine_formation_env._numba) registers them with numba and calls
# them per vessel. They compute what Path.frame / Path.project compute, in the same order.


def segment_frame(
    start: np.ndarray, x0: np.ndarray, y0: np.ndarray, gamma0: np.ndarray, kappa: np.ndarray, ell: float
) -> tuple[float, float, float, float]:
    """``(x, y, γ, κ)`` of the path at one arc length ``ell`` (as ``Path.frame``)."""
    k = 0
    for m in range(1, start.shape[0]):
        if ell >= start[m]:
            k = m
    s = ell - start[k]
    g0, kap = gamma0[k], kappa[k]
    gamma = g0 + kap * s
    if kap != 0.0:
        return (
            x0[k] + (math.sin(gamma) - math.sin(g0)) / kap,
            y0[k] + (math.cos(g0) - math.cos(gamma)) / kap,
            gamma,
            kap,
        )
    return x0[k] + s * math.cos(g0), y0[k] + s * math.sin(g0), gamma, kap


def segment_project(
    start: np.ndarray,
    x0: np.ndarray,
    y0: np.ndarray,
    gamma0: np.ndarray,
    kappa: np.ndarray,
    x: float,
    y: float,
    guess: float,
) -> float:
    """The projection's arc length of one point, by Newton's method from ``guess`` (as ``Path.project``)."""
    ell = guess
    for _ in range(PROJECTION_ITERATIONS):
        px, py, gamma, kap = segment_frame(start, x0, y0, gamma0, kappa, ell)
        dx, dy = x - px, y - py
        c, s = math.cos(gamma), math.sin(gamma)
        along, normal = dx * c + dy * s, dy * c - dx * s
        ell = ell + along / max(1.0 - kap * normal, MIN_METRIC)
    return ell
