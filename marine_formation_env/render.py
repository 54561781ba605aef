"""Rendering with matplotlib (imported lazily; ``pip install marine-formation-env[plot]``).

A fixed world camera shows the scenario's workspace box (on a curved path:
the whole route, docs/paths.md) with:

* the desired paths ``y = D_yj`` (dashed); on a curved path, the path (grey)
  and the lanes ``P(ℓ) + D_yj·n(ℓ)`` (dashed),
* the formation slots ``(x̄ + D_xj, D_yj)`` around the current mean along-track
  position ``x̄ = mean_k(x_k − D_xk)`` (hollow circles); on a curved path the
  slots ``P(θ̄ + D_xj) + D_yj·n`` around ``θ̄ = mean_k(ℓ_k − D_xk)``,
* each vessel as an oriented hull polygon at true scale,
* every communication link as an arrow from transmitter to receiver; over a
  non-ideal channel, links that exist in the graph but are down right now
  (out of range, failed, switched off) are drawn dotted and pale,
* the ocean current, if any, in the title.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from marine_formation_env.errors import check_number
from marine_formation_env.paths import path_coordinates
from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["VESSEL_COLORS", "FormationRenderer", "even_frame", "hull_polygon", "render_fps", "require_matplotlib"]

VESSEL_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


def check_render_mode(render_mode: str | None, modes: Sequence[str]) -> None:
    """Raise ValueError for a render mode outside ``modes`` (None means no rendering)."""
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"unknown render_mode {render_mode!r}; choose one of {list(modes)}")


def render_fps(dt: float, speedup: float = 1.0) -> float:
    """Frames per second that play an episode in real time, one frame per control period
    ``dt`` [s], or ``speedup`` times faster (``render_speedup`` of the front ends).

    Raises:
        ConfigError: ``speedup`` is not a finite number > 0.
    """
    check_number("env", "render_speedup", speedup, strict=True)
    return float(speedup) / dt


def even_frame(image: np.ndarray) -> np.ndarray:
    """``image`` without its last row or column where the height or width is odd.

    Video encoders subsample colour in 2×2 blocks (yuv420p, the format browsers
    play); an odd frame size makes them fall back to yuv444p.
    """
    height, width = image.shape[0], image.shape[1]
    return image[: height - height % 2, : width - width % 2]


def require_matplotlib() -> Any:
    """Import matplotlib or fail with the install hint."""
    try:
        import matplotlib
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError("rendering and plotting need matplotlib: pip install 'marine-formation-env[plot]'") from err
    return matplotlib


def hull_polygon(x: float, y: float, psi: float, length: float, beam: float) -> np.ndarray:
    """Corners ``(7, 2)`` [m] of a hull outline with a pointed bow, centred at (x, y), heading ψ."""
    half_l, half_b = 0.5 * length, 0.5 * beam
    body = np.array(
        [
            [half_l, 0.0],
            [0.55 * half_l, half_b],
            [-half_l, half_b],
            [-half_l, -half_b],
            [0.55 * half_l, -half_b],
            [half_l, 0.0],
        ]
    )
    c, s = np.cos(psi), np.sin(psi)
    return body @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def route_span(config: ScenarioConfig) -> tuple[float, float]:
    """The stretch ``(ℓ_from, ℓ_to)`` [m] of a curved path the camera shows: from behind the start to past the end.

    A path without an end (a circle) is shown over one lap.
    """
    start = config.path.closest(config.start_state[:, 0], config.start_state[:, 1])
    lo = float(np.min(start)) - 100.0
    length = config.path.length
    if not np.isfinite(length):
        return lo, lo + 2.0 * np.pi * config.path.min_radius
    return lo, max(length, float(np.max(start))) + 200.0


def route_box(config: ScenarioConfig) -> tuple[float, float, float, float]:
    """``(x_min, x_max, y_min, y_max)`` [m]: the route of ``route_span`` with its lanes and a margin."""
    lo, hi = route_span(config)
    points = config.path.points(lo, hi)
    margin = float(np.max(np.abs(config.formation[:, 1]))) + 100.0
    return (
        float(points[:, 0].min()) - margin,
        float(points[:, 0].max()) + margin,
        float(points[:, 1].min()) - margin,
        float(points[:, 1].max()) + margin,
    )


def vessel_color(j: int) -> str:
    """A stable color per vessel index."""
    return VESSEL_COLORS[j % len(VESSEL_COLORS)]


class FormationRenderer:
    """Draws frames of one formation; ``draw`` returns an RGB array (or updates a window).

    Top panel: the fixed world camera over the workspace, with the paths
    travelled so far. Bottom panel: a close-up that follows the formation's
    centroid (``zoom_width`` metres wide) so hulls, slots and link arrows stay
    legible when the workspace is kilometres long.

    The figure and its artists are made once; a frame moves them (hulls,
    slots, trails, arrows, titles, the close-up's limits) and redraws, which
    is what keeps recording an evaluation video cheap.
    """

    def __init__(
        self, config: ScenarioConfig, human: bool = False, width_px: int = 1280, zoom_width: float = 500.0
    ) -> None:
        require_matplotlib()
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.config = config
        self.human = human
        self.zoom_width = float(zoom_width)
        self._trail: list[np.ndarray] = []
        self._arc: np.ndarray | None = None  # the vessels' projections on a curved path, followed frame to frame
        x_lo, x_hi, y_lo, y_hi = config.workspace if config.straight else route_box(config)
        width_in = width_px / 100.0
        world_h = float(np.clip(width_in * (y_hi - y_lo) / (x_hi - x_lo), 1.6, 0.5 * width_in))
        zoom_h = 0.3 * width_in
        height_in = world_h + zoom_h + 1.2
        self._plt: Any = None
        if human:
            import matplotlib.pyplot as plt

            plt.ion()
            self._plt = plt
            self.fig = plt.figure(figsize=(width_in, height_in))
        else:
            self.fig = Figure(figsize=(width_in, height_in), dpi=100)
            FigureCanvasAgg(self.fig)
        grid = self.fig.add_gridspec(2, 1, height_ratios=[world_h, zoom_h])
        self.ax_world = self.fig.add_subplot(grid[0])
        self.ax_zoom = self.fig.add_subplot(grid[1])
        self._world = self._make_scene(self.ax_world, link_arrows=False, trail_alpha=1.0)
        self._zoom = self._make_scene(self.ax_zoom, link_arrows=True, trail_alpha=0.6)
        ax = self.ax_world
        ax.set_xlim(x_lo, x_hi)
        ax.set_ylim(y_lo, y_hi)
        ax.set_aspect("equal", adjustable="box")
        ax.set_ylabel("y [m]")
        self._title = ax.set_title(" ", fontsize=9)
        ax = self.ax_zoom
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title("close-up: hulls to scale, formation slots (circles), links i → j (arrows)", fontsize=8)
        if config.straight:
            self._place_zoom(np.column_stack([config.formation, np.zeros((config.n_vessels, 4))]))
        else:
            self._place_zoom(None, config.start_state[:, :2])
        self.fig.tight_layout()  # once: the layout does not change from frame to frame
        # what moves is drawn over a cached background (blitting): the world panel's moving artists
        # and title, and the whole close-up (its limits, hence its ticks, change every frame)
        self._moving = [a for group in self._world.values() for a in group] + [self._title]
        for artist in self._moving:
            artist.set_animated(True)
        self._background: Any = None

    def _make_scene(self, ax: Any, link_arrows: bool, trail_alpha: float) -> dict[str, list[Any]]:
        """The artists of one panel at a neutral pose: paths, slots, hulls, trails (and arrows, labels)."""
        from matplotlib.patches import Circle, FancyArrowPatch, Polygon

        cfg = self.config
        length = cfg.params.length or 40.0
        scene: dict[str, list[Any]] = {"slots": [], "hulls": [], "trails": [], "arrows": [], "labels": []}
        if not cfg.straight:
            lo, hi = route_span(cfg)
            route = cfg.path.points(lo, hi)
            ax.plot(route[:, 0], route[:, 1], color="0.6", lw=0.8)
        for j, (d_x, d_y) in enumerate(cfg.formation):
            color = vessel_color(j)
            if cfg.straight:
                ax.axhline(d_y, color=color, lw=0.8, ls="--", alpha=0.5)
            else:
                lane = cfg.path.points(lo, hi, offset=float(d_y))
                ax.plot(lane[:, 0], lane[:, 1], color=color, lw=0.8, ls="--", alpha=0.5)
            scene["slots"].append(ax.add_patch(Circle((d_x, d_y), 0.4 * length, fill=False, ec=color, lw=1.0)))
            (trail,) = ax.plot([], [], color=color, lw=0.8, alpha=trail_alpha)
            scene["trails"].append(trail)
        if link_arrows:
            for _ in cfg.graph.links:
                arrow = FancyArrowPatch(
                    (0.0, 0.0),
                    (1.0, 0.0),
                    arrowstyle="-|>",
                    mutation_scale=12,
                    lw=1.0,
                    shrinkA=10,
                    shrinkB=10,
                    connectionstyle="arc3,rad=0.15",
                )
                scene["arrows"].append(ax.add_patch(arrow))
        for j in range(cfg.n_vessels):
            hull = Polygon(np.zeros((6, 2)), closed=True, fc=vessel_color(j), ec="k", lw=0.6)
            scene["hulls"].append(ax.add_patch(hull))
            if link_arrows:
                scene["labels"].append(
                    ax.annotate(
                        f"vessel_{j}", (0.0, 0.0), xytext=(0, 9), textcoords="offset points", ha="center", fontsize=8
                    )
                )
        return scene

    def draw(
        self, state: np.ndarray, time: float, links: np.ndarray | None = None, arc: np.ndarray | None = None
    ) -> np.ndarray | None:
        """Draw ``state`` ``(n, 6)`` at ``time`` [s]; return ``(H, W, 3)`` uint8 unless human.

        ``links``: ``(n, n)`` booleans, ``links[j, i]`` iff the link i → j is up
        now (``links_up``); None:
        every link of the graph. ``arc``: ``(n,)`` the vessels' projections on a
        curved path (``arc``); None:
        found by a global search at the first frame and followed from frame to
        frame (then render every few control periods, or the projection may
        jump between a route's legs).
        """
        cfg = self.config
        if time == 0.0 or not self._trail:
            self._trail = []
        self._trail.append(np.array(state[:, :2]))
        trail = np.stack(self._trail)  # (T, n, 2)
        offsets = cfg.formation
        if cfg.straight:
            theta, cross_track, slots = state[:, 0] - offsets[:, 0], state[:, 1] - offsets[:, 1], None
        else:
            if arc is not None:
                guess = np.asarray(arc, dtype=float)
            elif time == 0.0 or self._arc is None:
                guess = cfg.path.closest(state[:, 0], state[:, 1])
            else:
                guess = self._arc
            c = path_coordinates(cfg.path, state[:, 0], state[:, 1], state[:, 2], state[:, 3], state[:, 4], guess)
            self._arc = c.ell
            theta, cross_track = c.ell - offsets[:, 0], c.offset - offsets[:, 1]
            sx, sy, _ = cfg.path.lane_point(float(np.mean(theta)) + offsets[:, 0], offsets[:, 1])
            slots = np.column_stack([sx, sy])
        spread = float(np.ptp(theta))
        cross = float(np.max(np.abs(cross_track)))
        for scene in (self._world, self._zoom):
            self._move_scene(scene, state, trail, links, slots)
        sea = ""
        if not cfg.current.is_zero:
            vc_x, vc_y = cfg.current.velocity(time)
            sea = f"   current {float(np.hypot(vc_x, vc_y)):.2f} m/s towards {np.degrees(cfg.current.direction):.0f}°"
        self._title.set_text(
            f"{cfg.name} ({cfg.action_level})   t = {time:6.1f} s   coordination spread {spread:8.2f} m   "
            f"max |{'y − D_y' if cfg.straight else 'e'}| {cross:7.2f} m{sea}"
        )
        if cfg.straight:
            self._place_zoom(state)
        else:
            self._place_zoom(None, state[:, :2])
        canvas = self.fig.canvas
        if self._background is None:
            self.ax_zoom.set_visible(False)
            canvas.draw()
            self._background = canvas.copy_from_bbox(self.fig.bbox)  # type: ignore[attr-defined]
            self.ax_zoom.set_visible(True)
        canvas.restore_region(self._background)  # type: ignore[attr-defined]
        for artist in self._moving:
            self.fig.draw_artist(artist)
        self.fig.draw_artist(self.ax_zoom)
        if self.human:
            canvas.blit(self.fig.bbox)
            canvas.flush_events()
            self._plt.pause(1.0 / 30.0)
            return None
        rgba = np.asarray(canvas.buffer_rgba())  # type: ignore[attr-defined]
        return np.array(even_frame(rgba)[..., :3])

    def _move_scene(
        self,
        scene: dict[str, list[Any]],
        state: np.ndarray,
        trail: np.ndarray,
        links: np.ndarray | None,
        slots: np.ndarray | None = None,
    ) -> None:
        """Move one panel's artists to ``state``; ``slots`` ``(n, 2)``: the slots' positions (None: straight path)."""
        cfg = self.config
        offsets = cfg.formation
        length = cfg.params.length or 40.0
        beam = cfg.params.beam or 0.25 * length
        x_bar = float(np.mean(state[:, 0] - offsets[:, 0]))
        for j, (x, y, psi, *_rest) in enumerate(state):
            centre = (x_bar + offsets[j, 0], offsets[j, 1]) if slots is None else (slots[j, 0], slots[j, 1])
            scene["slots"][j].set_center(centre)
            scene["hulls"][j].set_xy(hull_polygon(x, y, psi, length, beam))
            scene["trails"][j].set_data(trail[:, j, 0], trail[:, j, 1])
            if scene["labels"]:
                scene["labels"][j].xy = (float(x), float(y))
        for arrow, (i, j) in zip(scene["arrows"], cfg.graph.links, strict=False):  # i transmits to j
            live = links is None or bool(links[j, i])
            arrow.set_positions((float(state[i, 0]), float(state[i, 1])), (float(state[j, 0]), float(state[j, 1])))
            arrow.set_color("0.3" if live else "0.75")
            arrow.set_linestyle("-" if live else ":")

    def _place_zoom(self, state: np.ndarray | None, positions: np.ndarray | None = None) -> None:
        """The close-up's window: centred on the formation, wide enough for every vessel and slot.

        On a curved path ``state`` is None and ``positions`` ``(n, 2)`` are the
        vessels' positions: the window is centred on them, whatever their heading.
        """
        offsets = self.config.formation
        ratio = 0.3  # height / width of the close-up window
        if state is None:
            points = np.asarray(positions)
            cx, cy = float(np.mean(points[:, 0])), float(np.mean(points[:, 1]))
            reach = float(np.max(np.hypot(points[:, 0] - cx, points[:, 1] - cy))) + 0.5 * float(np.ptp(offsets[:, 0]))
            half_w = max(0.5 * self.zoom_width, 1.2 * reach + 50.0, (1.2 * reach + 40.0) / ratio)
            self.ax_zoom.set_xlim(cx - half_w, cx + half_w)
            self.ax_zoom.set_ylim(cy - ratio * half_w, cy + ratio * half_w)
            return
        cx, cy = float(np.mean(state[:, 0])), float(np.mean(offsets[:, 1]))
        half_w = max(
            0.5 * self.zoom_width,
            0.6 * float(np.ptp(state[:, 0])) + 50.0,
            (0.6 * float(np.ptp(np.append(state[:, 1], offsets[:, 1]))) + 40.0) / ratio,
        )
        self.ax_zoom.set_xlim(cx - half_w, cx + half_w)
        self.ax_zoom.set_ylim(cy - ratio * half_w, cy + ratio * half_w)

    def close(self) -> None:
        if self._plt is not None:
            self._plt.close(self.fig)
