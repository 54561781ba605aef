"""``python -m benchmarks.learning``: ``--set`` overrides reach the run, bad ones are refused before training."""

from __future__ import annotations

import json

import pytest
import yaml

pytest.importorskip("stable_baselines3")

from benchmarks import learning
from marine_formation_env import ENV_ID

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("learning_rate=lin_fast", "learning_rate must be a number or 'lin_<number>', got 'lin_fast'"),
        ("n_stepz=64", "n_stepz"),
        ("no_equals_sign", "no_equals_sign"),
    ],
)
def test_a_bad_override_is_refused_by_name_before_any_training(tmp_path, capsys, item, message):
    with pytest.raises(SystemExit) as stop:
        learning.main(["--minutes", "1", "--out", str(tmp_path / "run"), "--set", item])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "run").exists()


def test_a_level_that_is_not_the_configs_is_refused_before_any_training(tmp_path, capsys):
    config = str(learning.CONFIG_DIR / "acoustic_speed_ppo.yaml")
    with pytest.raises(SystemExit) as stop:
        learning.main(["--level", "guidance", "--config", config, "--minutes", "1", "--out", str(tmp_path / "run")])
    assert stop.value.code == 2
    assert f"--level 'guidance', but {config} trains at action_level 'speed'" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_the_report_names_the_level_of_the_config_it_trained(tmp_path):
    out = tmp_path / "run"
    args = ["--config", str(learning.CONFIG_DIR / "paper_guidance_ppo.yaml"), "--minutes", "1", "--vessel-steps", "384"]
    args += ["--episodes", "1", "--out", str(out), "--quiet", "--set", "n_envs=2", "--set", "n_steps=64"]
    assert learning.main([*args, "--set", "batch_size=64"]) == 0
    assert json.loads((out / "benchmark.json").read_text())["level"] == "guidance"


def test_an_override_reaches_the_run_and_its_recorded_config(tmp_path):
    out = tmp_path / "run"
    args = ["--minutes", "1", "--vessel-steps", "384", "--episodes", "1", "--out", str(out), "--quiet"]
    args += ["--set", "n_envs=2", "--set", "n_steps=64", "--set", "batch_size=64", "--set", "learning_rate=lin_1e-3"]
    assert learning.main(args) == 0
    recorded = yaml.safe_load((out / "config.yaml").read_text())
    assert recorded["trainer"] == "sb3" and recorded["env_id"] == ENV_ID
    assert recorded["learning_rate"] == "lin_1e-3" and recorded["n_envs"] == 2
    assert recorded["n_timesteps"] == 384  # the budget's ceiling still applies on top of the overrides
