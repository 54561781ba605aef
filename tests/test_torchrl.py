"""The TorchRL view ``marine_formation_env.torchrl.MarineFormationTorchEnv``.

Truth: TorchRL's own ``check_env_specs`` (the specs describe what the env
returns, at every level, with and without a channel); B PettingZoo
ParallelEnvs reset with ``seed + b`` and stepped by hand with the same
actions, each reset (without a seed) as soon as its episode ends, which is
what TorchRL's ``step_and_maybe_reset`` asks of a formation; and the
documented action map ``u_c = U_min + (a + 1)/2 · (U_max − U_min)``.
Same machine, same backend: the comparisons with the ParallelEnvs are exact.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from torchrl.envs.utils import check_env_specs  # noqa: E402

import marine_formation_env  # noqa: E402
from marine_formation_env.torchrl import GROUP, INFO_KEYS, MarineFormationTorchEnv  # noqa: E402

LEVELS = ("force", "guidance", "speed")
SCENARIO = {"n_vessels": 4, "topology": "ring"}  # random initial states: the seeds matter
LOSSY = {"burst": {"p_good_to_bad": 0.3, "p_bad_to_good": 0.4, "loss_bad": 0.9}, "latency": 0.2, "jitter": 0.3}


@pytest.mark.parametrize("scenario", ["paper", "acoustic", "survey_acoustic"])
@pytest.mark.parametrize("level", LEVELS)
def test_check_env_specs_at_every_level_with_and_without_a_channel(level, scenario):
    env = MarineFormationTorchEnv(num_envs=3, scenario=scenario, action_level=level)
    check_env_specs(env, seed=0)
    td = env.reset()
    assert td.batch_size == torch.Size([3])
    assert td[GROUP, "observation"].shape == (3, 3, env.core.layout.dim)
    expected = set(INFO_KEYS) | ({"commanded_speed"} if level != "force" else set())
    assert set(td[GROUP, "info"].keys()) == expected
    assert env.group_map == {GROUP: ["vessel_0", "vessel_1", "vessel_2"]}


def _stack(values: dict, n: int) -> np.ndarray:
    return np.stack([values[f"vessel_{j}"] for j in range(n)])


@pytest.mark.parametrize(
    ("level", "extra"),
    [("force", {}), ("speed", {}), ("guidance", {"channel": LOSSY, "sensor_noise": {"position": 2.0}})],
)
def test_seeded_formations_replay_parallel_envs_through_partial_resets(level, extra):
    b_count, seed, horizon = 3, 7, 1.5 if level != "force" else 0.5
    kw = {"action_level": level, "horizon": horizon, **SCENARIO, **extra}
    env = MarineFormationTorchEnv(num_envs=b_count, **kw)
    env.set_seed(seed)
    td = env.reset()
    singles = [marine_formation_env.parallel_env(**kw) for _ in range(b_count)]
    first = [s.reset(seed=seed + b)[0] for b, s in enumerate(singles)]
    n = singles[0].config.n_vessels
    for b in range(b_count):
        np.testing.assert_array_equal(td[GROUP, "observation"][b].numpy(), _stack(first[b], n))
    rng = np.random.default_rng(3)
    ends = 0
    for _ in range(3 * singles[0].max_steps + 2):  # through two episode ends of every formation
        actions = rng.uniform(-1, 1, (b_count, n, env.config.action_dim)).astype(np.float32)
        td[GROUP, "action"] = torch.from_numpy(actions)
        td, td_next_root = env.step_and_maybe_reset(td)
        out = td["next"]
        for b, single in enumerate(singles):
            obs, rew, term, trunc, _ = single.step({f"vessel_{j}": actions[b, j] for j in range(n)})
            np.testing.assert_array_equal(out[GROUP, "observation"][b].numpy(), _stack(obs, n))
            np.testing.assert_array_equal(out[GROUP, "reward"][b, :, 0].numpy(), _stack(rew, n).astype(np.float32))
            assert bool(out["terminated"][b]) == any(term.values())
            assert bool(out["truncated"][b]) == any(trunc.values())
            if not single.agents:  # the formation restarts: TorchRL's reset, a plain reset() of the single env
                ends += 1
                restart, _ = single.reset()
                np.testing.assert_array_equal(td_next_root[GROUP, "observation"][b].numpy(), _stack(restart, n))
        td = td_next_root
    assert ends >= 2 * b_count


def test_partial_reset_restarts_only_the_masked_formations():
    env = MarineFormationTorchEnv(num_envs=4, **SCENARIO)
    env.set_seed(0)
    td = env.reset()
    for _ in range(5):
        td = env.rand_step(td)["next"].exclude("reward")
    before = env.core.state.copy()
    time_before = env.core.time.copy()
    mask = torch.tensor([[False], [True], [False], [True]])
    out = env.reset(td.set("_reset", mask))
    np.testing.assert_array_equal(env.core.state[[0, 2]], before[[0, 2]])  # untouched
    np.testing.assert_array_equal(env.core.time[[0, 2]], time_before[[0, 2]])
    assert (env.core.time[[1, 3]] == 0).all() and (time_before[[1, 3]] > 0).all()
    assert not out["done"].any()
    assert not np.array_equal(env.core.state[1], before[1])


def test_infos_hold_the_reward_components_and_the_commanded_speed():
    env = MarineFormationTorchEnv(num_envs=2, action_level="speed")
    env.set_seed(1)
    td = env.reset()
    a = np.array([[[-1.0], [0.0], [0.5]], [[1.0], [-0.5], [0.25]]], dtype=np.float32)
    td[GROUP, "action"] = torch.from_numpy(a)
    out = env.step(td)["next"]
    info = out[GROUP, "info"]
    cfg = env.config
    expected_u_c = cfg.u_min + 0.5 * (a + 1.0) * (cfg.u_max - cfg.u_min)
    np.testing.assert_allclose(info["commanded_speed"].numpy(), expected_u_c, rtol=1e-6)  # float32 entries
    components = sum(
        info[f"reward_{key}"] for key in ("cross_track", "heading", "coordination", "speed", "effort", "terminal")
    )
    np.testing.assert_allclose(components.numpy(), out[GROUP, "reward"].numpy(), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(info["time"].numpy(), cfg.dt)
    assert out["state"].shape == (2, 6 * 3 + 1)


def test_group_named_as_vmas_and_seed_at_construction():
    """``group="agents"``, ``seed=`` as ``VmasEnv`` takes them: the same numbers under VMAS's keys."""
    ours = MarineFormationTorchEnv(num_envs=2, action_level="speed", **SCENARIO)
    ours.set_seed(5)
    vmas_like = MarineFormationTorchEnv(num_envs=2, action_level="speed", group="agents", seed=5, **SCENARIO)
    check_env_specs(vmas_like)
    vmas_like.set_seed(5)
    a, b = ours.reset(), vmas_like.reset()
    assert set(b.keys()) == {"agents", "state", "done", "terminated", "truncated"}
    np.testing.assert_array_equal(a[GROUP, "observation"].numpy(), b["agents", "observation"].numpy())
    assert vmas_like.action_key == ("agents", "action") and vmas_like.reward_key == ("agents", "reward")


def test_bad_arguments_are_refused_with_the_value_named():
    with pytest.raises(ValueError, match="num_envs must be a whole number ≥ 1, got 0"):
        MarineFormationTorchEnv(num_envs=0)
    with pytest.raises(TypeError, match="unexpected keyword argument 'frameskip'"):
        MarineFormationTorchEnv(num_envs=1, frameskip=4)
    with pytest.raises(ValueError, match="render_mode must be None or 'rgb_array', got 'human'"):
        MarineFormationTorchEnv(num_envs=1, render_mode="human")
    with pytest.raises(ValueError, match=r"group must be a non-empty name other than .*, got 'state'"):
        MarineFormationTorchEnv(num_envs=1, group="state")


def test_a_curriculum_starts_later_resets_part_of_the_way_from_the_formation_on_its_lanes():
    # the paper's straight path is the inertial frame; its nominal start (docs/model.md §5) has every vessel
    # 30-40 m off its lane and the coordination variables θ_j = x_j − D_xj at 50, −60 and −20 m
    env = MarineFormationTorchEnv(num_envs=2)
    d_x, d_y = env.config.formation[:, 0], env.config.formation[:, 1]
    nominal = np.array(env.config.start_state)
    env.set_initial_spread(0.0)
    env.reset()
    state = env.core.state
    np.testing.assert_allclose(state[..., 1], np.broadcast_to(d_y, (2, 3)))  # on the lanes
    np.testing.assert_allclose(state[..., 2], 0.0)  # along the path
    np.testing.assert_allclose(state[..., 0] - d_x, -10.0)  # coordinated at the nominal mean θ, (50 − 60 − 20) / 3
    np.testing.assert_array_equal(state[..., 3:], np.broadcast_to(nominal[:, 3:], (2, 3, 3)))  # u, v, r kept
    env.set_initial_spread(0.5)
    env.reset()
    in_formation = np.stack([d_x - 10.0, d_y, np.zeros(3)], axis=1)
    np.testing.assert_allclose(env.core.state[0, :, :3], (in_formation + nominal[:, :3]) / 2)  # half-way
    env.set_initial_spread(1.0)  # the scenario's again
    env.reset()
    np.testing.assert_allclose(env.core.state[0], nominal)
    for bad in (1.5, -0.1, float("nan"), True, "0.5"):
        with pytest.raises(ValueError, match=r"initial-state spread must be a number in \[0, 1\], got "):
            env.set_initial_spread(bad)


def test_the_initial_state_noise_shrinks_with_the_spread():
    half = np.array([40.0, 20.0, 0.3, 1.0])  # init_noise half-widths: x, y [m], psi [rad], u [m/s]
    env = MarineFormationTorchEnv(num_envs=64, init_noise=dict(zip(("x", "y", "psi", "u"), half, strict=True)))
    env.set_initial_spread(0.0)
    env.reset()
    centre = env.core.state[0, :, :4].copy()  # no noise at 0: every formation starts there
    np.testing.assert_array_equal(env.core.state[..., :4], np.broadcast_to(centre, (64, 3, 4)))
    env.set_initial_spread(0.25)
    env.set_seed(0)
    env.reset()
    scaled_nominal = centre + 0.25 * (np.array(env.config.start_state)[:, :4] - centre)
    deviation = np.abs(env.core.state[..., :4] - scaled_nominal).reshape(-1, 4)
    # uniform draws within ±0.25 of the half-widths; 192 of them reach past 0.2 in every column (else the
    # noise would be smaller than asked: the chance that all stay below is 0.8^192 per column)
    assert (deviation <= 0.25 * half + 1e-9).all() and (deviation > 0.2 * half).any(axis=0).all()


def test_render_returns_an_even_sized_frame():
    pytest.importorskip("matplotlib")
    env = MarineFormationTorchEnv(num_envs=2, render_mode="rgb_array")
    env.reset()
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[0] % 2 == 0 and frame.shape[1] % 2 == 0
    env.close()
    plain = MarineFormationTorchEnv(num_envs=1)
    plain.reset()
    with pytest.warns(UserWarning, match="without a render_mode"):
        assert plain.render() is None
    asked = plain.render(mode="rgb_array", agent_index_focus=None)  # as TorchRL's VMAS recipes call it
    assert asked.shape == frame.shape
    plain.close()


def test_torchrl_pettingzoo_wrapper_takes_the_parallel_env_with_its_infos():
    """TorchRL's generic wrapper builds its info spec from ``reset()``: flat numeric infos reach the tensordict."""
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    env = PettingZooWrapper(marine_formation_env.parallel_env("paper", action_level="speed"))
    check_env_specs(env, seed=0)
    td = env.rollout(3)
    info = td["next", "vessel", "info"]
    assert {"reward_coordination", "commanded_speed", "time"} <= set(info.keys())
    np.testing.assert_allclose(info["time"][:, 0].numpy(), [0.5, 1.0, 1.5])
