"""The sea around the vessels: ocean currents and sensor noise (our extensions of the paper).

* ``Current``: an inertial, irrotational current that carries the vessels
  (``η̇ = R(ψ)·ν_r + V_c``, ``vessel_derivatives``),
  constant or slowly varying in magnitude. The paper's controllers do not know
  it: the built-in LOS path follower then settles with a steady cross-track
  error, which integral LOS removes (``baselines.ReferencePolicy`` with
  ``integral_los``; Børhaug, Pavlov and Pettersen, "Integral LOS control for
  path following of underactuated marine surface vessels in the presence of
  constant ocean currents", CDC 2008).
* ``SensorNoise``: zero-mean Gaussian noise on what a vessel measures of
  itself: its own observation and the data it transmits. The built-in inner
  loops of the ``speed`` and ``guidance`` levels act continuously on the true
  state; only what the policy sees is noisy.

Both are fields of ``Settings``
(``current=…``, ``sensor_noise=…``; mappings are accepted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from marine_formation_env.dynamics import current_velocity
from marine_formation_env.errors import check_number
from marine_formation_env.streams import BlockStream

__all__ = [
    "Current",
    "SensorNoise",
    "SensorNoiseSource",
]


@dataclass(frozen=True)
class Current:
    """An inertial ocean current ``V_c(t) = (speed + amplitude·sin(2πt/period))·(cos β, sin β)``.

    Attributes:
        speed: mean magnitude [m/s] (typical ocean currents: 0.1-1 m/s).
        direction: β, the direction the current flows *towards* [rad], from the
            path's x axis; ``π/2`` is a cross current pushing vessels to +y.
        amplitude: slow variation of the magnitude [m/s] (0: constant).
        period: period of that variation [s]; keep it long against the vessel's
            time constants (≳ 100 s), as the model neglects the current's acceleration.
    """

    speed: float = 0.0
    direction: float = 0.0
    amplitude: float = 0.0
    period: float = 600.0

    def __post_init__(self) -> None:
        check_number("current", "speed", self.speed)
        check_number("current", "direction", self.direction, minimum=None)
        check_number("current", "amplitude", self.amplitude)
        check_number("current", "period", self.period, strict=True)

    @property
    def is_zero(self) -> bool:
        """Still water."""
        return self.speed == 0.0 and self.amplitude == 0.0

    @property
    def coefficients(self) -> tuple[float, float, float, float, float]:
        """``(speed, amplitude, ω, cos β, sin β)`` for ``current_velocity``."""
        return (
            float(self.speed),
            float(self.amplitude),
            2.0 * math.pi / float(self.period),
            math.cos(self.direction),
            math.sin(self.direction),
        )

    def velocity(self, t: Any) -> tuple[Any, Any]:
        """``(V_x, V_y)`` [m/s] at time(s) ``t`` [s]."""
        return current_velocity(*self.coefficients, np.asarray(t, dtype=float))  # type: ignore[no-any-return]


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of the Gaussian noise on a vessel's measurement of itself.

    Fresh, independent noise is drawn every control period from the
    formation's stream of normals (``SensorNoiseSource``). It enters the
    vessel's own observation and the (x, ẋ) it transmits.

    Attributes:
        position: on x and y [m].
        heading: on ψ [rad].
        speed: on u and v [m/s].
        yaw_rate: on r [rad/s].
    """

    position: float = 0.0
    heading: float = 0.0
    speed: float = 0.0
    yaw_rate: float = 0.0

    def __post_init__(self) -> None:
        for key in ("position", "heading", "speed", "yaw_rate"):
            check_number("sensor_noise", key, getattr(self, key))

    @property
    def is_zero(self) -> bool:
        """No noise at all."""
        return not any((self.position, self.heading, self.speed, self.yaw_rate))

    def as_array(self) -> np.ndarray:
        """Standard deviations for the state columns ``x, y, psi, u, v, r``."""
        return np.array([self.position, self.position, self.heading, self.speed, self.speed, self.yaw_rate])


class SensorNoiseSource:
    """The sensor-noise draws of ``B`` formations of ``N`` vessels, held by the core.

    Each formation draws from its own generator of standard normals (the
    second stream of ``channel_streams``),
    one row of ``6·N`` numbers per control instant, scaled by the standard
    deviations of ``SensorNoise``.
    """

    def __init__(self, noise: SensorNoise, n: int, num_envs: int) -> None:
        self.n = n
        self.scale = noise.as_array()
        self.normals = BlockStream(num_envs, 6 * n, normal=True)

    def seed(self, b: int, generator: np.random.Generator) -> None:
        """Give formation ``b`` a new stream of standard normals."""
        self.normals.seed(b, generator)

    def draw(self, ids: np.ndarray) -> np.ndarray:
        """``(len(ids), N, 6)`` noise on the state columns ``x, y, psi, u, v, r`` of formations ``ids``."""
        return self.normals.take(ids).reshape(len(ids), self.n, 6) * self.scale
