"""Rendering: rgb_array frames, the no-render_mode warning, bad render modes."""

from __future__ import annotations

import numpy as np
import pytest

import marine_formation_env

pytest.importorskip("matplotlib")


def _frame_ok(frame) -> np.ndarray:
    assert isinstance(frame, np.ndarray)
    assert frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] > 50 and frame.shape[1] > 50
    assert frame.dtype == np.uint8
    assert frame.astype(float).var() > 0.0  # not blank
    return frame


def test_rgb_array_frames_change_with_time():
    env = marine_formation_env.parallel_env("paper", render_mode="rgb_array", horizon=20.0)
    env.reset(seed=0)
    first = _frame_ok(env.render())
    for _ in range(10):
        env.step({a: np.ones(1, np.float32) for a in env.agents})
    second = _frame_ok(env.render())
    assert second.shape == first.shape
    assert not np.array_equal(first, second)
    env.close()


def test_rgb_array_frame_depends_on_vessel_state():
    # Same time (t = 0), different vessel positions: the difference must come
    # from the drawing of the vessels, not from the time in the title.
    env = marine_formation_env.parallel_env("paper", render_mode="rgb_array", horizon=20.0)
    x0 = np.array(
        [
            [-50.0, 20.0, 0.0, 3.0, 0.0, 0.0],
            [-60.0, 30.0, 0.3, 3.0, 0.0, 0.0],
            [-120.0, -10.0, -0.2, 3.0, 0.0, 0.0],
        ]
    )
    env.reset(options={"initial_state": x0})
    a = _frame_ok(env.render())
    env.reset(options={"initial_state": x0})
    a_again = _frame_ok(env.render())
    moved = x0.copy()
    moved[0, :3] = [-20.0, 60.0, 0.8]
    env.reset(options={"initial_state": moved})
    b = _frame_ok(env.render())
    assert np.array_equal(a, a_again)  # rendering is a function of the state
    assert not np.array_equal(a, b)
    env.close()


def test_render_without_mode_warns_and_returns_none():
    env = marine_formation_env.parallel_env("paper")
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_unknown_render_mode_raises():
    with pytest.raises(ValueError, match="'ansi'"):
        marine_formation_env.parallel_env("paper", render_mode="ansi")


def test_links_that_are_down_are_drawn_differently():
    """A range limit cuts the 0–2 link of a column (200 m apart); the frame differs from all links up."""
    frames = []
    for channel in ({"range": 1e9}, {"range": 150.0}):
        env = marine_formation_env.parallel_env(
            "paper", render_mode="rgb_array", formation="column", topology="complete", initial_state=None,
            channel=channel,
        )  # fmt: skip
        env.reset(seed=0)
        up = env.core.links_up(0)
        frames.append(_frame_ok(env.render()))
    assert not up[2, 0] and not up[0, 2] and up[1, 0] and up[2, 1]
    assert not np.array_equal(frames[0], frames[1])


FRONTS = {
    "parallel_env": lambda **kw: marine_formation_env.parallel_env(**kw),
    "gymnasium.make": lambda **kw: __import__("gymnasium").make("MarineFormation-v1", **kw).unwrapped,
    "make_vec": lambda **kw: __import__("gymnasium").make_vec(
        "MarineFormation-v1", num_envs=2, vectorization_mode="vector_entry_point", **kw
    ),
}


@pytest.mark.parametrize("front", list(FRONTS))
@pytest.mark.parametrize(("level", "dt"), [("force", 0.1), ("speed", 0.5), ("guidance", 0.5)])
def test_render_fps_plays_the_episode_in_real_time(front, level, dt):
    """One frame per control period: a video of a 400 s episode lasts 400 s (``render_speedup`` shortens it)."""
    env = FRONTS[front](action_level=level)
    assert env.metadata["render_fps"] == pytest.approx(1.0 / dt)
    fast = FRONTS[front](action_level=level, render_speedup=8)
    assert fast.metadata["render_fps"] == pytest.approx(8.0 / dt)
    assert env.max_steps == round(400.0 / dt)  # the public episode length, as wrappers read it
    with pytest.raises(ValueError, match=r"render_speedup must be .*got 0"):
        FRONTS[front](action_level=level, render_speedup=0)


@pytest.mark.parametrize(
    "workspace", [None, (-300.0, 2300.0, -501.5, 501.5), (-300.0, 2300.0, -505.5, 505.5)], ids=["paper", "a", "b"]
)
def test_frames_have_even_height_and_width(workspace):
    """Video encoders need even frame sizes for yuv420p (which browsers play); the workspace sets the height."""
    kw = {} if workspace is None else {"workspace": workspace}
    env = marine_formation_env.parallel_env("paper", render_mode="rgb_array", **kw)
    env.reset(seed=0)
    frame = _frame_ok(env.render("rgb_array"))  # a mode argument is accepted (RLlib passes one)
    assert frame.shape[0] % 2 == 0 and frame.shape[1] % 2 == 0, frame.shape
    canvas = env._rendering._renderer.fig.canvas.get_width_height()  # (W, H) as matplotlib drew it
    assert abs(frame.shape[0] - canvas[1]) <= 1 and frame.shape[1] == canvas[0]  # at most one row cropped
    env.close()


@pytest.mark.parametrize("scenario", ["survey", "circle"])
def test_camera_frames_the_whole_route_and_draws_the_lanes(scenario):
    """On a curved path the world panel shows every point of the route's lanes (docs/paths.md)."""
    pytest.importorskip("matplotlib")
    from marine_formation_env.render import FormationRenderer, route_span

    cfg = marine_formation_env.make_config(scenario)
    renderer = FormationRenderer(cfg, width_px=640)
    frame = renderer.draw(cfg.start_state, 0.0)
    assert frame is not None and frame.shape[0] % 2 == 0 and frame.shape[1] % 2 == 0
    x_lo, x_hi = renderer.ax_world.get_xlim()
    y_lo, y_hi = renderer.ax_world.get_ylim()
    lo, hi = route_span(cfg)
    for d_y in cfg.formation[:, 1]:
        lane = cfg.path.points(lo, hi, offset=float(d_y))
        assert np.all((lane[:, 0] >= x_lo) & (lane[:, 0] <= x_hi) & (lane[:, 1] >= y_lo) & (lane[:, 1] <= y_hi))
    # the lanes are drawn as lines in the world panel (the path plus one per vessel)
    assert len(renderer.ax_world.lines) >= 1 + cfg.n_vessels
    if np.isfinite(cfg.path.length):  # a route: the camera shows its end too
        end_x, end_y, _, _ = cfg.path.frame(cfg.path.length)
        assert x_lo <= end_x <= x_hi and y_lo <= end_y <= y_hi
    renderer.close()
