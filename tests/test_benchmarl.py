"""The BenchMARL tasks: BenchMARL's own experiment API and command line run them with nothing else written.

Needs the ``marl`` extra (BenchMARL with TorchRL 0.11), which lives in its own
virtual environment (``.venv-ecosystem``, see README): skipped elsewhere.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("benchmarl")

from benchmarl.algorithms import IppoConfig, MappoConfig, MasacConfig
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig
from torchrl.envs.utils import check_env_specs

from marine_formation_env.benchmarl import ENV_NAME, MarineFormationTask
from marine_formation_env.errors import ConfigError
from marine_formation_env.scenarios import make_config

TASKS = [
    "paper_speed",
    "paper_guidance",
    "paper_force",
    "acoustic_speed",
    "ring6_speed",
    "survey_speed",
    "paper_speed_budget",
    "acoustic_speed_budget",
]


def _small_experiment_config(folder: Path, evaluation: bool) -> ExperimentConfig:
    """BenchMARL's default experiment config, shrunk to one short iteration."""
    cfg = ExperimentConfig.get_from_yaml()
    cfg.loggers = ["tensorboard"] if evaluation else []
    cfg.create_json = evaluation
    cfg.save_folder = str(folder)
    cfg.max_n_iters = 1
    cfg.max_n_frames = None
    cfg.on_policy_collected_frames_per_batch = 400
    cfg.on_policy_n_envs_per_worker = 4
    cfg.on_policy_minibatch_size = 200
    cfg.on_policy_n_minibatch_iters = 1
    cfg.off_policy_collected_frames_per_batch = 400
    cfg.off_policy_n_envs_per_worker = 4
    cfg.off_policy_train_batch_size = 128
    cfg.off_policy_n_optimizer_steps = 4
    cfg.off_policy_init_random_frames = 0
    cfg.evaluation = evaluation
    cfg.evaluation_interval = 400
    cfg.evaluation_episodes = 2
    cfg.checkpoint_at_end = False
    return cfg


def _experiment(tmp_path: Path, algorithm, task, evaluation: bool) -> Experiment:
    """BenchMARL's experiment with its default MLPs, seed 0 and the shrunk config."""
    return Experiment(
        task=task,
        algorithm_config=algorithm.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=_small_experiment_config(tmp_path, evaluation=evaluation),
    )


def _task(name: str, horizon: float):
    task = MarineFormationTask[name.upper()].get_from_yaml()
    task.config["overrides"]["horizon"] = horizon
    return task


@pytest.mark.parametrize("name", TASKS)
def test_every_task_config_builds_its_scenario_and_passes_torchrl_checks(name):
    task = MarineFormationTask[name.upper()].get_from_yaml()
    expected = make_config(task.config["scenario"], **task.config["overrides"])
    env = task.get_env_fun(num_envs=3, continuous_actions=True, seed=0, device="cpu")()
    check_env_specs(env)
    assert env.config.to_dict() == expected.to_dict()
    assert task.max_steps(env) == expected.max_steps
    assert task.group_map(env) == {"vessel": [f"vessel_{j}" for j in range(expected.n_vessels)]}
    # what BenchMARL's models see: observations apart from infos and the state
    assert set(task.observation_spec(env).keys(True, True)) == {("vessel", "observation")}
    assert ("vessel", "info", "reward_cross_track") in task.info_spec(env).keys(True, True)
    assert ("vessel", "info", "messages_sent") in task.info_spec(env).keys(True, True)
    # the budget tasks: a transmit entry after the speed command, budget left and age after the slots
    assert task.action_spec(env)["vessel", "action"].shape[-1] == expected.control_dim + expected.transmit
    assert task.state_spec(env)["state"].shape == (6 * expected.n_vessels + 1,)
    env.close()


def test_bad_task_configs_are_refused_by_name():
    task = MarineFormationTask.PAPER_SPEED.get_from_yaml()
    task.config["overrides"]["n_vesels"] = 4
    with pytest.raises(TypeError, match="n_vesels"):
        task.get_env_fun(num_envs=2, continuous_actions=True, seed=0, device="cpu")
    task = MarineFormationTask.PAPER_SPEED.get_task({"scenario": "lake", "overrides": {}})
    with pytest.raises(ConfigError, match="unknown scenario 'lake'"):
        task.get_env_fun(num_envs=2, continuous_actions=True, seed=0, device="cpu")
    task = MarineFormationTask.PAPER_SPEED.get_from_yaml()
    with pytest.raises(ConfigError, match="continuous actions only"):
        task.get_env_fun(num_envs=2, continuous_actions=False, seed=0, device="cpu")


@pytest.mark.parametrize("algorithm", [IppoConfig, MasacConfig])
def test_benchmarl_api_trains_ippo_and_masac(tmp_path, algorithm):
    experiment = _experiment(tmp_path, algorithm, _task("paper_speed", horizon=50.0), evaluation=False)
    experiment.run()
    assert experiment.n_iters_performed == 1
    assert experiment.total_frames == 400


def test_benchmarl_api_trains_mappo_and_records_its_evaluation_video(tmp_path):
    pytest.importorskip("moviepy")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    task = _task("paper_speed", horizon=40.0)  # 80 steps per episode
    experiment = _experiment(tmp_path, MappoConfig, task, evaluation=True)
    experiment.run()
    # torch's SummaryWriter writes its queue every 10 events or 120 s: the last events of the
    # run (the video among them) reach the file when it flushes, as tensorboard would find them
    for logger in experiment.logger.loggers:
        logger.experiment.flush()
    folder = Path(experiment.folder_name)
    # marl-eval's json: the evaluation returns of both episodes, finite
    report = json.loads(next(folder.glob("*.json")).read_text())
    returns = report[ENV_NAME]["paper_speed"]["mappo"]["seed_0"]["step_1"]["return"]
    assert len(returns) == 2 and np.all(np.isfinite(returns))
    events = [EventAccumulator(str(f), size_guidance={"images": 0}) for f in folder.rglob("events.out.tfevents.*")]
    tags: dict[str, list] = {"images": [], "scalars": []}
    for acc in events:
        acc.Reload()
        for key in tags:
            tags[key] += [(acc, t) for t in acc.Tags()[key]]
    video = [acc.Images(t)[0] for acc, t in tags["images"] if t == "eval_video"]
    assert video, "no evaluation video in the tensorboard log"
    assert video[0].width % 2 == 0 and video[0].height % 2 == 0
    scalars = {t for _, t in tags["scalars"]}
    assert {"collection_vessel_info_reward_cross_track", "collection_vessel_info_collision"} <= scalars


def test_benchmarl_command_line_runs_a_marine_formation_task(tmp_path):
    command = [
        sys.executable, "-m", "benchmarl.run", "algorithm=mappo", "task=marine_formation/acoustic_speed",
        "experiment.loggers=[]", "experiment.create_json=false", "experiment.evaluation=false",
        "experiment.max_n_iters=1", "experiment.max_n_frames=null",
        "experiment.on_policy_collected_frames_per_batch=200", "experiment.on_policy_n_envs_per_worker=2",
        "experiment.on_policy_minibatch_size=100", "experiment.checkpoint_at_end=false",
        f"experiment.save_folder={tmp_path}", "+task.overrides.horizon=20", f"hydra.run.dir={tmp_path / 'hydra'}",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Task: marine_formation/acoustic_speed" in done.stdout
    assert "scenario: acoustic" in done.stdout  # the task config, as BenchMARL printed it
    assert list(tmp_path.glob("mappo_acoustic_speed_mlp_*"))


def test_a_benchmarl_policy_acts_in_the_evaluation_engine_as_in_benchmarl(tmp_path):
    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from baselines.engine import episode_reports
    from benchmarks.benchmarl_budget import BenchMARLPolicy

    task = _task("paper_speed", horizon=20.0)
    experiment = _experiment(tmp_path, MappoConfig, task, evaluation=False)
    experiment.run()
    policy = BenchMARLPolicy(experiment.policy, "vessel", 3, 18, 1)  # obs dim 10 + 4·2 (MarineFormation-v1)
    env = task.get_env_fun(num_envs=4, continuous_actions=True, seed=7, device="cpu")()
    td = env.reset()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        expected = experiment.policy(td.clone())["vessel", "action"].numpy()
    obs = td["vessel", "observation"].numpy().reshape(12, 18)  # the engine's layout: (B·N, dim)
    np.testing.assert_allclose(policy.act_batch(obs).reshape(4, 3, 1), expected, rtol=1e-6, atol=1e-7)
    reports, _ = episode_reports(policy, env.config, [0, 1])
    assert all(np.isfinite(r["return"]) for r in reports)
