"""Figures in the style of the paper's Fig. 6 (matplotlib, imported lazily).

``plot_episode`` draws, for one recorded episode:

(a) the paths in the plane with the desired paths and the vessels drawn as
    oriented markers at a few instants, (b) cross-track errors y_j − D_yj,
(c) headings ψ_j, (d) along-track coordination errors
    x_j − D_xj − (x_k − D_xk) for every pair (or relative to the mean when
    n > 4), (e) surge speeds u_j and commanded speeds u_cj with u_d(t) and the
    band (U_min, U_max).

On a curved path (docs/paths.md) the panels are in path coordinates: (a)
draws the path and the lanes with equal axes, (b) the cross-track errors
e_j, (c) the course over ground relative to the path's tangent, (d) the
coordination errors of θ_j = ℓ_j − D_xj, and (e) adds each vessel's lane
speed (1 − κ·D_yj)·u_d (thin dashed).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from baselines.metrics import goal_errors, path_coordinates_along
from baselines.rollout import Trajectory
from marine_formation_env.atomic import atomic_path, atomic_write_text
from marine_formation_env.dynamics import wrap_angle
from marine_formation_env.provenance import provenance
from marine_formation_env.render import require_matplotlib, vessel_color
from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["plot_comparison", "plot_episode", "save_figure"]


def _snapshot_indices(t: np.ndarray, count: int = 6) -> np.ndarray:
    if t[-1] > 600.0:  # a long run (a survey): instants spread over it
        marks = np.linspace(0.0, t[-1], 7)
    else:
        marks = np.array([0.0, 20.0, 50.0, 100.0, 200.0, t[-1]])[:count]
    marks = marks[marks <= t[-1]]
    return np.unique(np.searchsorted(t, marks).clip(0, len(t) - 1))


def _finish(fig: Any, cfg: ScenarioConfig, path: str | Path | None, title: str) -> Any:
    """Title, layout and (if ``path``) save a figure."""
    fig.suptitle(title or f"scenario {cfg.name!r}, action level {cfg.action_level!r}", fontsize=11)
    fig.tight_layout()
    if path is not None:
        save_figure(fig, path)
    return fig


def save_figure(fig: Any, path: str | Path) -> None:
    """Save ``fig`` to ``path`` (format from the suffix), creating the folder; atomic (whole or not at all)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp)


def write_report(
    out: Path, report: dict[str, Any], markdown: str, plot: Callable[[dict[str, Any], Path], Any], command: str
) -> None:
    """Write a grid's report as ``out.json`` (with its ``provenance``), ``out.md`` and the figure ``out.png``.

    Each file is written whole or not at all; without matplotlib the figure is left out with a message.
    """
    report["provenance"] = provenance(command)
    atomic_write_text(out.with_suffix(".json"), json.dumps(report, indent=2, allow_nan=False))
    atomic_write_text(out.with_suffix(".md"), markdown)
    try:
        plot(report, out.with_suffix(".png"))
    except ImportError as err:
        print(f"no figure: {err}", file=sys.stderr)


def _path_view(traj: Trajectory, cfg: ScenarioConfig) -> dict[str, Any]:
    """What the panels show: errors, θ and labels, in path coordinates on a curved path."""
    s = traj.state
    offsets = cfg.formation
    if cfg.straight:
        return {
            "e": s[..., 1] - offsets[:, 1],
            "heading": np.degrees(wrap_angle(s[..., 2])),
            "theta": s[..., 0] - offsets[:, 0],
            "lane_speed": None,
            "e_label": "y_j − D_yj [m]",
            "heading_label": "ψ_j [deg]",
            "heading_title": "(c) headings",
            "theta_label": "x",
        }
    c = path_coordinates_along(traj, cfg)
    errors = goal_errors(traj, cfg)  # the course as the metrics take it (over ground with a current)
    return {
        "e": errors["cross_track"],
        "heading": errors["heading_deg"],
        "theta": c.ell - offsets[:, 0],
        "ell": c.ell,
        "lane_speed": (1.0 - c.kappa * offsets[:, 1]) * traj.u_d[:, None],
        "e_label": "e_j [m]",
        "heading_label": "χ_j − γ(ℓ_j) [deg]",
        "heading_title": "(c) course over ground relative to the path",
        "theta_label": "ℓ",
    }


def _draw_lanes(ax: Any, cfg: ScenarioConfig, ell: np.ndarray | None, lw: float = 0.8) -> None:
    """The desired paths: lines y = D_yj, or the path (grey) and its lanes along the stretch ``ell`` covers.

    ``ell``: the vessels' projections followed through the run (None on the straight path).
    """
    offsets = cfg.formation
    if ell is None:
        for j in range(cfg.n_vessels):
            ax.axhline(offsets[j, 1], color=vessel_color(j), ls="--", lw=lw, alpha=0.6)
        return
    lo, hi = float(np.min(ell)) - 100.0, float(np.max(ell)) + 100.0
    route = cfg.path.points(lo, hi)
    ax.plot(route[:, 0], route[:, 1], color="0.55", lw=lw, ls="-", alpha=0.8, label="path")
    for j in range(cfg.n_vessels):
        lane = cfg.path.points(lo, hi, offset=float(offsets[j, 1]))
        ax.plot(lane[:, 0], lane[:, 1], color=vessel_color(j), ls="--", lw=lw, alpha=0.6)
    ax.set_aspect("equal", adjustable="datalim")


def plot_episode(traj: Trajectory, cfg: ScenarioConfig, path: str | Path | None = None, title: str = "") -> Any:
    """Draw the Fig. 6 panels for ``traj`` and save to ``path`` (PNG/PDF/SVG) if given.

    Returns:
        The matplotlib Figure.
    """
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t, s = traj.t, traj.state
    n = cfg.n_vessels
    fig = Figure(figsize=(12.0, 11.0), dpi=110)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(3, 2, height_ratios=[1.1, 1.0, 1.0])
    ax_path = fig.add_subplot(grid[0, :])
    ax_ct = fig.add_subplot(grid[1, 0])
    ax_psi = fig.add_subplot(grid[1, 1], sharex=ax_ct)
    ax_coord = fig.add_subplot(grid[2, 0], sharex=ax_ct)
    ax_u = fig.add_subplot(grid[2, 1], sharex=ax_ct)

    view = _path_view(traj, cfg)
    # (a) paths in the plane
    _draw_lanes(ax_path, cfg, view.get("ell"))
    for j in range(n):
        color = vessel_color(j)
        ax_path.plot(s[:, j, 0], s[:, j, 1], color=color, lw=1.2, label=f"vessel_{j}")
        for k in _snapshot_indices(t):
            ax_path.plot(
                s[k, j, 0],
                s[k, j, 1],
                ls="none",
                color=color,
                mec="k",
                mew=0.5,
                ms=9,
                marker=(3, 0, np.degrees(s[k, j, 2]) - 90.0),
            )
    for k in _snapshot_indices(t):
        ax_path.annotate(
            f"{t[k]:.0f} s",
            (float(np.mean(s[k, :, 0])), float(np.max(s[k, :, 1]))),
            xytext=(0, 10),
            textcoords="offset points",
            ha="center",
            fontsize=7,
            color="0.3",
        )
    ax_path.set_xlabel("x [m]")
    ax_path.set_ylabel("y [m]")
    ax_path.set_title("(a) paths; markers show the vessels (pointing along ψ) at the labelled times", fontsize=9)
    ax_path.legend(loc="center right", bbox_to_anchor=(1.0, 0.72), fontsize=8, ncol=min(n, 4))

    # (b) cross-track errors, (c) heading
    for j in range(n):
        ax_ct.plot(t, view["e"][:, j], color=vessel_color(j), lw=1.2)
        ax_psi.plot(t, view["heading"][:, j], color=vessel_color(j), lw=1.2)
    ax_ct.set_ylabel(view["e_label"])
    ax_ct.set_title("(b) cross-track errors", fontsize=9)
    ax_psi.set_ylabel(view["heading_label"])
    ax_psi.set_title(view["heading_title"], fontsize=9)

    # (d) coordination errors
    theta, q = view["theta"], view["theta_label"]
    if n <= 4:
        for j in range(n):
            for k in range(j + 1, n):
                ax_coord.plot(t, theta[:, j] - theta[:, k], lw=1.2, label=f"{j}−{k}")
        ax_coord.set_ylabel(f"({q}_j − D_xj) − ({q}_k − D_xk) [m]")
        ax_coord.legend(fontsize=7, title="j−k", title_fontsize=7)
    else:
        for j in range(n):
            ax_coord.plot(t, theta[:, j] - theta.mean(axis=1), color=vessel_color(j), lw=1.0)
        ax_coord.set_ylabel(f"({q}_j − D_xj) − mean_k [m]")
    ax_coord.set_title("(d) along-track coordination errors", fontsize=9)
    ax_coord.set_xlabel("t [s]")

    # (e) speeds
    for j in range(n):
        ax_u.plot(t, s[:, j, 3], color=vessel_color(j), lw=1.2)
        if np.any(np.isfinite(traj.commanded_speed[:, j])):
            ax_u.step(t[:-1], traj.commanded_speed[:, j], where="post", color=vessel_color(j), lw=0.8, ls=":")
        if view["lane_speed"] is not None:
            ax_u.plot(t, view["lane_speed"][:, j], color=vessel_color(j), lw=0.6, ls="--", alpha=0.7)
    ax_u.plot(t, traj.u_d, color="k", lw=0.8, ls="--", label="u_d")
    for bound in (cfg.u_min, cfg.u_max):
        ax_u.axhline(bound, color="0.5", lw=0.8, ls="-.")
    ax_u.set_ylabel("u_j (solid), u_cj (dotted) [m/s]")
    ax_u.set_title(f"(e) surge and commanded speeds; band (U_min, U_max) = ({cfg.u_min:g}, {cfg.u_max:g})", fontsize=9)
    ax_u.set_xlabel("t [s]")
    ax_u.legend(fontsize=7, loc="upper right")

    for ax in (ax_ct, ax_psi, ax_coord):
        ax.axhline(0.0, color="k", lw=0.5, alpha=0.5)
    for ax in (ax_path, ax_ct, ax_psi, ax_coord, ax_u):
        ax.grid(alpha=0.3)
    return _finish(fig, cfg, path, title)


def plot_comparison(
    trajectories: dict[str, Trajectory], cfg: ScenarioConfig, path: str | Path | None = None, title: str = ""
) -> Any:
    """Policies side by side (one column each, shared y-axes per row) on the same episode.

    Rows: paths in the plane, cross-track errors, along-track coordination
    errors relative to the formation mean, surge and commanded speeds.
    """
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    labels = list(trajectories)
    cols = len(labels)
    fig = Figure(figsize=(4.6 * cols, 11.0), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(4, cols, squeeze=False, sharey="row")
    for c, label in enumerate(labels):
        traj = trajectories[label]
        t, s = traj.t, traj.state
        view = _path_view(traj, cfg)
        theta = view["theta"]
        _draw_lanes(axes[0, c], cfg, view.get("ell"), lw=0.7)
        for j in range(cfg.n_vessels):
            color = vessel_color(j)
            axes[0, c].plot(s[:, j, 0], s[:, j, 1], color=color, lw=1.1)
            axes[1, c].plot(t, view["e"][:, j], color=color, lw=1.1)
            axes[2, c].plot(t, theta[:, j] - theta.mean(axis=1), color=color, lw=1.1)
            axes[3, c].plot(t, s[:, j, 3], color=color, lw=1.1)
            if np.any(np.isfinite(traj.commanded_speed[:, j])):
                axes[3, c].step(t[:-1], traj.commanded_speed[:, j], where="post", color=color, lw=0.7, ls=":")
        axes[3, c].plot(t, traj.u_d, color="k", ls="--", lw=0.8)
        for bound in (cfg.u_min, cfg.u_max):
            axes[3, c].axhline(bound, color="0.5", lw=0.8, ls="-.")
        name = Path(label).parent.name + "/" + Path(label).name if label.endswith(".zip") else label
        end = "terminated" if traj.terminated else f"return {traj.rewards.sum(axis=0).mean():.1f}"
        axes[0, c].set_title(f"{name}\n({end})", fontsize=9)
        axes[3, c].set_xlabel("t [s]")
        axes[0, c].set_xlabel("x [m]")
        for r in range(4):
            axes[r, c].grid(alpha=0.3)
    axes[0, 0].set_ylabel("y [m]")
    axes[1, 0].set_ylabel("y_j − D_yj [m]" if cfg.straight else "e_j [m]")
    axes[2, 0].set_ylabel("θ_j − mean θ [m]")
    axes[3, 0].set_ylabel("u_j, u_cj (dotted) [m/s]")
    return _finish(fig, cfg, path, title)
