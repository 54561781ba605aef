"""``python -m training.torchrl_ppo``: TorchRL's multi-agent PPO loop on the batched TorchRL env.

Truth: TorchRL's own deterministic action of the saved actor (the
distribution's mode, ``ExplorationType.DETERMINISTIC``), which the batch
policy used for evaluation must reproduce; the files the module docstring
promises; one-line CLI errors naming the bad value.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import record_calls

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from tensordict import TensorDict  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type  # noqa: E402

import training.torchrl_config as torchrl_config  # noqa: E402
import training.torchrl_networks as networks  # noqa: E402
import training.torchrl_ppo as trainer  # noqa: E402
from marine_formation_env import ENV_ID  # noqa: E402
from marine_formation_env.scenarios import make_config  # noqa: E402
from marine_formation_env.settings import TRACKING_TERMS  # noqa: E402
from training.config import load_config, training_env_kwargs  # noqa: E402
from training.learned import load_learned_policy  # noqa: E402
from training.torchrl_config import resolve  # noqa: E402
from training.torchrl_networks import load_torch_policy, running_norm  # noqa: E402
from training.torchrl_ppo import RewardScaler, main  # noqa: E402

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)

HEADER = (
    "vessel_steps,wall_time_s,episode_return_mean,episodes,frames,mean_reward,learning_rate,kl,updates,initial_spread"
)
#: A small actor of 3 vessels: keyword arguments of ``policy_network`` beside the sizes.
SMALL = {"n_agents": 3, "hidden": [16], "distribution": "normal", "initial_scale": 0.3}
TINY = [
    "n_envs=4",
    "frames_per_batch=40",
    "total_frames=80",
    "minibatch_size=20",
    "n_epochs=1",
    "eval_episodes=2",
    "hidden=[16]",
    "env_kwargs.horizon=4.0",
    "env_kwargs.init_noise={'x': 10.0}",
]


@pytest.mark.parametrize(
    ("algo", "distribution", "scale", "action_scale"),
    [
        ("mappo", "tanh_normal", "state_dependent", 1.0),
        ("ippo", "tanh_normal", "state_dependent", 1.0),
        ("mappo", "normal", "state_dependent", 1.0),
        ("mappo", "normal", "state_independent", 1.0),
        ("mappo", "normal", "state_independent", 0.05),
    ],
)
def test_two_iterations_write_a_loadable_policy_that_acts_like_torchrl_s_deterministic_actor(
    tmp_path, algo, distribution, scale, action_scale
):
    out = tmp_path / algo
    args = [
        "--seed",
        "3",
        "--out",
        str(out),
        "--no-progress",
        "--set",
        f"algo={algo}",
        "--set",
        f"distribution={distribution}",
        "--set",
        f"scale={scale}",
        "--set",
        f"action_scale={action_scale}",
        "--set",
        "env_kwargs.action_level=speed",
    ]
    for item in TINY:
        args += ["--set", item]
    assert main(args) == 0
    progress = (out / "progress.csv").read_text().splitlines()
    assert progress[0] == HEADER and len(progress) == 3  # two iterations
    summary = json.loads((out / "evaluation.json").read_text())
    assert summary["vessel_steps"] == 240 and summary["seeds"] == [10_000, 10_001]
    assert int(progress[-1].split(",")[4]) == 80  # frames
    assert np.isfinite(summary["learned_return"]) and summary["learned_return"] < 0
    assert summary["reference_return"] < 0
    policy, config = load_torch_policy(out)
    assert config["algo"] == algo and config["seed"] == 3 and config["scale"] == scale
    record = yaml.safe_load((out / "config.yaml").read_text())
    assert (
        record["trainer"] == "torchrl" and {k: v for k, v in record.items() if k not in ("trainer", "env_id")} == config
    )
    loaded, run_config = networks.load_torchrl_run(out)
    assert run_config == record and isinstance(load_learned_policy(out)[0], type(loaded))
    assert config["action_scale"] == action_scale
    obs = np.random.default_rng(0).uniform(-5, 5, (6, 3, policy.observation_dim)).astype(np.float32)
    mine = policy.act_batch(obs)
    assert mine.shape == (6, 3, 1) and np.all(np.abs(mine) <= 1.0)
    td = TensorDict({("vessel", "observation"): torch.from_numpy(obs.reshape(18, 1, -1))}, batch_size=[18])
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        theirs = policy.actor(td)["vessel", "action"].numpy().reshape(6, 3, 1)
    if distribution == "normal":  # TorchRL's mode is the Gaussian's mean; the env clips it, and so does the policy
        theirs = np.clip(theirs, -1.0, 1.0)
    np.testing.assert_allclose(mine, theirs, rtol=1e-5, atol=1e-6)  # float32 tanh of the same loc


def test_baselines_evaluate_loads_the_run_folder_next_to_the_reference(tmp_path):
    out = tmp_path / "run"
    config = tmp_path / "config.yaml"
    config.write_text(f"{ENV_ID}:\n  algo: ippo\n  env_kwargs: {{action_level: speed}}\n")
    args = ["--config", str(config), "--out", str(out), "--no-progress"]
    for item in TINY:
        args += ["--set", item]
    assert main(args) == 0
    report = tmp_path / "report.json"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "baselines.evaluate",
            "--policy",
            "reference",
            "--policy",
            str(out),
            "--episodes",
            "2",
            "--seed",
            "10000",
            "--json",
            str(report),
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    data = json.loads(report.read_text())
    assert set(data["policies"]) == {"reference", str(out)}
    learned = json.loads((out / "evaluation.json").read_text())
    # the evaluation at the end of training used the same seeds (10 000, 10 001) and the same engine; the two
    # processes run the float32 network with different torch thread counts (training sets 1), so its sums may
    # round in another order: 1e-9 relative was seen on one machine, while another policy or seed moves the
    # return by percents
    assert data["policies"][str(out)]["summary"]["return"]["mean"] == pytest.approx(learned["learned_return"], rel=1e-6)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("algo=dqn", "algo must be one of ['mappo', 'ippo'], got 'dqn'"),
        ("n_epochs=0", "n_epochs must be a whole number ≥ 1, got 0"),
        ("gamma=1.5", "gamma must lie in [0, 1], got 1.5"),
        ("hidden=fish", "hidden must be a non-empty list of whole numbers ≥ 1, got 'fish'"),
        ("frames_per_batch=100", "frames_per_batch = 100 must be a multiple of n_envs = 64"),
        ("colour=1", "unknown key(s) ['colour']"),
        ("env_kwargs.frameskip=4", "unexpected keyword argument 'frameskip'"),
        ("normalize_observations=1", "normalize_observations must be true or false, got 1"),
        ("normalize_advantage=maybe", "normalize_advantage must be true or false, got 'maybe'"),
        ("normalize_reward=0.5", "normalize_reward must be true or false, got 0.5"),
        ("drop_inputs=age", "drop_inputs must be a list of observation entry names, got 'age'"),
        ("drop_inputs=['speed']", "drop_inputs must name distinct entries of ['cross_track_error'"),
        ("drop_inputs=['age', 'age']", "(repeated)"),
        ("threads=0", "threads must be a whole number ≥ 1, got 0"),
        ("distribution=beta", "distribution must be one of ['tanh_normal', 'normal'], got 'beta'"),
        ("learning_rate=cosine", "learning_rate must be a number or 'lin_<number>', got 'cosine'"),
        ("learning_rate=0", "learning_rate must be > 0, got 0"),
        ("lr=1e-3", "the key 'lr' is now 'learning_rate'"),
        ("num_envs=8", "the key 'num_envs' is now 'n_envs'"),
        ("lmbda=0.9", "the key 'lmbda' is now 'gae_lambda'"),
        ("clip_epsilon=0.1", "the key 'clip_epsilon' is now 'clip_range'"),
        ("entropy_coef=0.0", "the key 'entropy_coef' is now 'ent_coef'"),
        ("epochs=2", "the key 'epochs' is now 'n_epochs'"),
        (
            "lr_schedule=linear",
            "the key 'lr_schedule' is now 'learning_rate' (a linear schedule is learning_rate: lin_",
        ),
        ("target_kl=-0.01", "target_kl must be > 0, got -0.01"),
        ("initial_scale=0", "initial_scale must be > 0, got 0"),
        ("scale=fixed", "scale must be one of ['state_dependent', 'state_independent'], got 'fixed'"),
        ("inputs=scaled", "inputs must be one of ['raw', 'predicted'], got 'scaled'"),
        ("action_head_gain=-1", "action_head_gain must be > 0, got -1"),
        ("action_scale=0", "action_scale entries must be numbers in (0, 1], got 0"),
        ("action_scale=[2]", "action_scale entries must be numbers in (0, 1], got [2]"),
        ("action_scale=[0.1, 0.2, 0.3]", "action_scale has 3 entries, the action has"),
        ("action_scale=0.5", "action_scale 0.5 needs distribution: normal"),
        ("train_reward=[1]", "train_reward must be a mapping of reward fields, got [1]"),
        ("train_reward.sigma_x=1", "unknown reward key(s) ['sigma_x']"),
        ("train_reward.sigma_coordination=0", "reward.sigma_coordination must be a finite number > 0, got 0"),
        (
            "initial_state_curriculum={'start': 2, 'until': 0.5}",
            "initial_state_curriculum.start must lie in [0, 1], got 2",
        ),
        (
            "initial_state_curriculum={'start': 0.1, 'until': 0}",
            "initial_state_curriculum.until must lie in (0, 1], got 0",
        ),
        ("initial_state_curriculum={'start': 0.1}", "initial_state_curriculum must be null or a mapping with the keys"),
        ("train_dt=0", "train_dt must be > 0, got 0"),
        ("train_dt=1000", "train_dt = 1000.0: horizon = 400.0 s must be at least one control period dt = 1000.0 s"),
    ],
)
def test_bad_configs_are_refused_in_one_line(tmp_path, capsys, item, message):
    with pytest.raises(SystemExit) as stop:
        main(["--out", str(tmp_path / "x"), "--set", item])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_train_reward_shapes_only_what_the_learner_sees(tmp_path):
    # every weight 0 and no terminal penalty: the learner's reward is exactly 0 at every step, while the
    # closing evaluation (and the saved env_kwargs) keep the benchmark's reward, which is < 0 for any policy
    out = tmp_path / "shaped"
    args = ["--out", str(out), "--no-progress", "--set", "env_kwargs.action_level=speed"]
    for item in [*TINY, *(f"train_reward.{k}=0.0" for k in TRACKING_TERMS)]:
        args += ["--set", item]
    assert main([*args, "--set", "train_reward.terminal_penalty=false"]) == 0
    rows = (out / "progress.csv").read_text().splitlines()[1:]
    assert rows and all(float(row.split(",")[5]) == 0.0 for row in rows)  # mean_reward
    summary = json.loads((out / "evaluation.json").read_text())
    assert summary["learned_return"] < 0 and summary["reference_return"] < 0
    _, config = load_torch_policy(out)
    assert "reward" not in config["env_kwargs"] and config["train_reward"]["coordination"] == 0.0
    assert training_env_kwargs(config)["reward"]["speed"] == 0.0


def test_a_used_run_folder_needs_overwrite(tmp_path, capsys):
    (tmp_path / "policy.pt").write_bytes(b"")
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path)])
    assert "pass --overwrite" in capsys.readouterr().err


def test_resolve_fills_defaults_and_keeps_the_seed():
    cfg = resolve({"scenario": "acoustic"}, seed=5)
    assert cfg["seed"] == 5 and cfg["algo"] == "mappo" and cfg["n_envs"] == 64 and cfg["threads"] == 1
    assert resolve({"threads": None}, seed=0)["threads"] is None  # torch's default


def test_training_sets_torch_s_threads_from_the_config(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(torch, "set_num_threads", calls.append)
    args = [
        "--out",
        str(tmp_path / "run"),
        "--no-progress",
        "--set",
        "threads=2",
        "--set",
        "env_kwargs.action_level=speed",
    ]
    for item in TINY:
        args += ["--set", item]
    assert main(args) == 0
    assert calls == [2]


def test_a_run_saves_its_policy_and_progress_during_training_not_only_at_the_end(tmp_path, monkeypatch):
    # with the save interval at 0 s every iteration saves: the first save holds one iteration's row and a policy
    # that loads; the last (after training) holds both iterations
    saves: list[tuple[int, bool]] = []
    save = trainer._save

    def spy(out, *args):
        save(out, *args)
        saves.append((len((out / "progress.csv").read_text().splitlines()) - 1, (out / networks.POLICY_FILE).is_file()))
        load_torch_policy(out)

    monkeypatch.setattr(trainer, "SAVE_SECONDS", 0.0)
    monkeypatch.setattr(trainer, "_save", spy)
    args = ["--out", str(tmp_path / "run"), "--no-progress", "--set", "env_kwargs.action_level=speed"]
    for item in TINY:
        args += ["--set", item]
    assert main(args) == 0
    assert saves[0] == (1, True) and saves[-1] == (2, True)


def test_the_linear_schedule_falls_to_zero_over_whichever_budget_runs_out_first():
    cfg = resolve({"learning_rate": "lin_1e-3", "total_frames": 1000, "minutes": 10}, seed=0)
    assert torchrl_config.learning_rate(cfg, 0.0, 0) == 1e-3
    assert torchrl_config.learning_rate(cfg, 150.0, 100) == pytest.approx(0.75e-3)  # a quarter of the 600 s used
    assert torchrl_config.learning_rate(cfg, 60.0, 500) == pytest.approx(0.5e-3)  # half of the frames used
    assert torchrl_config.learning_rate(cfg, 900.0, 0) == 0.0  # past the budget: floored, never negative
    frames_only = resolve({"learning_rate": "lin_1e-3", "total_frames": 1000}, seed=0)
    assert torchrl_config.learning_rate(frames_only, 1e6, 250) == pytest.approx(0.75e-3)
    assert torchrl_config.learning_rate(resolve({"learning_rate": 1e-3}, seed=0), 1e6, 10**9) == 1e-3  # constant


def test_the_linear_schedule_and_the_kl_stop_are_applied_and_logged(tmp_path):
    out = tmp_path / "run"
    args = ["--out", str(out), "--no-progress", "--set", "env_kwargs.action_level=speed"]
    # two iterations of two minibatch updates per epoch, 3 epochs: without a stop, 6 updates each
    for item in [*TINY, "n_epochs=3", "learning_rate=lin_1e-3", "target_kl=1e-5"]:
        args += ["--set", item]
    assert main(args) == 0
    rows = (out / "progress.csv").read_text().splitlines()
    assert rows[0] == HEADER
    lr = [float(r.split(",")[6]) for r in rows[1:]]
    updates = [int(r.split(",")[8]) for r in rows[1:]]
    assert lr[0] == 1e-3 and lr[1] == pytest.approx(0.5e-3)  # the second iteration starts half-way (40 of 80 frames)
    # the first minibatch meets the policy that collected the batch (KL 0 but for float rounding, far below the
    # limit of 1.5e-5) and is stepped on; a step at this rate moves the log-probabilities by far more than the
    # limit, so a later minibatch stops the epochs before its own step
    assert all(1 <= u < 6 for u in updates), updates


def test_train_dt_is_the_learner_s_control_period_and_the_evaluation_keeps_the_scenario_s(tmp_path):
    # horizon 4 s, 10 steps per formation per iteration: at the speed level's 0.5 s each of the 4 formations
    # ends one episode per iteration (after 8 decisions); at train_dt = 2 s each ends five (2 decisions each)
    counts = {}
    for name, extra in (("own", []), ("coarse", ["train_dt=2.0"])):
        out = tmp_path / name
        args = ["--out", str(out), "--no-progress", "--set", "env_kwargs.action_level=speed"]
        for item in [*TINY, *extra]:
            args += ["--set", item]
        assert main(args) == 0
        rows = (out / "progress.csv").read_text().splitlines()[1:]
        counts[name] = [int(float(row.split(",")[3])) for row in rows]  # episodes
        _, config = load_torch_policy(out)
        assert "dt" not in config["env_kwargs"]  # the evaluation's scenario is the benchmark's
        summary = json.loads((out / "evaluation.json").read_text())
        assert summary["reference_return"] < 0
    assert counts == {"own": [12, 12], "coarse": [60, 60]}  # the log counts each of the 3 vessels' episodes
    cfg = resolve({"train_dt": 0.5, "env_kwargs": {"action_level": "force"}}, seed=0)
    assert torchrl_config.learner_env_kwargs(cfg)["dt"] == 0.5 and "dt" not in cfg["env_kwargs"]
    assert "dt" not in torchrl_config.learner_env_kwargs(resolve({}, seed=0))


def test_the_initial_state_curriculum_reaches_the_training_env_and_is_logged(tmp_path, monkeypatch):
    from marine_formation_env.torchrl import MarineFormationTorchEnv

    scales = record_calls(monkeypatch, MarineFormationTorchEnv, "set_initial_spread")
    out = tmp_path / "run"
    args = ["--out", str(out), "--no-progress", "--set", "env_kwargs.action_level=speed"]
    for item in [*TINY, "initial_state_curriculum={'start': 0.2, 'until': 1.0}"]:
        args += ["--set", item]
    assert main(args) == 0
    # 80 frames in two iterations of 40: 0.2 before the first, 0.2 + 0.8 * 0.5 after it, 1 after the second
    assert scales == pytest.approx([0.2, 0.6, 1.0])
    rows = (out / "progress.csv").read_text().splitlines()[1:]
    assert [float(row.split(",")[9]) for row in rows] == pytest.approx([0.6, 1.0])
    cfg = resolve({"total_frames": 1000, "initial_state_curriculum": {"start": 0.0, "until": 0.5}}, seed=0)
    assert torchrl_config.initial_spread(cfg, 0.0, 100) == pytest.approx(0.2)  # 10 % of the budget of 50 %
    assert torchrl_config.initial_spread(cfg, 0.0, 800) == 1.0  # the scenario's from half the budget on
    assert torchrl_config.initial_spread(resolve({}, seed=0), 0.0, 0) == 1.0  # no curriculum: the scenario's


@pytest.mark.parametrize("distribution", ["normal", "tanh_normal"])
def test_initial_scale_is_the_exploration_deviation_where_the_network_outputs_zero(distribution):
    # with every weight of the MLP zeroed its output is 0: the Gaussian's deviation must be exactly the configured one
    actor = networks.policy_network(7, 2, hidden=[8], distribution=distribution, initial_scale=0.3)
    with torch.no_grad():
        for weight in networks.shared_trunk(actor).parameters():
            weight.zero_()
    out = actor(TensorDict({("vessel", "observation"): torch.randn(5, 1, 7)}, batch_size=[5]))
    torch.testing.assert_close(out["vessel", "scale"], torch.full((5, 1, 2), 0.3))
    torch.testing.assert_close(out["vessel", "loc"], torch.zeros(5, 1, 2))


def test_a_state_independent_scale_starts_at_initial_scale_whatever_the_observation_and_is_learned():
    actor = networks.policy_network(
        7, 2, n_agents=3, hidden=[16], distribution="normal", initial_scale=0.1, scale="state_independent"
    )
    obs = TensorDict({("vessel", "observation"): 30.0 * torch.randn(64, 3, 7)}, batch_size=[64])
    with torch.no_grad():
        scale = actor(obs)["vessel", "scale"]
    torch.testing.assert_close(scale, torch.full((64, 3, 2), 0.1))
    learned = [name for name, p in actor.named_parameters() if "state_independent_scale" in name]
    assert len(learned) == 1  # one log-deviation per action entry, trained with the policy


def _built_alike(options: dict, **variant) -> tuple:
    """Two actors ``(7 inputs, 2 actions)`` from the same seed: ``options``, and ``options`` with ``variant``."""
    torch.manual_seed(5)
    plain = networks.policy_network(7, 2, **options)
    torch.manual_seed(5)
    return plain, networks.policy_network(7, 2, **options, **variant)


def test_action_head_gain_scales_the_output_layer_s_initial_weights_and_zeroes_its_bias():
    # the same seed builds the same hidden layers; only the output layer differs: loc = gain · (W h), W h = loc₀ − b₀
    obs = TensorDict({("vessel", "observation"): 30.0 * torch.randn(64, 3, 7)}, batch_size=[64])
    plain, small = _built_alike(SMALL, action_head_gain=0.01)
    *_, bias = networks.shared_trunk(plain).parameters()
    with torch.no_grad():
        loc_plain, loc_small = plain(obs.clone())["vessel", "loc"], small(obs.clone())["vessel", "loc"]
    torch.testing.assert_close(loc_small, 0.01 * (loc_plain - bias[:2]))
    assert float(loc_small.abs().max()) < 0.05  # the first actions' means are near 0 on any observation


def test_action_scale_turns_the_network_s_gaussian_into_one_in_the_env_s_units():
    # the same seed builds the same network; the scaled actor's mean and deviation are k times the plain one's,
    # per action entry, and nothing of it is learned
    obs = TensorDict({("vessel", "observation"): 30.0 * torch.randn(64, 3, 7)}, batch_size=[64])
    k = torch.tensor([0.2, 0.05])
    plain, scaled = _built_alike(
        {**SMALL, "action_head_gain": 0.01, "scale": "state_independent"}, action_scale=[0.2, 0.05]
    )
    with torch.no_grad():
        a, b = plain(obs.clone()), scaled(obs.clone())
    torch.testing.assert_close(b["vessel", "loc"], k * a["vessel", "loc"])
    torch.testing.assert_close(b["vessel", "scale"], torch.tensor([0.3 * 0.2, 0.3 * 0.05]).expand(64, 3, 2))
    assert [n for n, _ in scaled.named_parameters()] == [n for n, _ in plain.named_parameters()]
    with pytest.raises(ValueError, match="needs distribution 'normal'"):
        networks.policy_network(7, 2, **{**SMALL, "distribution": "tanh_normal"}, action_scale=0.5)


def test_an_unreadable_policy_file_is_named(tmp_path):
    (tmp_path / "policy.pt").write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="cannot load the policy"):
        load_torch_policy(tmp_path)


@pytest.mark.parametrize("path", sorted(Path(__file__).parents[1].glob("training/configs/torchrl/*.yaml")), ids=str)
def test_shipped_torchrl_configs_resolve(path):
    cfg = resolve(load_config(path), seed=0)
    assert cfg["frames_per_batch"] % cfg["n_envs"] == 0
    make_config(cfg["scenario"], **cfg["env_kwargs"])  # the scenario and every override exist


def test_running_norm_statistics_are_numpy_s_mean_and_variance_of_everything_it_was_updated_with():
    """Truth: numpy's weighted mean and (population) variance of all batches concatenated, plus the module's prior
    (mean 0, variance 1, weight 1e-4: the two points ±1 with weight 5e-5 each). Float32 buffers: rtol 1e-5."""
    rng = np.random.default_rng(1)
    norm = running_norm(4)
    seen = [np.ones((1, 4)), -np.ones((1, 4))]
    for rows, shift in [(7, 0.0), (50, 3.0), (1, -2.0), (200, 10.0)]:
        batch = rng.normal(shift, [1.0, 0.1, 5.0, 30.0], (rows, 3, 4)) + np.array([0.0, 100.0, -7.0, 1.0])
        norm.update(torch.from_numpy(batch.astype(np.float32)))
        seen.append(batch.astype(np.float32).reshape(-1, 4))
    every = np.concatenate(seen).astype(np.float64)
    weights = np.r_[5e-5, 5e-5, np.ones(len(every) - 2)]
    mean = np.average(every, axis=0, weights=weights)
    var = np.average((every - mean) ** 2, axis=0, weights=weights)
    np.testing.assert_allclose(norm.mean.numpy(), mean, rtol=1e-5)
    np.testing.assert_allclose(norm.var.numpy(), var, rtol=1e-5)
    assert float(norm.count) == pytest.approx(weights.sum(), rel=1e-12)
    x = torch.from_numpy(every[2:7].astype(np.float32))
    expected = np.clip((every[2:7] - mean) / np.sqrt(var + 1e-8), -10, 10)
    np.testing.assert_allclose(norm(x).numpy(), expected, rtol=1e-4, atol=1e-4)
    assert norm(torch.full((1, 4), 1e6)).max() == 10.0  # clipped


def test_episode_returns_are_the_sums_of_each_vessel_s_rewards_between_done_flags():
    tracker = trainer.EpisodeReturns()
    reward = torch.arange(2 * 3 * 2, dtype=torch.float32).reshape(2, 3, 2, 1)  # 2 formations, 3 steps, 2 vessels
    done = torch.tensor([[False, True, False], [False, False, False]]).unsqueeze(-1)
    # formation 0 ends after its second step: vessels' sums 0 + 2 and 1 + 3
    assert tracker(reward, done) == [2.0, 4.0]
    done = torch.tensor([[True, False, False], [False, False, True]]).unsqueeze(-1)
    # the next batch: formation 0 ends after its first step (its third step of before, 4 and 5, plus 0 and 1);
    # formation 1 after its third step of this batch: the six steps of both batches
    ended = tracker(reward, done)
    assert ended == [4.0 + 0.0, 5.0 + 1.0, 2 * (6.0 + 8.0 + 10.0), 2 * (7.0 + 9.0 + 11.0)]


def test_reward_scaler_divides_by_the_std_of_the_discounted_returns_it_has_seen():
    """Truth: a plain loop over each (formation, vessel) stream, G = γG + r reset after done, carried across two
    batches; numpy's variance of every G. Float32 rewards: rtol 1e-5."""
    rng = np.random.default_rng(2)
    gamma, streams = 0.9, np.zeros((2, 3, 1))
    scaler = RewardScaler(gamma)
    returns, batches = [], []
    for _ in range(2):
        reward = rng.normal(-1.0, 0.5, (2, 6, 3, 1)).astype(np.float32)
        done = rng.random((2, 6, 1)) < 0.25
        for b in range(2):
            for t in range(6):
                streams[b] = gamma * streams[b] + reward[b, t]
                returns.append(streams[b].copy())
                if done[b, t, 0]:
                    streams[b] = 0.0
        batches.append((reward, scaler(torch.from_numpy(reward), torch.from_numpy(done))))
    std = np.sqrt(np.concatenate(returns).var() + 1e-8)
    reward, scaled = batches[-1]  # the last batch is scaled with the statistics of both
    np.testing.assert_allclose(scaled.numpy(), np.clip(reward / std, -10, 10), rtol=1e-5)


def _train_tiny(out, *items):
    """Train TINY at the speed level (seed 1) with these ``--set`` items more; the reloaded policy and config."""
    args = ["--seed", "1", "--out", str(out), "--no-progress", "--set", "env_kwargs.action_level=speed"]
    for item in [*TINY, *items]:
        args += ["--set", item]
    assert main(args) == 0
    return load_torch_policy(out)


def test_a_normalized_run_saves_the_statistics_and_reloads_a_policy_that_acts_like_the_trained_one(
    tmp_path, monkeypatch
):
    trained = {}
    save = trainer._save

    def keep(out, actor, *args):
        trained["actor"] = actor
        save(out, actor, *args)

    monkeypatch.setattr(trainer, "_save", keep)
    out = tmp_path / "run"
    normalized = ("normalize_observations=true", "normalize_advantage=true", "normalize_reward=true")
    policy, config = _train_tiny(out, *normalized)
    assert config["normalize_observations"] and config["normalize_reward"]
    saved, loaded = trained["actor"].module[0].module[0], policy.trunk[0]
    assert float(saved.count) == pytest.approx(240, abs=1e-3)  # every vessel's observation of the 80 frames
    for name in ("mean", "var", "count"):
        torch.testing.assert_close(getattr(loaded, name), getattr(saved, name), rtol=0, atol=0)
    assert not torch.allclose(saved.mean, torch.zeros_like(saved.mean))
    obs = np.random.default_rng(0).uniform(-5, 5, (6, 3, policy.observation_dim)).astype(np.float32)
    td = TensorDict({("vessel", "observation"): torch.from_numpy(obs)}, batch_size=[6])
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        theirs = trained["actor"](td)["vessel", "action"].numpy()
    np.testing.assert_allclose(policy.act_batch(obs), theirs, rtol=1e-5, atol=1e-6)
    from baselines.evaluate import main as evaluate

    report = tmp_path / "report.json"
    evaluate(["--policy", str(out), "--episodes", "2", "--seed", "10000", "--json", str(report), "--quiet"])
    mean = json.loads(report.read_text())["policies"][str(out)]["summary"]["return"]["mean"]
    assert mean == pytest.approx(json.loads((out / "evaluation.json").read_text())["learned_return"], rel=1e-9)


def test_drop_inputs_and_predicted_inputs_are_refused_together(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--out", str(tmp_path / "x"), "--set", "drop_inputs=['age']", "--set", "inputs=predicted"])
    assert stop.value.code == 2
    assert "drop_inputs applies to raw inputs; inputs: predicted maps them first" in capsys.readouterr().err
