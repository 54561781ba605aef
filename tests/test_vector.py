"""The batched vector env ``gymnasium.make_vec("MarineFormation-v1", vectorization_mode="vector_entry_point")``.

Truth: B PettingZoo ParallelEnvs stepped by hand with the seeds the module
docstring promises (``seed + b``), following Gymnasium's documented autoreset
semantics (NEXT_STEP: the call after the end returns the new episode's first
observation with reward 0 and ignores the actions; SAME_STEP: the last
observation goes to ``infos["final_obs"]`` and the new episode's first is
returned), and, for the joint layout, gymnasium's own ``SyncVectorEnv`` over the
single-formation env, which implements those semantics independently.
"""

from __future__ import annotations

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import marine_formation_env
from marine_formation_env.vector import MarineFormationVectorEnv

ENV_ID = "MarineFormation-v1"
LEVELS = ("force", "guidance", "speed")
ACTION_DIM = {"force": 2, "guidance": 2, "speed": 1}
DT = {"force": 0.1, "guidance": 0.5, "speed": 0.5}
MODES = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
LAYOUTS = ("joint", "agent")

N = 4
DIM = 10 + 4 * (N - 1)
SCENARIO = {"n_vessels": N, "topology": "ring"}  # random initial states: the seeds matter


def make_vec(num_envs: int, **kwargs) -> MarineFormationVectorEnv:
    return gymnasium.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)


class ManualFormations:
    """B ParallelEnvs with Gymnasium's autoreset semantics written out by hand.

    ``step`` returns per formation: obs (B, N, dim), rewards (B, N), terminated (B,),
    truncated (B,), and the final observations {b: (N, dim)} of formations that ended.
    """

    def __init__(self, seeds, mode: AutoresetMode, level: str, options=None, **overrides):
        self.envs = [marine_formation_env.parallel_env(action_level=level, **overrides) for _ in seeds]
        self.mode = mode
        self.n = self.envs[0].config.n_vessels
        self.pending = [False] * len(seeds)
        self.obs = []
        for b, (env, seed) in enumerate(zip(self.envs, seeds, strict=True)):
            opts = None if options is None else {"initial_state": options[b]}
            obs, _ = env.reset(seed=seed, options=opts)
            self.obs.append(self._stack(obs))

    def _stack(self, obs: dict) -> np.ndarray:
        return np.stack([obs[f"vessel_{j}"] for j in range(self.n)])

    def step(self, actions: np.ndarray):
        b_count = len(self.envs)
        rewards = np.zeros((b_count, self.n))
        term = np.zeros(b_count, dtype=bool)
        trunc = np.zeros(b_count, dtype=bool)
        final = {}
        for b, env in enumerate(self.envs):
            if self.pending[b]:  # NEXT_STEP: reset without a seed, reward 0, actions ignored
                obs, _ = env.reset()
                self.obs[b] = self._stack(obs)
                self.pending[b] = False
                continue
            obs, rew, te, tr, _ = env.step({f"vessel_{j}": actions[b, j] for j in range(self.n)})
            self.obs[b] = self._stack(obs)
            rewards[b] = [rew[f"vessel_{j}"] for j in range(self.n)]
            term[b] = all(te.values())
            trunc[b] = all(tr.values())
            assert term[b] == any(te.values()) and trunc[b] == any(tr.values())
            if term[b] or trunc[b]:
                assert env.agents == []
                if self.mode == AutoresetMode.NEXT_STEP:
                    self.pending[b] = True
                else:
                    final[b] = self.obs[b].copy()
                    obs, _ = env.reset()
                    self.obs[b] = self._stack(obs)
        return np.stack(self.obs), rewards, term, trunc, final


def check_against_manual(venv, manual: ManualFormations, layout: str, b_count: int, level: str, steps: int):
    """Step both with the same random actions; return how many formation episodes ended."""
    a = ACTION_DIM[level]
    rng = np.random.default_rng(12345)
    ended = 0
    for _ in range(steps):
        actions = rng.uniform(-1.0, 1.0, (b_count, N, a)).astype(np.float32)
        if layout == "joint":
            vec_actions = actions.reshape(b_count, N * a)
        else:
            vec_actions = actions.reshape(b_count * N, a)
        obs, reward, terminated, truncated, infos = venv.step(vec_actions)
        m_obs, m_rew, m_term, m_trunc, m_final = manual.step(actions)
        ended += len(m_final) + int(np.sum(m_term | m_trunc)) * (manual.mode == AutoresetMode.NEXT_STEP)
        if layout == "joint":
            np.testing.assert_array_equal(obs, np.stack([np.concatenate(list(m_obs[b])) for b in range(b_count)]))
            np.testing.assert_allclose(reward, m_rew.mean(axis=1), rtol=1e-12, atol=1e-15)
            np.testing.assert_array_equal(terminated, m_term)
            np.testing.assert_array_equal(truncated, m_trunc)
        else:
            for b in range(b_count):
                for j in range(N):
                    np.testing.assert_array_equal(obs[b * N + j], m_obs[b, j])
                    assert reward[b * N + j] == m_rew[b, j]
                    assert terminated[b * N + j] == m_term[b]
                    assert truncated[b * N + j] == m_trunc[b]
        if manual.mode == AutoresetMode.SAME_STEP:
            if m_final:
                mask = infos["_final_obs"]
                final = infos["final_obs"]
                for b in range(b_count):
                    if layout == "joint":
                        assert bool(mask[b]) == (b in m_final)
                        if b in m_final:
                            np.testing.assert_array_equal(final[b], np.concatenate(list(m_final[b])))
                    else:
                        for j in range(N):
                            assert bool(mask[b * N + j]) == (b in m_final)
                            if b in m_final:
                                np.testing.assert_array_equal(final[b * N + j], m_final[b][j])
            else:
                assert not np.any(infos.get("_final_obs", False))
        else:
            assert "final_obs" not in infos
    return ended


# --------------------------------------------------------------------------- construction


def test_make_vec_returns_the_batched_vector_env():
    venv = make_vec(3, action_level="speed", n_vessels=5, topology="ring")
    assert type(venv) is MarineFormationVectorEnv
    assert venv.num_envs == 3
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    venv.close()


@pytest.mark.parametrize("level", LEVELS)
def test_spaces_joint_layout(level):
    b, a = 3, ACTION_DIM[level]
    venv = make_vec(b, action_level=level, **SCENARIO)
    assert venv.num_envs == b
    assert venv.single_observation_space.shape == (N * DIM,)
    assert venv.observation_space.shape == (b, N * DIM)
    assert venv.single_action_space.shape == (N * a,)
    assert venv.action_space.shape == (b, N * a)
    assert venv.single_observation_space.dtype == np.float32
    # per formation, the gymnasium single-env view's spaces
    single = gymnasium.make(ENV_ID, action_level=level, **SCENARIO)
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space


@pytest.mark.parametrize("level", LEVELS)
def test_spaces_agent_layout(level):
    b, a = 3, ACTION_DIM[level]
    venv = make_vec(b, action_level=level, layout="agent", **SCENARIO)
    assert venv.num_envs == b * N
    assert venv.single_observation_space.shape == (DIM,)
    assert venv.observation_space.shape == (b * N, DIM)
    assert venv.single_action_space.shape == (a,)
    assert venv.action_space.shape == (b * N, a)
    par = marine_formation_env.parallel_env(action_level=level, **SCENARIO)
    assert venv.single_observation_space == par.observation_space("vessel_0")
    assert venv.single_action_space == par.action_space("vessel_0")


@pytest.mark.parametrize("layout", LAYOUTS)
def test_observations_inside_single_observation_space(layout):
    venv = make_vec(2, action_level="force", layout=layout, horizon=3.0, **SCENARIO)
    obs, _ = venv.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(40):  # crosses an autoreset (30 steps per episode at force)
        assert obs.shape == venv.observation_space.shape
        assert venv.observation_space.contains(obs)
        for row in obs:
            assert venv.single_observation_space.contains(row)
        obs, *_ = venv.step(rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32))


def test_bad_constructor_arguments():
    with pytest.raises(ValueError, match="layout"):
        MarineFormationVectorEnv(2, layout="per_vessel")
    with pytest.raises(ValueError, match="autoreset_mode"):
        MarineFormationVectorEnv(2, autoreset_mode=AutoresetMode.DISABLED)


# --------------------------------------------------------------------------- formation k == parallel_env(seed + k)


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
@pytest.mark.parametrize("level", LEVELS)
def test_formations_match_parallel_envs_across_autoreset(level, mode, layout):
    b_count, seed = 3, 11
    horizon = 1.5 if level != "force" else 0.5  # 3 or 5 steps per episode
    max_steps = round(horizon / DT[level])
    venv = make_vec(b_count, action_level=level, layout=layout, autoreset_mode=mode, horizon=horizon, **SCENARIO)
    assert venv.metadata["autoreset_mode"] == mode
    obs, _ = venv.reset(seed=seed)
    manual = ManualFormations([seed + b for b in range(b_count)], mode, level, horizon=horizon, **SCENARIO)
    first = np.stack(manual.obs)
    if layout == "joint":
        np.testing.assert_array_equal(obs, first.reshape(b_count, -1))
    else:
        np.testing.assert_array_equal(obs, first.reshape(b_count * N, -1))
    # distinct seeds give distinct formations
    assert not np.array_equal(first[0], first[1])
    steps = 2 * max_steps + 3  # two episode ends (and the NEXT_STEP resets) and a bit of the third episode
    ended = check_against_manual(venv, manual, layout, b_count, level, steps)
    # NEXT_STEP spends one call per reset; SAME_STEP does not
    per_formation = 2 if mode == AutoresetMode.NEXT_STEP else steps // max_steps
    assert ended == per_formation * b_count


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
def test_channel_and_noise_streams_carry_on_across_autoreset_as_in_parallel_envs(mode):
    """With random links and sensor noise, formation k draws from its channel streams exactly what
    ``parallel_env`` seeded with seed + k draws over the same episodes: the autoreset of the vector
    env (in the compiled step under NEXT_STEP) consumes nothing for the step it replaces."""
    b_count, seed, level, horizon = 3, 4, "force", 1.0
    channel = {
        "burst": {"p_good_to_bad": 0.3, "p_bad_to_good": 0.4, "loss_bad": 0.9},
        "latency": 0.2,
        "jitter": 0.3,
        "tdma_slot": 0.2,
        "failure_rate": 0.5,
        "recovery_rate": 1.0,
    }
    kw = {"horizon": horizon, "channel": channel, "sensor_noise": {"position": 2.0, "speed": 0.1}, **SCENARIO}
    venv = make_vec(b_count, action_level=level, layout="joint", autoreset_mode=mode, **kw)
    venv.reset(seed=seed)
    manual = ManualFormations([seed + b for b in range(b_count)], mode, level, **kw)
    ended = check_against_manual(venv, manual, "joint", b_count, level, 3 * round(horizon / DT[level]) + 2)
    assert ended >= 2 * b_count


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
@pytest.mark.parametrize("layout", LAYOUTS)
def test_one_formation_ends_while_others_go_on(mode, layout):
    """Formation 1 starts with two vessels 6 m apart, head-on, and collides in the first step; 0 and 2 do not."""
    b_count, seed, level = 3, 5, "speed"
    kw = {"horizon": 2.0, "safety_distance": 5.0, **SCENARIO}
    initial = []
    for b in range(b_count):
        probe = marine_formation_env.parallel_env(**kw)
        probe.reset(seed=seed + b)
        initial.append(probe.vessel_states)
    initial = np.stack(initial)
    initial[1, 1, :2] = initial[1, 0, :2] + np.array([0.0, 6.0])
    initial[1, :2, 2:] = [[math.pi / 2, 5.0, 0.0, 0.0], [-math.pi / 2, 5.0, 0.0, 0.0]]
    venv = make_vec(b_count, action_level=level, layout=layout, autoreset_mode=mode, **kw)
    venv.reset(seed=seed, options={"initial_state": initial})
    manual = ManualFormations([seed + b for b in range(b_count)], mode, level, options=initial, **kw)
    # step 1: formation 1 collides; the others run to truncation at step 4 (and beyond)
    check_against_manual(venv, manual, layout, b_count, level, 7)


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
def test_joint_layout_matches_gymnasium_sync_vector_env(mode):
    """gymnasium's own SyncVectorEnv over the single-formation env implements the same autoreset."""
    b_count, seed, kw = 3, 21, {"action_level": "guidance", "horizon": 1.5, **SCENARIO}
    ours = make_vec(b_count, autoreset_mode=mode, **kw)
    sync = gymnasium.make_vec(
        ENV_ID, num_envs=b_count, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **kw
    )
    assert isinstance(sync, gymnasium.vector.SyncVectorEnv)
    obs, _ = ours.reset(seed=seed)
    s_obs, _ = sync.reset(seed=seed)
    np.testing.assert_array_equal(obs, s_obs)
    rng = np.random.default_rng(1)
    finals = 0
    for _ in range(10):
        actions = rng.uniform(-1, 1, ours.action_space.shape).astype(np.float32)
        obs, rew, te, tr, info = ours.step(actions)
        s_obs, s_rew, s_te, s_tr, s_info = sync.step(actions)
        np.testing.assert_array_equal(obs, s_obs)
        np.testing.assert_allclose(rew, s_rew, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(te, s_te)
        np.testing.assert_array_equal(tr, s_tr)
        if "_final_obs" in s_info and np.any(s_info["_final_obs"]):
            finals += 1
            np.testing.assert_array_equal(info["_final_obs"], s_info["_final_obs"])
            for b in np.flatnonzero(s_info["_final_obs"]):
                np.testing.assert_array_equal(info["final_obs"][b], s_info["final_obs"][b])
    assert finals == (3 if mode == AutoresetMode.SAME_STEP else 0)


def test_next_step_reset_ignores_actions_and_returns_zero_reward():
    venv = make_vec(2, action_level="speed", horizon=1.0, **SCENARIO)  # 2 steps per episode
    venv.reset(seed=0)
    venv.step(np.zeros((2, N), np.float32))
    _, _, te, tr, _ = venv.step(np.zeros((2, N), np.float32))
    assert not te.any() and tr.all()
    # the reset call: whatever the actions (even NaN), the new episode's first observation, reward 0
    obs_a, rew, te, tr, _ = venv.step(np.full((2, N), np.nan, np.float32))
    np.testing.assert_array_equal(rew, 0.0)
    assert not te.any() and not tr.any()
    single = [marine_formation_env.parallel_env(horizon=1.0, **SCENARIO) for _ in range(2)]
    for b, env in enumerate(single):
        env.reset(seed=b)
        while env.agents:
            env.step({a: np.zeros(1, np.float32) for a in env.agents})
        first, _ = env.reset()
        np.testing.assert_array_equal(obs_a[b], np.concatenate([first[f"vessel_{j}"] for j in range(N)]))


# --------------------------------------------------------------------------- seeding


@pytest.mark.parametrize("layout", LAYOUTS)
def test_reset_with_list_of_seeds(layout):
    seeds = [40, 7, 123]
    venv = make_vec(3, action_level="speed", layout=layout, **SCENARIO)
    obs, _ = venv.reset(seed=seeds)
    for b, s in enumerate(seeds):
        par_obs, _ = marine_formation_env.parallel_env(**SCENARIO).reset(seed=s)
        for j in range(N):
            expected = par_obs[f"vessel_{j}"]
            if layout == "joint":
                np.testing.assert_array_equal(obs[b, j * DIM : (j + 1) * DIM], expected)
            else:
                np.testing.assert_array_equal(obs[b * N + j], expected)


def test_reset_list_with_none_keeps_that_formations_generator():
    venv = make_vec(2, action_level="speed", **SCENARIO)
    venv.reset(seed=[3, 4])
    obs, _ = venv.reset(seed=[9, None])
    p9 = marine_formation_env.parallel_env(**SCENARIO)
    p4 = marine_formation_env.parallel_env(**SCENARIO)
    first9, _ = p9.reset(seed=9)
    p4.reset(seed=4)
    second4, _ = p4.reset()  # the generator of seed 4 carries on
    np.testing.assert_array_equal(obs[0], np.concatenate([first9[f"vessel_{j}"] for j in range(N)]))
    np.testing.assert_array_equal(obs[1], np.concatenate([second4[f"vessel_{j}"] for j in range(N)]))


@pytest.mark.parametrize("seeds", [[1, 2], [1, 2, 3, 4], []])
def test_reset_with_wrong_number_of_seeds_raises(seeds):
    venv = make_vec(3, **SCENARIO)
    with pytest.raises(ValueError, match="3 seeds"):
        venv.reset(seed=seeds)


def test_same_seed_reproduces():
    a = make_vec(2, **SCENARIO)
    b = make_vec(2, **SCENARIO)
    obs_a, _ = a.reset(seed=17)
    obs_b, _ = b.reset(seed=17)
    np.testing.assert_array_equal(obs_a, obs_b)
    obs_c, _ = b.reset(seed=18)
    assert not np.array_equal(obs_a, obs_c)
    # seed=17 makes formation 1 start like seed=18 makes formation 0 (seed + b)
    np.testing.assert_array_equal(obs_a[1], obs_c[0])


def test_numpy_integer_seed_is_accepted():
    # reset() explicitly treats numpy integers like int (isinstance(seed, (int, np.integer))),
    # so a seed from a numpy array must work and equal the python int seed.
    a = make_vec(2, **SCENARIO)
    b = make_vec(2, **SCENARIO)
    obs_a, _ = a.reset(seed=17)
    obs_b, _ = b.reset(seed=np.int64(17))
    np.testing.assert_array_equal(obs_a, obs_b)


# --------------------------------------------------------------------------- errors


def test_step_before_reset_raises():
    venv = make_vec(2, **SCENARIO)
    with pytest.raises(RuntimeError, match="reset"):
        venv.step(np.zeros((2, N), np.float32))


@pytest.mark.parametrize("layout", LAYOUTS)
def test_wrong_action_shape_and_nan_raise(layout):
    venv = make_vec(2, action_level="force", layout=layout, **SCENARIO)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, N), np.float32))
    bad = np.zeros(venv.action_space.shape, np.float32)
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        venv.step(bad)


def test_rollout_emits_no_warnings():
    venv = make_vec(2, action_level="force", layout="agent", horizon=1.0, **SCENARIO)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        venv.reset(seed=0)
        rng = np.random.default_rng(0)
        for _ in range(25):
            venv.step(rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32))
        venv.close()
    assert [str(w.message) for w in caught] == []
