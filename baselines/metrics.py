"""Episode metrics of the paper's control goals (7)-(10), computed from a ``Trajectory``.

Definitions (n vessels, θ_j = x_j − D_xj):

* cross-track error e_j = y_j − D_yj (goal 7); heading ψ_j (goal 8, wrapped).
  With an ocean current a vessel that holds its path must crab into the
  current, so goal (8) becomes one on the course over ground
  ``χ_j = atan2(ẏ_j, ẋ_j)`` (inertial velocities, current included), which is
  what "heading" then measures;
* coordination spread max_j θ_j − min_j θ_j (goal 9a);
* speed error u_j − u_d(t) (goals 9b, 10);
* on a curved path (docs/paths.md) the same goals in path coordinates, from
  each vessel's projection ℓ_j followed through the recorded states:
  cross-track e_j = (p_j − P(ℓ_j))·n − D_yj; heading: the course over ground
  relative to the path's tangent, χ_j − γ(ℓ_j) (a vessel on its lane crabs
  into the turn, so its heading cannot be the tangent's); θ_j = ℓ_j − D_xj;
  speed error: the vessel's speed along its lane minus the lane's speed,
  (1 − κ·D_yj)·(ℓ̇_j − u_d), in m/s along the lane, with ℓ̇_j through the water
  (as u_j − u_d on the straight path);
* settling time: the earliest time after which, until the end of the episode,
  max |e_j| ≤ 0.5 m, max |ψ_j| ≤ 0.5°, the spread ≤ 0.5 m and
  max |u_j − u_d| ≤ 0.05 m/s (``SETTLING_BANDS``); None if never;
* time outside the band: control periods with some u_cj ∉ (U_min, U_max), in s;
  and the same for the vessels' actual surge speeds u_j (recorded states);
* effort: mean over periods and vessels of the squared normalized action ‖a‖²/A;
* action change (smoothness): mean over consecutive periods, vessels and
  action components of the normalized action's change |a_k − a_{k−1}|
  (each component in [−1, 1], so 0 … 2; 0 for a constant command); and the
  same per component, ``action_change_<command>`` with the level's command
  names (``marine_formation_env.actions.LEVEL_COMMANDS``: ``tau_u``,
  ``tau_r``; ``u_c``, ``psi_d``; ``u_c``), which says which command chatters;
* return: per-vessel sum of rewards, averaged over vessels;
* success: the episode ran to its time limit (no collision, no exit from the
  workspace or envelope) and at its end every error is inside
  ``SUCCESS_BANDS``: max |e_j| ≤ 1 m, max |ψ_j| ≤ 2°, spread ≤ 1 m,
  max |u_j − u_d| ≤ 0.1 m/s.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from baselines.rollout import Trajectory
from marine_formation_env.actions import LEVEL_COMMANDS
from marine_formation_env.dynamics import PSI, U, V, X, Y, wrap_angle
from marine_formation_env.paths import PathCoordinates, path_coordinates
from marine_formation_env.scenarios import ScenarioConfig

__all__ = [
    "SETTLING_BANDS",
    "SUCCESS_BANDS",
    "action_change",
    "action_change_by_entry",
    "episode_metrics",
    "goal_errors",
    "path_coordinates_along",
    "settling_time",
    "summarize",
]

#: Tolerances that define "settled": cross-track [m], heading [deg], spread [m], speed [m/s].
SETTLING_BANDS = {"cross_track": 0.5, "heading_deg": 0.5, "spread": 0.5, "speed": 0.05}
#: Final-time tolerances of a successful episode (same units).
SUCCESS_BANDS = {"cross_track": 1.0, "heading_deg": 2.0, "spread": 1.0, "speed": 0.1}


def _heading(traj: Trajectory, cfg: ScenarioConfig) -> np.ndarray:
    """ψ (still water) or the course over ground χ (with a current), ``(T+1, n)`` [rad]."""
    psi = traj.state[..., PSI]
    if cfg.current.is_zero:
        return wrap_angle(psi)  # type: ignore[no-any-return]
    u, v = traj.state[..., U], traj.state[..., V]
    vc_x, vc_y = cfg.current.velocity(traj.t[:, None])
    return np.arctan2(u * np.sin(psi) + v * np.cos(psi) + vc_y, u * np.cos(psi) - v * np.sin(psi) + vc_x)


def path_coordinates_along(traj: Trajectory, cfg: ScenarioConfig) -> PathCoordinates:
    """Path coordinates ``(T+1, n)`` of a trajectory on a curved path (ℓ̇ through the water, as the goals ask).

    The projection starts from a global search at the first instant and is
    then followed from one recorded instant to the next (Newton steps from the
    previous ℓ), as the simulation follows it.
    """
    s = traj.state
    guess = cfg.path.closest(s[0, :, X], s[0, :, Y])
    rows = []
    for k in range(len(s)):
        c = path_coordinates(cfg.path, s[k, :, X], s[k, :, Y], s[k, :, PSI], s[k, :, U], s[k, :, V], guess)
        rows.append(c)
        guess = c.ell
    return PathCoordinates(*(np.stack(column) for column in zip(*rows, strict=True)))


def goal_errors(traj: Trajectory, cfg: ScenarioConfig) -> dict[str, np.ndarray]:
    """``(T+1, n)`` errors of goals (7)-(10) (``spread``: ``(T+1,)``) as the module docstring defines them."""
    return _errors(traj, cfg)


def _errors(traj: Trajectory, cfg: ScenarioConfig) -> dict[str, np.ndarray]:
    s = traj.state
    if not cfg.straight:
        c = path_coordinates_along(traj, cfg)
        psi, u, v = s[..., PSI], s[..., U], s[..., V]
        if cfg.current.is_zero:
            course = psi + np.arctan2(v, u)
        else:
            vc_x, vc_y = cfg.current.velocity(traj.t[:, None])
            course = np.arctan2(u * np.sin(psi) + v * np.cos(psi) + vc_y, u * np.cos(psi) - v * np.sin(psi) + vc_x)
        d_y = cfg.formation[:, 1]
        return {
            "cross_track": c.offset - d_y,
            "heading_deg": np.degrees(wrap_angle(course - (psi - c.beta))),  # χ − γ(ℓ)
            "spread": np.ptp(c.ell - cfg.formation[:, 0], axis=1),
            "speed": (1.0 - c.kappa * d_y) * (c.ell_dot - traj.u_d[:, None]),
        }
    theta = s[..., X] - cfg.formation[:, 0]
    return {
        "cross_track": s[..., Y] - cfg.formation[:, 1],
        "heading_deg": np.degrees(_heading(traj, cfg)),
        "spread": np.ptp(theta, axis=1),
        "speed": s[..., U] - traj.u_d[:, None],
    }


def settling_time(traj: Trajectory, cfg: ScenarioConfig, bands: dict[str, float] = SETTLING_BANDS) -> float | None:
    """Earliest time after which every error stays inside ``bands`` (see module docstring)."""
    err = _errors(traj, cfg)
    inside = np.ones(len(traj.t), dtype=bool)
    for key, tol in bands.items():
        value = np.abs(err[key])
        inside &= (value if value.ndim == 1 else value.max(axis=1)) <= tol
    if not inside[-1]:
        return None
    outside = np.flatnonzero(~inside)
    return float(traj.t[0] if outside.size == 0 else traj.t[outside[-1] + 1])


def _surge_outside_time(traj: Trajectory, cfg: ScenarioConfig) -> float:
    """Time [s] during which some vessel's surge speed u_j was outside (U_min, U_max).

    Each recorded instant but the last stands for the control period that follows it.
    """
    u = traj.state[:-1, :, U]
    outside = ~np.all((u > cfg.u_min) & (u < cfg.u_max), axis=1)
    return float(np.sum(np.diff(traj.t)[outside]))


def action_change(actions: np.ndarray) -> float:
    """Mean |a_k − a_{k−1}| of ``(T, n, A)`` normalized actions over k ≥ 1, vessels and components (0 if T < 2).

    The mean of ``action_change_by_entry`` (every component has the same number of changes).
    """
    return float(np.mean(action_change_by_entry(actions)))


def action_change_by_entry(actions: np.ndarray) -> np.ndarray:
    """Mean |a_k − a_{k−1}| of ``(T, n, A)`` normalized actions per component: ``(A,)`` (zeros if T < 2)."""
    actions = np.asarray(actions, dtype=float)
    if actions.ndim != 3:
        raise ValueError(f"actions must have the shape (T, n, A), got {actions.shape}")
    if len(actions) < 2:
        return np.zeros(actions.shape[-1])
    return np.mean(np.abs(np.diff(actions, axis=0)), axis=(0, 1))  # type: ignore[no-any-return]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def episode_metrics(traj: Trajectory, cfg: ScenarioConfig) -> dict[str, Any]:
    """All metrics of one episode as a JSON-friendly dict (units in the key names' docs)."""
    err = _errors(traj, cfg)
    u_c = traj.commanded_speed
    known = np.all(np.isfinite(u_c), axis=1) if u_c.size else np.zeros(0, dtype=bool)
    outside = ~np.all((u_c > cfg.u_min) & (u_c < cfg.u_max), axis=1) & known
    returns = traj.rewards.sum(axis=0)
    i, j = np.triu_indices(cfg.n_vessels, k=1)
    separation = np.hypot(traj.state[:, i, X] - traj.state[:, j, X], traj.state[:, i, Y] - traj.state[:, j, Y])
    settle = settling_time(traj, cfg)
    commands = traj.actions[..., : cfg.control_dim]  # without the transmit entry
    by_entry = action_change_by_entry(commands)
    duration = float(traj.t[-1])
    success = not traj.terminated and all(
        float(np.max(np.abs(err[key][-1]))) <= tol for key, tol in SUCCESS_BANDS.items()
    )
    return {
        "episode_time": float(traj.t[-1]),
        "steps": len(traj.t) - 1,
        "return": float(returns.mean()),
        "return_per_vessel": returns.tolist(),
        "final_cross_track_max": float(np.abs(err["cross_track"][-1]).max()),
        "rms_cross_track": _rms(err["cross_track"]),
        "final_heading_max_deg": float(np.abs(err["heading_deg"][-1]).max()),
        "rms_heading_deg": _rms(err["heading_deg"]),
        "final_coordination_spread": float(err["spread"][-1]),
        "rms_coordination_spread": _rms(err["spread"]),
        "final_speed_error_max": float(np.abs(err["speed"][-1]).max()),
        "rms_speed_error": _rms(err["speed"]),
        "settling_time": settle,
        "commanded_speed_min": float(np.nanmin(u_c)) if known.any() else None,
        "commanded_speed_max": float(np.nanmax(u_c)) if known.any() else None,
        "time_outside_speed_band": float(outside.sum() * cfg.dt),
        "surge_outside_band_time": _surge_outside_time(traj, cfg),
        "effort": float(np.mean(np.square(commands))) if commands.size else 0.0,
        "action_change": float(np.mean(by_entry)),
        **{
            f"action_change_{name}": float(change)
            for name, change in zip(LEVEL_COMMANDS[cfg.action_level], by_entry, strict=True)
        },
        "min_separation": float(separation.min()),
        **_message_metrics(traj, cfg.n_vessels, duration),
        "terminated": traj.terminated,
        "collision": traj.collision,
        "success": success,
    }


def _message_metrics(traj: Trajectory, n: int, duration: float) -> dict[str, Any]:
    """``message_rate`` (broadcasts sent per vessel per second) and ``bit_rate`` [bit/s per vessel] over the
    episode's steps, and each counter's total (``messages_sent``, …; ``marine_formation_env.channel``)."""
    if not traj.messages:
        return {}
    totals = {key: int(value.sum()) for key, value in traj.messages.items()}
    per = n * duration if duration > 0 else float("nan")
    return {"message_rate": totals["messages_sent"] / per, "bit_rate": totals["bits_sent"] / per, **totals}


def summarize(episodes: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Mean and std over episodes of every numeric metric (None-valued entries skipped)."""
    out: dict[str, dict[str, float]] = {}
    for key in episodes[0]:
        values = [e[key] for e in episodes if isinstance(e[key], (int, float)) and not isinstance(e[key], bool)]
        flags = [e[key] for e in episodes if isinstance(e[key], bool)]
        if flags:
            out[key] = {"mean": float(np.mean(flags)), "std": float(np.std(flags)), "count": len(flags)}
        elif values:
            out[key] = {"mean": float(np.mean(values)), "std": float(np.std(values)), "count": len(values)}
    return out
