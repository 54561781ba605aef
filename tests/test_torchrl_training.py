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

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from tensordict import TensorDict  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type  # noqa: E402

from marine_formation_env import ENV_ID  # noqa: E402
from training.config import load_config  # noqa: E402
from training.torchrl_ppo import load_torch_policy, main, resolve  # noqa: E402

TINY = [
    "num_envs=4",
    "frames_per_batch=40",
    "total_frames=80",
    "minibatch_size=20",
    "epochs=1",
    "eval_episodes=2",
    "hidden=[16]",
    "env_kwargs.horizon=4.0",
    "env_kwargs.init_noise={'x': 10.0}",
]


@pytest.mark.parametrize("algo", ["mappo", "ippo"])
def test_two_iterations_write_a_loadable_policy_that_acts_like_torchrl_s_deterministic_actor(tmp_path, algo):
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
        "env_kwargs.action_level=speed",
    ]
    for item in TINY:
        args += ["--set", item]
    assert main(args) == 0
    progress = (out / "progress.csv").read_text().splitlines()
    assert progress[0] == "frames,vessel_steps,seconds,mean_reward" and len(progress) == 3  # two iterations
    summary = json.loads((out / "evaluation.json").read_text())
    assert summary["frames"] == 80 and summary["vessel_steps"] == 240
    assert np.isfinite(summary["learned_return"]) and summary["learned_return"] < 0
    assert summary["reference_return"] < 0
    policy, config = load_torch_policy(out)
    assert config["algo"] == algo and config["seed"] == 3
    obs = np.random.default_rng(0).uniform(-5, 5, (6, 3, policy.observation_dim)).astype(np.float32)
    mine = policy.act_batch(obs)
    assert mine.shape == (6, 3, 1) and np.all(np.abs(mine) <= 1.0)
    td = TensorDict({("vessel", "observation"): torch.from_numpy(obs.reshape(18, 1, -1))}, batch_size=[18])
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        theirs = policy.actor(td)["vessel", "action"].numpy().reshape(6, 3, 1)
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
    # the evaluation at the end of training used the same seeds (10 000, 10 001) and the same engine
    assert data["policies"][str(out)]["summary"]["return"]["mean"] == pytest.approx(learned["learned_return"], rel=1e-9)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("algo=dqn", "algo must be one of ['mappo', 'ippo'], got 'dqn'"),
        ("epochs=0", "epochs must be a whole number ≥ 1, got 0"),
        ("gamma=1.5", "gamma must lie in [0, 1], got 1.5"),
        ("hidden=fish", "hidden must be a non-empty list of whole numbers ≥ 1, got 'fish'"),
        ("frames_per_batch=100", "frames_per_batch = 100 must be a multiple of num_envs = 64"),
        ("colour=1", "unknown key(s) ['colour']"),
        ("env_kwargs.frameskip=4", "unexpected keyword argument 'frameskip'"),
    ],
)
def test_bad_configs_are_refused_in_one_line(tmp_path, capsys, item, message):
    with pytest.raises(SystemExit) as stop:
        main(["--out", str(tmp_path / "x"), "--set", item])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_a_used_run_folder_needs_overwrite(tmp_path, capsys):
    (tmp_path / "policy.pt").write_bytes(b"")
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path)])
    assert "pass --overwrite" in capsys.readouterr().err


def test_resolve_fills_defaults_and_keeps_the_seed():
    cfg = resolve({"scenario": "acoustic"}, seed=5)
    assert cfg["seed"] == 5 and cfg["algo"] == "mappo" and cfg["num_envs"] == 64


def test_an_unreadable_policy_file_is_named(tmp_path):
    (tmp_path / "policy.pt").write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="cannot load the policy"):
        load_torch_policy(tmp_path)


@pytest.mark.parametrize("path", sorted(Path(__file__).parents[1].glob("training/configs/torchrl/*.yaml")), ids=str)
def test_shipped_torchrl_configs_resolve(path):
    cfg = resolve(load_config(path), seed=0)
    assert cfg["frames_per_batch"] % cfg["num_envs"] == 0
