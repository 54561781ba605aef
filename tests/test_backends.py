"""The numba backend against the numpy reference implementation, and backend selection.

The numpy path of ``FormationCore`` is the reference; the compiled kernel must
reproduce it (the kernel evaluates the same expressions in the same order, so
the tests ask for bit-identical states and observations).
"""

from __future__ import annotations

import numpy as np
import pytest

import marine_formation_env
from baselines import ReferencePolicy
from marine_formation_env import RewardConfig, SpeedProfile
from marine_formation_env.core import FormationCore, resolve_backend
from marine_formation_env.scenarios import make_config

pytest.importorskip("numba")

CASES = {
    "paper": {},
    "ring4-noise": {"n_vessels": 4, "topology": "ring"},
    "varying-ud-effort": {
        "u_d": SpeedProfile(mean=5.0, amplitude=0.6, period=40.0),
        "reward": RewardConfig(effort=0.4),
    },
    "as-printed": {"paper_as_printed": True},
    "random6-episode-ends": {"n_vessels": 6, "topology": "random", "safety_distance": 25.0, "horizon": 20.0},
    "cross-current-ilos": {"current": {"speed": 0.6, "direction": 2.0}, "los_integral_gain": 1.0},
    "acoustic-channel-noise": {
        "channel": {"burst": {"p_good_to_bad": 0.2}, "latency": 0.9, "jitter": 0.7, "tdma_slot": 1.0},
        "sensor_noise": {"position": 0.5, "heading": 0.01},
    },
}


@pytest.mark.parametrize("level", ["force", "guidance", "speed"])
@pytest.mark.parametrize("case", list(CASES))
def test_numba_core_is_bit_identical_to_numpy(level: str, case: str) -> None:
    overrides = dict(CASES[case])
    if level != "speed":
        overrides.pop("los_integral_gain", None)  # a speed-level option
    cfg = make_config("paper", action_level=level, **overrides)
    b = 5
    fast, ref = FormationCore(cfg, b, backend="numba"), FormationCore(cfg, b, backend="numpy")
    rng = np.random.default_rng(7)
    x0 = np.stack([ref.sample_initial_state(rng) for _ in range(b)])
    for core in (fast, ref):
        core.seed_channel(list(range(b)))  # the same channel luck on both
        core.reset(x0)
    ended = 0
    for _ in range(120):
        actions = rng.uniform(-1.3, 1.3, (b, cfg.n_vessels, cfg.action_dim))  # out-of-range values are clipped
        a, r = fast.step(actions), ref.step(actions)
        assert np.array_equal(fast.state, ref.state)
        assert np.array_equal(a.observation, r.observation)
        for key in r.components:
            assert np.array_equal(a.components[key], r.components[key]), key
        np.testing.assert_allclose(a.reward, r.reward, rtol=1e-13, atol=1e-15)
        for field in ("terminated", "truncated", "collision", "out_of_bounds"):
            assert np.array_equal(getattr(a, field), getattr(r, field)), field
        if r.commanded_speed is not None:
            assert np.array_equal(a.commanded_speed, r.commanded_speed)
        done = np.flatnonzero(r.terminated | r.truncated)
        ended += done.size
        if done.size:
            fresh = np.stack([ref.sample_initial_state(rng) for _ in done])
            assert np.array_equal(fast.reset(fresh, env_ids=done), ref.reset(fresh, env_ids=done))
    if case == "random6-episode-ends":
        assert ended > 0  # the episode-end path was exercised


def test_reference_paper_episode_is_identical_on_both_backends() -> None:
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
    assert np.array_equal(finals["numpy"][0], finals["numba"][0])
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
