"""The numba backend against the numpy reference implementation, and backend selection.

The numpy path of ``FormationCore`` is the reference; the compiled kernel must
reproduce it. The kernel evaluates the same expressions in the same order, but
not with the same transcendental functions: numpy's vectorized ``arctan``,
``sin`` and ``cos`` (SIMD loops, which differ between CPUs: AVX-512 machines use
other kernels) and libm's scalar ``atan``/``sin``/``cos`` that numba calls may
disagree in the last bit. So the two backends are compared with tolerances
that say what such a last-bit difference can grow to, not bit for bit:

* states: 1e-12 relative to ``max(|value|, 1)`` (metres, m/s, rad). A
  last-bit difference is ~1e-16 relative; the closed loop is contracting, so
  over 120 control periods it grew to at most 5e-15 on the machines measured,
  and 1e-12 leaves a factor 200 of headroom while still catching any real
  difference of a model or controller term (those are ≥ 1e-8 after one step).
* observations (float32): within 4 float32 ulps (rounding a float64 that
  differs in the last bits can land on the neighbouring float32), and the
  link bits exactly: the structure of what a vessel sees must not differ.
* rewards and their components: 1e-12 absolute (a step's reward is at most
  ``dt·Σw`` ≈ 1.4 in magnitude).
* termination, truncation and the flags: exactly.

Seeded determinism within one backend stays bit-exact (tests/test_env.py,
tests/test_vector.py, tests/test_channel.py).
"""

from __future__ import annotations

import numpy as np
import pytest

import marine_formation_env
from baselines import ReferencePolicy
from marine_formation_env import RewardConfig, SpeedProfile
from marine_formation_env.backends import resolve_backend
from marine_formation_env.core import FormationCore
from marine_formation_env.observations import ObservationLayout
from marine_formation_env.scenarios import make_config, sample_initial_state

pytest.importorskip("numba")

pytestmark = pytest.mark.backend_independent  # it builds each backend itself

CASES = {
    "paper": {},
    "ring4-noise": {"n_vessels": 4, "topology": "ring"},
    "varying-ud-effort": {
        "u_d": SpeedProfile(mean=5.0, amplitude=0.6, period=40.0),
        "reward": RewardConfig(
            effort=0.4, fine_share=0.3, fine_scale=0.1, fine_terms=("cross_track", "coordination", "speed")
        ),
    },
    "as-printed": {"paper_as_printed": True},
    "random6-episode-ends": {"n_vessels": 6, "topology": "random", "safety_distance": 25.0, "horizon": 20.0},
    "cross-current-ilos": {"current": {"speed": 0.6, "direction": 2.0}, "los_integral_gain": 1.0},
    "acoustic-channel-noise": {
        "channel": {"burst": {"p_good_to_bad": 0.2}, "latency": 0.9, "jitter": 0.7, "tdma_slot": 1.0},
        "sensor_noise": {"position": 0.5, "heading": 0.01},
    },
    # every feature of the channel (the compiled one against LinkChannel): Bernoulli loss per link,
    # transmission period, range limit (100 m and 200 m apart), failures and recovery, switching graphs
    "loss-matrix-period-range-failures": {
        "channel": {
            "loss": [[0.0, 0.3, 0.1], [0.5, 0.0, 0.2], [0.0, 0.9, 0.0]],
            "period": 1.0,
            "range": 150.0,
            "failure_rate": 0.2,
            "recovery_rate": 0.5,
            "latency": 1.0,
        },
        "topology_schedule": [(2.0, "paper"), (1.0, "complete")],
    },
    "jitter-noise-current": {
        "channel": {"loss": 0.2, "jitter": 2.5},
        "sensor_noise": {"speed": 0.1, "yaw_rate": 0.01},
        "current": {"speed": 0.5, "direction": 1.0, "amplitude": 0.2, "period": 60.0},
    },
    "acoustic-preset": {"scenario": "acoustic"},
    # curved paths (docs/paths.md): the projection followed in the kernel, the loops in path coordinates,
    # the corridor, the channel transmitting (ℓ, ℓ̇) over ground of noisy measurements
    "circle": {"scenario": "circle"},
    "survey-ends": {"scenario": "survey", "horizon": 20.0, "corridor": 45.0},
    "survey-acoustic-noise-current-ilos": {
        "scenario": "survey_acoustic",
        "sensor_noise": {"position": 0.5, "heading": 0.01, "speed": 0.05},
        "current": {"speed": 0.4, "direction": 1.0},
        "los_integral_gain": 1.0,
    },
    "waypoints-right-turns": {
        "scenario": "paper",
        "path": {"kind": "waypoints", "waypoints": [[0, 0], [150, 0], [500, -400], [900, -400]], "turn_radius": 320.0},
    },
    "radio-preset": {"scenario": "radio", "n_vessels": 5, "topology": "ring", "safety_distance": 30.0},
}


STATE_RTOL = 1e-12  # relative to max(|value|, 1); see the module docstring
REWARD_ATOL = 1e-12
OBS_ULPS = 4


def assert_states_close(fast: np.ndarray, ref: np.ndarray) -> None:
    scale = np.maximum(np.abs(ref), 1.0)
    worst = np.max(np.abs(fast - ref) / scale)
    assert worst <= STATE_RTOL, f"states differ by {worst:.3g} (relative to max(|x|, 1)), more than {STATE_RTOL}"


def assert_observations_close(fast: np.ndarray, ref: np.ndarray, n: int) -> None:
    assert fast.dtype == ref.dtype == np.float32 and fast.shape == ref.shape
    own = ObservationLayout(n).own
    links = ref[..., own::4]
    assert np.array_equal(fast[..., own::4], links), "link bits differ"
    assert set(np.unique(links)) <= {0.0, 1.0}
    ulp = np.spacing(np.maximum(np.abs(ref), np.abs(fast)))
    assert np.all(np.abs(fast - ref) <= OBS_ULPS * ulp), np.max(np.abs(fast - ref) / ulp)


@pytest.mark.parametrize("level", ["force", "guidance", "speed"])
@pytest.mark.parametrize("case", list(CASES))
def test_numba_core_matches_numpy(level: str, case: str) -> None:
    overrides = dict(CASES[case])
    if level != "speed":
        overrides.pop("los_integral_gain", None)  # a speed-level option
    cfg = make_config(overrides.pop("scenario", "paper"), action_level=level, **overrides)
    compare_backends(cfg, b=5, steps=120, check_ends=case in ("random6-episode-ends", "survey-ends"))


def test_numba_channel_matches_numpy_with_threads_and_autoreset() -> None:
    """Enough formations for the multi-threaded kernels, episodes that end every few steps."""
    from marine_formation_env._numba import PARALLEL_FROM

    cfg = make_config("acoustic", action_level="force", horizon=3.0, sensor_noise={"position": 1.0})
    compare_backends(cfg, b=PARALLEL_FROM, steps=70, check_ends=True)
    curved = make_config("survey_acoustic", action_level="speed", horizon=6.0, sensor_noise={"position": 1.0})
    compare_backends(curved, b=PARALLEL_FROM, steps=40, check_ends=True)


def compare_backends(cfg, b: int, steps: int, check_ends: bool) -> None:
    """Step both backends with the same random actions; formations that end start anew, on odd
    episode ends through ``step(restart=…)`` (the vector env's autoreset), on even ones through ``reset``."""
    fast, ref = FormationCore(cfg, b, backend="numba"), FormationCore(cfg, b, backend="numpy")
    rng = np.random.default_rng(7)
    x0 = np.stack([sample_initial_state(cfg, rng) for _ in range(b)])
    for core in (fast, ref):
        core.seed_channel(list(range(b)))  # the same channel luck on both
        core.reset(x0)
    ended = events = 0
    restart, initial = None, None
    for _ in range(steps):
        actions = rng.uniform(-1.3, 1.3, (b, cfg.n_vessels, cfg.action_dim))  # out-of-range values are clipped
        a, r = fast.step(actions, restart, initial), ref.step(actions, restart, initial)
        restart, initial = None, None
        assert_states_close(fast.state, ref.state)
        assert_observations_close(a.observation, r.observation, cfg.n_vessels)
        for key in r.components:
            np.testing.assert_allclose(a.components[key], r.components[key], rtol=0, atol=REWARD_ATOL, err_msg=key)
        np.testing.assert_allclose(a.reward, r.reward, rtol=0, atol=REWARD_ATOL)
        for field in ("terminated", "truncated", "collision", "out_of_bounds"):
            assert np.array_equal(getattr(a, field), getattr(r, field)), field
        if r.commanded_speed is not None:  # a function of the actions only: no transcendental function
            assert np.array_equal(a.commanded_speed, r.commanded_speed)
        done = np.flatnonzero(r.terminated | r.truncated)
        ended += done.size
        if done.size:
            fresh = np.stack([sample_initial_state(cfg, rng) for _ in done])
            events += 1
            if events % 2:
                restart, initial = r.terminated | r.truncated, fresh
            else:
                assert_observations_close(
                    fast.reset(fresh, env_ids=done), ref.reset(fresh, env_ids=done), cfg.n_vessels
                )
    if check_ends:
        assert events > 1  # both episode-end paths were exercised


def test_reference_paper_episode_agrees_on_both_backends() -> None:
    finals = {}
    for backend in ("numpy", "numba"):
        env = marine_formation_env.parallel_env("paper", backend=backend)
        policy = ReferencePolicy(env)
        obs, _ = env.reset(seed=0)
        total = 0.0
        while env.agents:
            obs, rewards, *_ = env.step(policy.act(obs))
            total += sum(rewards.values())
        finals[backend] = (env.vessel_states, total)
    assert_states_close(finals["numba"][0], finals["numpy"][0])
    assert finals["numpy"][1] == pytest.approx(finals["numba"][1], rel=1e-12)


def test_slowly_varying_current_agrees_on_both_backends() -> None:
    """With a time-varying current the kernel's libm sin may differ from numpy's in the last bit."""
    cfg = make_config("paper", current={"speed": 0.4, "direction": 1.2, "amplitude": 0.3, "period": 150.0})
    fast, ref = FormationCore(cfg, 2, backend="numba"), FormationCore(cfg, 2, backend="numpy")
    for core in (fast, ref):
        core.reset(cfg.initial_state)
    actions = np.zeros((2, 3, 1))
    for _ in range(400):
        fast.step(actions)
        ref.step(actions)
    np.testing.assert_allclose(fast.state, ref.state, rtol=1e-11, atol=1e-9)


def test_backend_selection(monkeypatch: pytest.MonkeyPatch) -> None:
    assert resolve_backend("numpy") == "numpy"
    assert resolve_backend("numba") == "numba"
    monkeypatch.delenv("MARINE_FORMATION_BACKEND", raising=False)
    assert resolve_backend("auto") == "numba"  # installed here
    monkeypatch.setenv("MARINE_FORMATION_BACKEND", "numpy")
    assert resolve_backend("auto") == "numpy"
    assert marine_formation_env.parallel_env().core.backend == "numpy"
    monkeypatch.setenv("MARINE_FORMATION_BACKEND", "cuda")
    with pytest.raises(ValueError, match="'cuda'"):
        resolve_backend("auto")
    with pytest.raises(ValueError, match="'fortran'"):
        marine_formation_env.parallel_env(backend="fortran")


def test_kernel_cache_follows_the_sources_it_compiles_in():
    """numba's disk cache only watches the jitted function's own file; the kernel's name carries the others'."""
    import hashlib
    import inspect

    from marine_formation_env import _numba, channel, control, dynamics, paths, rules

    digest = hashlib.sha256()
    for module in (dynamics, control, rules, channel, paths):
        digest.update(inspect.getsource(module).encode())
    key = digest.hexdigest()[:16]
    assert _numba.step_kernel(1).__name__ == f"_kernel_{key}"
    assert _numba.step_kernel(_numba.PARALLEL_FROM).__name__ == f"_kernel_parallel_{key}"
