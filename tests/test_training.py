"""SB3 training: the shared-policy VecEnv, config parsing, and a seconds-long end-to-end run.

Truth: B PettingZoo ParallelEnvs stepped by hand with the seeds the module
docstring of ``training.vec_env`` promises (``s + b``) and SB3's documented
VecEnv conventions (``terminal_observation`` = the last observation of the
finished episode, ``TimeLimit.truncated`` on truncation only); SB3's own
wrappers and utilities; the algorithms' constructor signatures for
hyperparameter names; and, for the end-to-end run, returns recomputed by a
hand-written loop over the ParallelEnv (return = per-vessel sum of rewards,
averaged over vessels, as ``baselines.metrics`` documents).
"""

from __future__ import annotations

import csv
import inspect
import json
import re
import shutil
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import record_calls

pytest.importorskip("stable_baselines3")
import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecCheckNan, VecMonitor, VecNormalize
from stable_baselines3.common.vec_env.util import check_for_nested_spaces, obs_space_info

import marine_formation_env
from baselines.reference import ReferencePolicy
from baselines.seeds import DEVELOPMENT_SEED, EVALUATION_SEED
from training import train as train_module
from training.config import (
    TrainConfigError,
    algo_class,
    algo_kwargs,
    apply_overrides,
    budget_fraction,
    load_config,
    validate,
)
from training.learned import ModelPolicy, load_learned_policy
from training.vec_env import SharedPolicyVecEnv

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)

ENV_ID = "MarineFormation-v1"
REPO = Path(__file__).resolve().parents[1]
CONFIGS = sorted((REPO / "training" / "configs").glob("*.yaml"))
SPEED_CONFIG = REPO / "training" / "configs" / "paper_speed_ppo.yaml"
ACTION_DIM = {"force": 2, "guidance": 2, "speed": 1}
EVAL_SEED = DEVELOPMENT_SEED  # training.callbacks: evaluations during training use the development seeds


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread():
    """Tiny MLPs on a shared 2-core machine: one intra-op thread is hundreds of times faster."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def manual_return(env, policy, seed: int) -> float:
    """Per-vessel sum of rewards averaged over vessels, by a hand-written ParallelEnv loop."""
    obs, _ = env.reset(seed=seed)
    totals = dict.fromkeys(env.possible_agents, 0.0)
    while env.agents:
        obs, rewards, *_ = env.step(policy.act(obs))
        for agent, r in rewards.items():
            totals[agent] += r
    return float(np.mean(list(totals.values())))


# =========================================================================== (a) SharedPolicyVecEnv


def _stack(obs: dict, n: int) -> np.ndarray:
    return np.stack([obs[f"vessel_{j}"] for j in range(n)])


@pytest.mark.parametrize("level", ["speed", "force"])
def test_shared_policy_vec_env_matches_parallel_envs_across_episode_end(level):
    b_count, n, seed = 3, 4, 42
    horizon = 1.5 if level == "speed" else 0.5  # 3 / 5 steps per episode
    kw = {"action_level": level, "n_vessels": n, "topology": "ring", "horizon": horizon}
    venv = SharedPolicyVecEnv(b_count, "paper", **kw)
    assert venv.num_envs == b_count * n
    seeds = venv.seed(seed)
    assert list(seeds) == [seed + k // n for k in range(b_count * n)]  # a formation's vessels share one seed
    obs = venv.reset()
    envs = [marine_formation_env.parallel_env(**kw) for _ in range(b_count)]
    current = [_stack(env.reset(seed=seed + b)[0], n) for b, env in enumerate(envs)]
    np.testing.assert_array_equal(obs, np.concatenate(current))
    max_steps = envs[0].config.max_steps
    rng = np.random.default_rng(0)
    a = ACTION_DIM[level]
    ends = 0
    for _ in range(2 * max_steps + 2):
        actions = rng.uniform(-1, 1, (b_count * n, a)).astype(np.float32)
        obs, rewards, dones, infos = venv.step(actions)
        assert isinstance(infos, list) and len(infos) == b_count * n
        assert rewards.shape == (b_count * n,) and dones.shape == (b_count * n,)
        for b, env in enumerate(envs):
            p_obs, p_rew, p_term, p_trunc, _ = env.step({f"vessel_{j}": actions[b * n + j] for j in range(n)})
            last = _stack(p_obs, n)
            done = all(p_term.values()) or all(p_trunc.values())
            if done:
                current[b] = _stack(env.reset()[0], n)  # the formation's generator carries on
            else:
                current[b] = last
            for j in range(n):
                k = b * n + j
                assert rewards[k] == pytest.approx(p_rew[f"vessel_{j}"], rel=1e-6, abs=1e-7)
                assert bool(dones[k]) == done
                np.testing.assert_array_equal(obs[k], current[b][j])
                if done:
                    ends += 1
                    np.testing.assert_array_equal(infos[k]["terminal_observation"], last[j])
                    truncated_only = all(p_trunc.values()) and not all(p_term.values())
                    assert infos[k]["TimeLimit.truncated"] is truncated_only
                else:
                    assert "terminal_observation" not in infos[k]
                    assert "TimeLimit.truncated" not in infos[k]
    assert ends == 2 * b_count * n


def test_shared_policy_vec_env_termination_is_not_a_time_limit():
    # full yaw torque drives |r| past max_yaw_rate (1 rad/s) well before the 20 s horizon: termination
    kw = {"action_level": "force", "n_vessels": 3, "horizon": 20.0}
    venv = SharedPolicyVecEnv(1, "paper", **kw)
    venv.seed(0)
    venv.reset()
    env = marine_formation_env.parallel_env(**kw)
    env.reset(seed=0)
    action = np.array([0.0, 1.0], dtype=np.float32)
    for _ in range(200):
        _, rewards, dones, infos = venv.step(np.tile(action, (3, 1)))
        p_obs, p_rew, p_term, p_trunc, p_info = env.step(dict.fromkeys(env.agents, action))
        if dones.any():
            break
    assert all(p_term.values()) and not any(p_trunc.values())
    assert p_info["vessel_0"]["out_of_bounds"]
    assert dones.all()
    for j in range(3):
        assert infos[j]["TimeLimit.truncated"] is False
        np.testing.assert_array_equal(infos[j]["terminal_observation"], p_obs[f"vessel_{j}"])
        assert rewards[j] == pytest.approx(p_rew[f"vessel_{j}"], rel=1e-6)


def test_shared_policy_vec_env_seed_applies_to_next_reset_only():
    kw = {"n_vessels": 4, "topology": "ring"}
    venv = SharedPolicyVecEnv(2, "paper", **kw)
    venv.seed(7)
    first = venv.reset()
    second = venv.reset()  # not re-seeded: the generators carry on
    for b in range(2):
        env = marine_formation_env.parallel_env(**kw)
        o1, _ = env.reset(seed=7 + b)
        o2, _ = env.reset()
        np.testing.assert_array_equal(first[4 * b : 4 * b + 4], _stack(o1, 4))
        np.testing.assert_array_equal(second[4 * b : 4 * b + 4], _stack(o2, 4))


def test_shared_policy_vec_env_attribute_methods_return_per_entry_lists():
    venv = SharedPolicyVecEnv(2, "paper", n_vessels=3)
    assert venv.num_envs == 6
    configs = venv.get_attr("config")
    assert len(configs) == 6 and all(c.n_vessels == 3 for c in configs)
    assert venv.get_attr("render_mode") == [None] * 6
    assert len(venv.get_attr("config", indices=[0, 4])) == 2
    assert len(venv.get_attr("config", indices=3)) == 1
    venv.set_attr("my_flag", 17)
    assert venv.get_attr("my_flag") == [17] * 6
    assert venv.get_attr("my_flag", indices=[1, 2, 5]) == [17] * 3
    assert venv.env_is_wrapped(Monitor) == [False] * 6
    assert venv.env_is_wrapped(Monitor, indices=[2]) == [False]
    result = venv.env_method("reset", seed=3)
    assert len(result) == 6
    result = venv.env_method("reset", seed=3, indices=[0, 1])
    assert len(result) == 2
    assert len(venv.get_images()) == 6


def test_shared_policy_vec_env_in_sb3_wrappers_and_utilities():
    b_count, n = 2, 3
    kw = {"action_level": "speed", "horizon": 2.0}  # 4 steps per episode
    venv = SharedPolicyVecEnv(b_count, "paper", **kw)
    check_for_nested_spaces(venv.observation_space)
    _keys, shapes, dtypes = obs_space_info(venv.observation_space)
    assert shapes[None] == (10 + 4 * (n - 1),) and dtypes[None] == np.float32
    wrapped = VecNormalize(VecMonitor(VecCheckNan(venv, raise_exception=True)), gamma=0.99)
    wrapped.seed(3)
    obs = wrapped.reset()
    assert obs.shape == (b_count * n, 10 + 4 * (n - 1))
    envs = [marine_formation_env.parallel_env(**kw) for _ in range(b_count)]
    for b, env in enumerate(envs):
        env.reset(seed=3 + b)
    totals = np.zeros(b_count * n)
    rng = np.random.default_rng(0)
    episodes = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(4):
            actions = rng.uniform(-1, 1, (b_count * n, 1)).astype(np.float32)
            obs, _, dones, infos = wrapped.step(actions)
            assert np.all(np.isfinite(obs))
            for b, env in enumerate(envs):
                _, rew, *_ = env.step({f"vessel_{j}": actions[b * n + j] for j in range(n)})
                for j in range(n):
                    totals[b * n + j] += rew[f"vessel_{j}"]
            episodes = [info.get("episode") for info in infos]
    assert [str(w.message) for w in caught] == []
    assert dones.all()
    # VecMonitor's episode statistics: each vessel's own (unnormalized) return and the 4-step length
    for k, ep in enumerate(episodes):
        assert ep is not None
        assert ep["l"] == 4
        assert ep["r"] == pytest.approx(totals[k], rel=1e-5)


def test_sb3_ppo_accepts_the_vec_env():
    venv = SharedPolicyVecEnv(1, "paper", horizon=2.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = PPO("MlpPolicy", venv, n_steps=8, batch_size=24, n_epochs=1, device="cpu", seed=0)
        model.learn(total_timesteps=24)
    assert [str(w.message) for w in caught] == []
    assert model.num_timesteps == 24


# =========================================================================== (b) config parsing


def base_config() -> dict:
    """The shipped speed config with an integer ``n_timesteps`` (see test_shipped_config_...: the file's
    ``3.0e6`` is a string to YAML 1.1), so that each test below checks only its own key."""
    return {**load_config(SPEED_CONFIG), "n_timesteps": 3_000_000}


def test_validate_fills_defaults_and_keeps_values():
    resolved = validate({**base_config(), "n_timesteps": 2.5e5})
    assert resolved["algo"] == "ppo"
    assert resolved["n_timesteps"] == 250_000 and isinstance(resolved["n_timesteps"], int)
    assert resolved["env_kwargs"]["action_level"] == "speed"
    minimal = validate({})
    assert minimal["algo"] == "ppo" and minimal["scenario"] == "paper" and minimal["env_kwargs"] == {}


def test_validate_rejects_unknown_hyperparameter():
    with pytest.raises(TrainConfigError, match="n_stepz"):
        validate({**base_config(), "n_stepz": 64})


def test_validate_checks_hyperparameters_against_the_algorithm():
    # buffer_size is a SAC argument, not a PPO one
    assert "buffer_size" not in inspect.signature(PPO).parameters
    with pytest.raises(TrainConfigError, match="buffer_size"):
        validate({"algo": "ppo", "buffer_size": 1000})
    assert validate({"algo": "sac", "buffer_size": 1000})["buffer_size"] == 1000
    assert "buffer_size" in inspect.signature(SAC).parameters


def test_validate_rejects_unknown_env_kwargs_key():
    cfg = base_config()
    cfg["env_kwargs"] = {**cfg["env_kwargs"], "wind_speed": 3.0}
    with pytest.raises(TrainConfigError, match="wind_speed"):
        validate(cfg)


def test_validate_rejects_bad_env_kwargs_value():
    with pytest.raises(TrainConfigError, match="action_level"):
        validate({"env_kwargs": {"action_level": "torque"}})


def test_validate_rejects_unknown_algo():
    with pytest.raises(TrainConfigError, match="dqn"):
        validate({**base_config(), "algo": "dqn"})


def test_validate_rejects_bad_activation_fn():
    cfg = base_config()
    cfg["policy_kwargs"] = {"net_arch": [8], "activation_fn": "sigmoid"}
    with pytest.raises(TrainConfigError, match=r"activation_fn.*sigmoid"):
        validate(cfg)


@pytest.mark.parametrize("bad", [["action_level", "speed"], "action_level=speed", 3])
def test_validate_rejects_non_mapping_env_kwargs(bad):
    with pytest.raises(TrainConfigError, match="env_kwargs must be a mapping"):
        validate({**base_config(), "env_kwargs": bad})


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("n_envs", 0),
        ("n_envs", 2.5),
        ("n_envs", True),
        ("n_timesteps", -1),
        ("n_timesteps", "many"),
        ("normalize", "yes"),
    ],
)
def test_validate_rejects_bad_special_values(key, value):
    with pytest.raises(TrainConfigError, match=key):
        validate({**base_config(), key: value})


def test_learning_rate_schedule():
    with pytest.raises(TrainConfigError, match="lin_fast"):
        validate({"learning_rate": "lin_fast"})
    resolved = validate({"learning_rate": "lin_3e-4"})
    schedule = algo_kwargs(resolved)["learning_rate"]
    # rl-zoo convention: SB3 passes progress_remaining from 1 (start) to 0 (end)
    assert schedule(1.0) == pytest.approx(3e-4)
    assert schedule(0.5) == pytest.approx(1.5e-4)
    assert schedule(0.0) == 0.0


@pytest.mark.parametrize(
    ("done", "elapsed", "seconds", "expected"),
    [
        (250, 10.0, None, 0.25),  # no clock: steps only
        (250, 10.0, 100.0, 0.25),  # the steps run out first
        (250, 60.0, 100.0, 0.6),  # the clock runs out first
        (1500, 0.0, 100.0, 1.5),  # not capped: the last rollout may pass the budget
    ],
)
def test_the_budget_spent_is_whichever_part_runs_out_first(done, elapsed, seconds, expected):
    assert budget_fraction(done, 1000, elapsed, seconds) == pytest.approx(expected)


def test_activation_names_become_torch_modules():
    kwargs = algo_kwargs(validate({"policy_kwargs": {"activation_fn": "relu", "net_arch": [8]}}))
    assert kwargs["policy_kwargs"]["activation_fn"] is torch.nn.ReLU
    assert kwargs["policy_kwargs"]["net_arch"] == [8]


def test_load_config_rejects_file_without_env_id(tmp_path):
    path = tmp_path / "other.yaml"
    path.write_text(yaml.safe_dump({"CartPole-v1": {"algo": "ppo"}}))
    with pytest.raises(TrainConfigError, match=ENV_ID):
        load_config(path)
    path.write_text(yaml.safe_dump({ENV_ID: {"algo": "ppo"}, "CartPole-v1": {}}))
    with pytest.raises(TrainConfigError, match=ENV_ID):
        load_config(path)
    path.write_text("- just\n- a list\n")
    with pytest.raises(TrainConfigError, match=ENV_ID):
        load_config(path)
    with pytest.raises(TrainConfigError, match="does not exist"):
        load_config(tmp_path / "missing.yaml")


def test_apply_overrides_dotted_keys():
    cfg = base_config()
    out = apply_overrides(cfg, {"env_kwargs.action_level": "force", "n_envs": 2, "policy_kwargs.net_arch": [16]})
    assert out["env_kwargs"]["action_level"] == "force"
    assert out["env_kwargs"]["init_noise"] == cfg["env_kwargs"]["init_noise"]  # siblings kept
    assert out["n_envs"] == 2
    assert out["policy_kwargs"] == {"net_arch": [16], "activation_fn": "tanh"}
    assert cfg["env_kwargs"]["action_level"] == "speed"  # the input is not modified
    deep = apply_overrides({}, {"env_kwargs.gains.k_u": 0.7})
    assert deep == {"env_kwargs": {"gains": {"k_u": 0.7}}}
    with pytest.raises(TrainConfigError, match="n_envs"):
        apply_overrides(cfg, {"n_envs.x": 1})
    assert validate(out)["env_kwargs"]["action_level"] == "force"


def test_train_main_rejects_unknown_set_key(tmp_path, capsys):
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as exc:
        train_module.main(["--config", str(SPEED_CONFIG), "--set", "n_stepz=64", "--out", str(out), "--quiet"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "n_stepz" in err and "error" in err
    assert not (out / "config.yaml").exists()


def test_train_main_rejects_unknown_env_kwargs_set(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        train_module.main(
            [
                "--config",
                str(SPEED_CONFIG),
                "--set",
                "n_timesteps=1000",
                "--set",
                "env_kwargs.wind=3",
                "--out",
                str(tmp_path / "r"),
                "--quiet",
            ]
        )
    assert exc.value.code == 2
    assert "wind" in capsys.readouterr().err


def test_train_main_requires_config(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        train_module.main(["--out", str(tmp_path / "r")])
    assert exc.value.code == 2
    assert "--config" in capsys.readouterr().err


def test_transmit_bias_starts_the_transmit_mean_there_and_needs_the_transmit_entry():
    raw = {**base_config(), "scenario": "paper_budget", "transmit_bias": 2.0}
    raw["env_kwargs"] = {**raw["env_kwargs"], "action_level": "speed", "transmit": True}
    resolved = validate(raw)
    venv = train_module.build_env(resolved, 0)
    try:
        model = train_module.build_model(resolved, venv, 0)
        obs = np.zeros((4, venv.observation_space.shape[0]), dtype=np.float32)
        mean = model.policy.get_distribution(model.policy.obs_to_tensor(obs)[0]).distribution.mean
        # SB3 starts its action layer with gain 0.01 and a zero bias: the speed entry's mean near 0, the
        # transmit entry's at the bias
        np.testing.assert_allclose(mean[:, -1].detach().numpy(), 2.0, atol=0.05)
        assert float(mean[:, 0].abs().max()) < 0.05
    finally:
        venv.close()
    with pytest.raises(TrainConfigError, match=r"transmit_bias = 2\.0 sets the transmit entry's initial mean, but"):
        validate({**base_config(), "transmit_bias": 2.0})
    with pytest.raises(TrainConfigError, match="transmit_bias must be a number or null, got 'high'"):
        validate({**raw, "transmit_bias": "high"})


def test_the_evaluation_callback_scores_the_reference_by_the_channel_s_rule_where_the_policy_transmits(tmp_path):
    from baselines.reference import rule_broadcasting
    from training.callbacks import ReferenceEvalCallback

    kwargs = {"action_level": "speed", "transmit": True, "horizon": 10.0}
    callback = ReferenceEvalCallback("paper_budget", kwargs, eval_freq=0, episodes=1, out_dir=tmp_path)
    assert callback.env.config.transmit  # the learned policy's env keeps the transmit action ...
    periodic = rule_broadcasting(callback.env.config)  # ... the reference's broadcasts by the budget's rule
    assert not periodic.transmit and periodic.channel == callback.env.config.channel
    assert callback.reference["message_rate"]["mean"] > 0.0  # it sent its messages


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_shipped_config_validates(path):
    # what `python -m training.train --config <path>` does first
    validate(load_config(path))


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_shipped_config_builds_its_algorithm_without_warnings(path):
    raw = load_config(path)
    # YAML 1.1 reads `3.0e6` as a string (test_shipped_config_validates); read it as the number it means here
    raw["n_timesteps"] = int(float(raw["n_timesteps"]))
    resolved = validate(raw)
    venv = train_module.build_env(resolved, 0)  # every team of the config (``teams``), as training builds it
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        algo_class(resolved["algo"])(resolved["policy"], venv, device="cpu", **algo_kwargs(resolved))
    # e.g. PPO warns when batch_size does not divide n_steps · (vessel entries)
    assert [str(w.message) for w in caught] == []


# =========================================================================== (c) end-to-end smoke run

SMOKE_ARGS = [
    "--config",
    str(SPEED_CONFIG),
    "--set",
    "n_timesteps=600",
    "--set",
    "n_envs=2",
    "--set",
    "n_steps=64",
    "--set",
    "batch_size=128",
    "--set",
    "eval_freq=300",
    "--set",
    "eval_episodes=1",
    "--set",
    "checkpoint_freq=300",
    "--set",
    "env_kwargs.horizon=20.0",
    "--seed",
    "0",
    "--quiet",
]


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    torch.set_num_threads(1)
    run = tmp_path_factory.mktemp("train") / "run"
    assert train_module.main([*SMOKE_ARGS, "--out", str(run)]) == 0
    return run


def test_smoke_run_writes_the_run_folder(smoke_run):
    for name in ("model.zip", "vecnormalize.pkl", "config.yaml", "evaluations.csv", "progress.csv", "evaluation.json"):
        assert (smoke_run / name).is_file(), name
    stored = yaml.safe_load((smoke_run / "config.yaml").read_text())
    assert list(stored)[:3] == ["trainer", "env_id", "seed"]
    assert stored["trainer"] == "sb3" and stored["env_id"] == ENV_ID
    cfg = {k: v for k, v in stored.items() if k not in ("trainer", "env_id")}
    assert cfg["seed"] == 0
    assert cfg["n_timesteps"] == 600 and cfg["n_envs"] == 2 and cfg["n_steps"] == 64
    assert cfg["env_kwargs"]["horizon"] == 20.0 and cfg["env_kwargs"]["action_level"] == "speed"
    # the stored config is itself a valid config (seed aside)
    validate({k: v for k, v in cfg.items() if k != "seed"})
    checkpoints = sorted((smoke_run / "checkpoints").glob("model_*_steps.zip"))
    assert checkpoints, "no checkpoints"
    for ckpt in checkpoints:
        steps = ckpt.stem.split("_")[1]
        assert (smoke_run / "checkpoints" / f"model_vecnormalize_{steps}_steps.pkl").is_file()
    model = PPO.load(smoke_run / "model.zip", device="cpu")
    assert model.num_timesteps >= 600
    assert model.observation_space.shape == (10 + 4 * 2,)
    assert model.action_space.shape == (1,)


def test_smoke_run_logs_its_learning_curve(smoke_run):
    with (smoke_run / "progress.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    # 2 formations × 3 vessels = 6 entries × 64 steps per rollout; 600 vessel-steps take 2 rollouts
    assert [int(r["vessel_steps"]) for r in rows] == [384, 768]
    # episodes of 20 s / 0.5 s = 40 steps end at steps 40 (rollout 1: 6 of them), 80 and 120 (rollout 2: 12)
    assert [int(r["episodes"]) for r in rows] == [6, 12]
    returns = [float(r["episode_return_mean"]) for r in rows]
    assert all(-40.0 * 10.0 < value < 0.0 for value in returns)  # every per-step cost lies in (0, 10]
    assert float(rows[0]["wall_time_s"]) < float(rows[1]["wall_time_s"])
    assert list(rows[0]) == ["vessel_steps", "wall_time_s", "episode_return_mean", "episodes"]


def test_smoke_run_reports_its_final_policy_on_the_evaluation_seeds(smoke_run):
    summary = json.loads((smoke_run / "evaluation.json").read_text())
    assert summary["seeds"] == [EVALUATION_SEED]  # eval_episodes=1
    assert summary["vessel_steps"] == 768 and summary["wall_time_s"] > 0
    env = marine_formation_env.parallel_env(
        "paper", action_level="speed", init_noise={"x": 40.0, "y": 20.0, "psi": 0.3, "u": 1.0}, horizon=20.0
    )
    assert summary["reference_returns"][0] == pytest.approx(manual_return(env, ReferencePolicy(env), EVALUATION_SEED))
    policy, _ = load_learned_policy(smoke_run)
    assert summary["learned_returns"][0] == pytest.approx(manual_return(env, policy, EVALUATION_SEED), rel=1e-9)


def test_smoke_run_evaluations_against_reference(smoke_run):
    with (smoke_run / "evaluations.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) >= 1
    for key in ("timesteps", "return_learned", "return_reference", "return_ratio"):
        assert key in rows[0]
    assert [int(r["timesteps"]) for r in rows] == sorted(int(r["timesteps"]) for r in rows)
    assert int(rows[0]["timesteps"]) >= 300
    # the reference's return on the first evaluation seed, by a hand-written loop
    env = marine_formation_env.parallel_env(
        "paper", action_level="speed", init_noise={"x": 40.0, "y": 20.0, "psi": 0.3, "u": 1.0}, horizon=20.0
    )
    expected = manual_return(env, ReferencePolicy(env), EVAL_SEED)
    for row in rows:
        assert float(row["return_reference"]) == pytest.approx(expected, rel=1e-9)
        assert float(row["return_ratio"]) == pytest.approx(expected / float(row["return_learned"]), rel=1e-9)


def test_load_learned_policy_acts_inside_action_space(smoke_run):
    policy, config = load_learned_policy(smoke_run / "model.zip")
    assert isinstance(policy, ModelPolicy)
    assert policy.normalizer is not None and policy.normalizer.training is False
    assert config["env_kwargs"]["horizon"] == 20.0
    env = marine_formation_env.parallel_env(config["scenario"], **config["env_kwargs"])
    obs, _ = env.reset(seed=5)
    steps = 0
    while env.agents:
        actions = policy.act(obs)
        assert set(actions) == set(env.agents)
        for agent, action in actions.items():
            assert env.action_space(agent).contains(np.asarray(action, dtype=np.float32)), action
        assert policy.act(obs).keys() == actions.keys()
        for agent in actions:  # deterministic by default
            np.testing.assert_array_equal(policy.act(obs)[agent], actions[agent])
        obs, *_ = env.step(actions)
        steps += 1
    assert steps == env.config.max_steps
    # the run folder itself and a checkpoint load too
    assert isinstance(load_learned_policy(smoke_run)[0], ModelPolicy)
    ckpt = sorted((smoke_run / "checkpoints").glob("model_*_steps.zip"))[0]
    ckpt_policy, _ = load_learned_policy(ckpt)
    assert ckpt_policy.normalizer is not None


def test_evaluate_reference_and_model_same_seeds(smoke_run, tmp_path, capsys):
    from baselines import evaluate

    model_path = str(smoke_run / "model.zip")
    out_json, plot = tmp_path / "cmp.json", tmp_path / "cmp.png"
    code = evaluate.main(
        ["--policy", "reference", "--policy", model_path, "--episodes", "1", "--json", str(out_json),
         "--plot", str(plot), "--quiet"]
    )  # fmt: skip
    assert code == 0
    report = json.loads(out_json.read_text())
    assert set(report["policies"]) == {"reference", model_path}
    seeds = {label: [ep["seed"] for ep in r["episodes"]] for label, r in report["policies"].items()}
    assert seeds["reference"] == seeds[model_path] == [0]
    # the model brings its training env: 20 s episodes at the speed level
    assert report["config"]["horizon"] == 20.0
    assert report["config"]["action_level"] == "speed"
    # returns agree with hand-written loops on seed 0
    env = marine_formation_env.parallel_env(
        "paper", action_level="speed", init_noise={"x": 40.0, "y": 20.0, "psi": 0.3, "u": 1.0}, horizon=20.0
    )
    ref_return = report["policies"]["reference"]["episodes"][0]["return"]
    assert ref_return == pytest.approx(manual_return(env, ReferencePolicy(env), 0), rel=1e-9)
    learned, _ = load_learned_policy(model_path)
    model_return = report["policies"][model_path]["episodes"][0]["return"]
    assert model_return == pytest.approx(manual_return(env, learned, 0), rel=1e-9)
    # the comparison figure and one figure per policy
    for path in (plot, tmp_path / "cmp_0_reference.png", tmp_path / "cmp_1_run.png"):
        assert path.is_file(), path
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a plain MLP reads its training team's observation length only: another team is refused by name
    with pytest.raises(SystemExit) as refused:
        evaluate.main(["--policy", model_path, "--set", "n_vessels=4", "--set", "topology=ring", "--quiet"])
    assert refused.value.code == 2
    assert re.search(r"expects observations of size 18 .* this scenario has 22 .* n_vessels 4", capsys.readouterr().err)
    with pytest.raises(ValueError, match="this policy reads observations of size 18, got 22"):
        learned.act_batch(np.zeros((4, 22), dtype=np.float32))


def test_resume_continues_from_last_checkpoint(smoke_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    before = PPO.load(run / "model.zip", device="cpu").num_timesteps
    last = max(int(p.stem.split("_")[1]) for p in (run / "checkpoints").glob("model_*_steps.zip"))
    capsys.readouterr()
    assert train_module.main(["--resume", "--out", str(run), "--set", "n_timesteps=1200", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert f"model_{last}_steps.zip" in err and f"at {last} steps" in err
    after = PPO.load(run / "model.zip", device="cpu").num_timesteps
    assert after >= 1200 and after > before
    assert max(int(p.stem.split("_")[1]) for p in (run / "checkpoints").glob("model_*_steps.zip")) > last
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    assert cfg["trainer"] == "sb3" and cfg["seed"] == 0 and cfg["n_timesteps"] == 1200
    assert cfg["env_kwargs"]["horizon"] == 20.0  # the stored run config is kept


def test_new_run_into_existing_folder_is_refused(smoke_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    config_before = (run / "config.yaml").read_bytes()
    model_before = (run / "model.zip").read_bytes()
    with pytest.raises(SystemExit) as exc:
        train_module.main([*SMOKE_ARGS, "--out", str(run)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--resume" in err and str(run) in err
    assert (run / "config.yaml").read_bytes() == config_before
    assert (run / "model.zip").read_bytes() == model_before


def test_resume_without_a_run_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        train_module.main(["--resume", "--out", str(tmp_path / "nothing"), "--quiet"])
    assert exc.value.code == 2
    assert "config.yaml" in capsys.readouterr().err


# =========================================================================== (d) curriculum over the initial state


def test_a_zero_spread_starts_every_formation_in_formation_on_its_lanes():
    # truth: spread 0 is the formation on its lanes (each vessel on its lane, aligned with the path, coordinated),
    # its noise scaled to 0 too; the paper's own start is 20-40 m off
    venv = SharedPolicyVecEnv(3, "paper", action_level="speed", init_noise={"x": 40.0, "y": 20.0, "psi": 0.3})
    venv.seed(7)
    first = venv.reset()
    assert np.abs(first[:, 0]).max() > 10.0  # cross-track error [m] of the scenario's start
    venv.set_initial_spread(0.0)
    venv.seed(7)
    obs = venv.reset()
    own, slots = obs[:, :10], obs[:, 10:].reshape(len(obs), -1, 4)
    np.testing.assert_allclose(own[:, :2], 0.0, atol=1e-9)  # e [m] and ψ relative to the path [rad]
    np.testing.assert_allclose(slots[..., 1], 0.0, atol=1e-9)  # Δθ to every neighbour heard [m]


def test_sb3_training_follows_the_curriculum_over_its_budget(tmp_path, monkeypatch):
    spreads = record_calls(monkeypatch, SharedPolicyVecEnv, "set_initial_spread")
    args = [*SMOKE_ARGS, "--set", "n_timesteps=768", "--set", "eval_freq=0", "--set", "checkpoint_freq=0"]
    args += ["--set", "initial_state_curriculum={'start': 0.2, 'until': 1.0}", "--out", str(tmp_path / "run")]
    assert train_module.main(args) == 0
    # 2 formations x 3 vessels x 64 steps = 384 vessel-steps per rollout, two rollouts of the 768: set before
    # learn() resets (0.2), before the first rollout (0 used: 0.2), before the second (half used: 0.2 + 0.8 * 0.5)
    assert spreads == pytest.approx([0.2, 0.2, 0.6])
    recorded = yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())
    assert recorded["initial_state_curriculum"] == {"start": 0.2, "until": 1.0}


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"start": 2, "until": 0.5}, "initial_state_curriculum.start must lie in [0, 1], got 2"),
        ({"start": 0.1, "until": 0}, "initial_state_curriculum.until must lie in (0, 1], got 0"),
        ({"start": 0.1}, "initial_state_curriculum must be null or a mapping with the keys start and until"),
    ],
)
def test_validate_rejects_a_bad_curriculum_by_name(value, message):
    with pytest.raises(TrainConfigError) as err:
        validate({**base_config(), "initial_state_curriculum": value})
    assert message in str(err.value)


def test_the_curriculum_counts_wall_time_when_the_budget_is_minutes():
    from training.callbacks import InitialStateCurriculum

    callback = InitialStateCurriculum({"start": 0.0, "until": 0.5}, total_steps=10**9, seconds=100.0)
    callback.start -= 25.0  # a quarter of the 100 s spent, no steps: half of the curriculum's 50 %
    assert callback.spread() == pytest.approx(0.5, abs=0.01)
    callback.start -= 100.0
    assert callback.spread() == 1.0


def test_a_linear_learning_rate_falls_over_whichever_budget_runs_out_first():
    from training.callbacks import BudgetSchedule

    def linear(progress_remaining):
        return 1e-3 * progress_remaining

    # 60 of 100 s spent: the clock has used more than 10 % of the steps, so the rate is 1e-3 · 0.4
    schedule = BudgetSchedule(linear, seconds=100.0, start=time.perf_counter() - 60.0)
    assert schedule(0.9) == pytest.approx(4e-4, abs=1e-6)  # 1 ms of the clock moves it by 1e-8
    assert schedule(0.2) == pytest.approx(2e-4, abs=1e-6)  # 80 % of the steps used: the steps ran out first
    assert BudgetSchedule(linear, 100.0, time.perf_counter() - 250.0)(1.0) == 0.0  # past the budget: floored at 0
    assert BudgetSchedule(lambda _: 3e-4, 100.0, time.perf_counter() - 60.0)(0.9) == 3e-4  # constant stays


def test_training_with_minutes_puts_the_learning_rate_on_the_budget_once(tmp_path):
    from training.callbacks import BudgetSchedule, LearningRateBudget

    resolved = validate({**base_config(), "n_timesteps": 384, "n_envs": 2, "n_steps": 64, "batch_size": 64,
                         "eval_freq": 0, "checkpoint_freq": 0, "learning_rate": "lin_1e-3"})  # fmt: skip
    model = train_module.train(resolved, tmp_path / "run", seed=0, progress=False, minutes=10.0)
    assert isinstance(model.lr_schedule, BudgetSchedule) and model.lr_schedule.seconds == 600.0
    # one rollout of 2 x 3 x 64 = 384 vessel-steps, in far less than 10 minutes: the steps ran out first,
    # so the update ran at SB3's own linear rate at progress 0 (all steps used)
    # (the clock keeps running after training, through the closing evaluation: bound it on both sides)
    schedule = model.lr_schedule
    before = time.perf_counter()
    rate = schedule(1.0)
    after = time.perf_counter()
    assert schedule(0.0) == 0.0
    assert 1e-3 * (1 - (after - schedule.start) / 600.0) <= rate <= 1e-3 * (1 - (before - schedule.start) / 600.0)
    assert after - schedule.start < 60.0  # the run itself took far less than its 10 minutes
    again = LearningRateBudget(60.0)
    again.model = model
    again._on_training_start()  # a resumed run: re-wrapped around the original schedule, not nested
    assert not isinstance(model.lr_schedule.schedule, BudgetSchedule) and model.lr_schedule.seconds == 60.0
