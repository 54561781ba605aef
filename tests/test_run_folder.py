"""``python -m training.train``: one-line CLI errors and run folders that never lose or corrupt work.

Truth: what the files on disk hold after real training runs (in process, or in
subprocesses that are sent SIGINT or killed with SIGKILL at seeded random
instants and once in the middle of a checkpoint write); PyYAML's own error
marks for malformed YAML; SB3's loaders (``PPO.load``, ``pickle``) for what
"readable" means; and, for the best model, a fresh evaluation of
``best_model.zip`` on the evaluation seeds (``training.callbacks`` documents
that evaluation is deterministic: the development seeds, deterministic actions).
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
import torch
from stable_baselines3 import PPO

import marine_formation_env
from baselines.metrics import summarize
from baselines.seeds import DEVELOPMENT_SEED, development_seeds
from training import run_folder
from training import train as train_module
from training.callbacks import evaluate_policy_episodes
from training.config import TrainConfigError, load_config, validate
from training.learned import load_learned_policy

pytestmark = pytest.mark.backend_independent

ENV_ID = "MarineFormation-v1"
REPO = Path(__file__).resolve().parents[1]
SPEED_CONFIG = REPO / "training" / "configs" / "paper_speed_ppo.yaml"
PROG = "python -m training.train"
#: The run artifacts a new run must not silently overwrite.
ARTIFACTS = (
    "config.yaml",
    "model.zip",
    "vecnormalize.pkl",
    "best_model.zip",
    "best_vecnormalize.pkl",
    "best_model.json",
    "evaluations.csv",
    "evaluation.json",
    "tb",
    "checkpoints",
)
# One formation of 3 vessels (3 SB3 entries), 20-step episodes, a 16-unit network; a high learning rate
# makes the evaluation scores go up and down, so "the best so far" is not simply "the latest".
TINY = [
    "--config", str(SPEED_CONFIG),
    "--set", "n_envs=1",
    "--set", "n_steps=16",
    "--set", "batch_size=48",
    "--set", "n_epochs=1",
    "--set", "eval_freq=150",
    "--set", "eval_episodes=1",
    "--set", "checkpoint_freq=150",
    "--set", "env_kwargs.horizon=10.0",
    "--set", "policy_kwargs.net_arch=[16]",
    "--set", "learning_rate=0.01",
    "--quiet",
]  # fmt: skip
SUBPROCESS_ENV = {**os.environ, "MARINE_FORMATION_BACKEND": "numpy", "PYTHONUNBUFFERED": "1"}


@pytest.fixture(autouse=True)
def _numpy_backend_one_thread(monkeypatch):
    """The subprocesses run the numpy backend with one torch thread; in-process runs do the same."""
    monkeypatch.setenv("MARINE_FORMATION_BACKEND", "numpy")
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "training.train", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=SUBPROCESS_ENV,
        timeout=timeout,
    )


def one_line_error(code: int | None, err: str, *fragments: str) -> str:
    """The single stderr line of a refused command, after checking status 2 and the fragments."""
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"{PROG}: error: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def run_main(args: list[str], capsys) -> tuple[int | None, str]:
    """``training.train.main(args)`` in process: (exit status, stderr)."""
    capsys.readouterr()
    try:
        code: int | None = train_module.main(args)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    return code, capsys.readouterr().err


def snapshot(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (hidden ones too) with a hash of its bytes."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def evaluation_rows(folder: Path) -> list[dict[str, str]]:
    with (folder / "evaluations.csv").open(newline="") as handle:
        return list(csv.DictReader(handle))


def checkpoint_steps(folder: Path) -> list[int]:
    return sorted(int(p.stem.split("_")[1]) for p in (folder / "checkpoints").glob("model_*_steps.zip"))


def reevaluate_best(folder: Path) -> float:
    """Mean learned return of ``best_model.zip`` (+ ``best_vecnormalize.pkl``) on the run's evaluation seeds."""
    config = yaml.safe_load((folder / "config.yaml").read_text())
    policy, _ = load_learned_policy(folder / "best_model.zip")
    env = marine_formation_env.parallel_env(config["scenario"], **config["env_kwargs"])
    episodes = evaluate_policy_episodes(env, policy, development_seeds(config["eval_episodes"]))
    assert [e["seed"] for e in episodes] == [DEVELOPMENT_SEED + k for k in range(config["eval_episodes"])]
    return float(summarize(episodes)["return"]["mean"])


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A finished 900-step run (checkpoints every 150 steps, one evaluation every 150 steps)."""
    run = tmp_path_factory.mktemp("tiny") / "run"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MARINE_FORMATION_BACKEND", "numpy")
        torch.set_num_threads(1)
        assert train_module.main([*TINY, "--set", "n_timesteps=900", "--out", str(run)]) == 0
    return run


@pytest.fixture
def run_copy(tiny_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    return run


# =========================================================================== atomic writes


def test_atomic_write_replaces_the_file_only_when_the_write_completes(tmp_path):
    path = tmp_path / "model.zip"
    path.write_bytes(b"old")
    with run_folder.atomic_write(path) as handle:
        handle.write(b"new content")
        assert path.read_bytes() == b"old"  # the final name is untouched while writing
        temps = list(tmp_path.glob(".model.zip.*"))
        assert len(temps) == 1  # the temporary file is in the same folder (same file system: rename is atomic)
    assert path.read_bytes() == b"new content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.zip"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # as open() would create it, not mkstemp's 0600


def test_config_yaml_writes_a_shared_setting_in_full_at_each_key(tmp_path):
    """A config whose teams share a setting through a YAML anchor (``&radio`` … ``*radio``) is recorded in full."""
    config = tmp_path / "teams.yaml"
    config.write_text(
        f"{marine_formation_env.ENV_ID}:\n  algo: ppo\n  teams:\n"
        "    - {n_vessels: 3, channel: &radio {loss: 0.05, tdma_slot: 0.5}}\n"
        "    - {n_vessels: 4, channel: *radio}\n"
    )
    resolved = load_config(config)
    out = tmp_path / "run"
    out.mkdir()
    run_folder.write_config(out, "sb3", resolved, seed=0)
    text = (out / "config.yaml").read_text()
    assert "&" not in text and "*" not in text
    teams = yaml.safe_load(text)["teams"]
    assert [team["channel"] for team in teams] == [{"loss": 0.05, "tdma_slot": 0.5}] * 2


def test_atomic_write_that_fails_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "vecnormalize.pkl"
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="disk full"), run_folder.atomic_write(path) as handle:
        handle.write(b"half")
        raise RuntimeError("disk full")
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["vecnormalize.pkl"]


def test_write_together_is_all_or_nothing_across_a_crash(tmp_path, monkeypatch):
    names = ("best_model.zip", "best_vecnormalize.pkl", "best_model.json")
    for name in names:
        (tmp_path / name).write_bytes(b"old " + name.encode())
    writers = {name: (lambda handle, name=name: handle.write(b"new " + name.encode())) for name in names}

    # a crash while staging (before the commit point): recover() drops the staged files, all stay old
    def failing(handle):
        handle.write(b"x")
        raise OSError("killed")

    with pytest.raises(OSError, match="killed"):
        run_folder.write_together(tmp_path, {**writers, "best_model.json": failing})
    run_folder.recover(tmp_path)
    assert {name: (tmp_path / name).read_bytes() for name in names} == {n: b"old " + n.encode() for n in names}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)

    # a crash after the commit point, between two renames: recover() finishes the renames, all are new
    real_replace = os.replace
    calls = []

    def crash_on_second_rename(src, dst):
        calls.append(Path(dst).name)
        if len(calls) == 3:  # the journal's own rename, then the first file, then crash
            raise OSError("killed")
        real_replace(src, dst)

    monkeypatch.setattr(run_folder.os, "replace", crash_on_second_rename)
    with pytest.raises(OSError, match="killed"):
        run_folder.write_together(tmp_path, writers)
    monkeypatch.setattr(run_folder.os, "replace", real_replace)
    contents = {name: (tmp_path / name).read_bytes() for name in names}
    assert contents["best_model.zip"].startswith(b"new") and contents["best_model.json"].startswith(b"old")
    notes = run_folder.recover(tmp_path)
    assert notes == [
        f"completed the interrupted update of best_model.zip, best_vecnormalize.pkl, best_model.json in {tmp_path}"
    ]
    assert {name: (tmp_path / name).read_bytes() for name in names} == {n: b"new " + n.encode() for n in names}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)


def test_checkpoints_are_written_atomically_statistics_first(tmp_path, capsys, monkeypatch):
    written: list[str] = []
    original = run_folder.atomic_write

    def recording(path):
        written.append(str(Path(path).relative_to(tmp_path / "run")))
        return original(path)

    together: list[list[str]] = []
    original_together = run_folder.write_together

    def recording_together(folder, writers):
        together.append(list(writers))
        return original_together(folder, writers)

    monkeypatch.setattr(run_folder, "atomic_write", recording)
    monkeypatch.setattr(run_folder, "write_together", recording_together)
    code, err = run_main([*TINY, "--set", "n_timesteps=300", "--out", str(tmp_path / "run")], capsys)
    assert code == 0, err
    ckpt = [name for name in written if name.startswith("checkpoints")]
    assert ckpt == [
        f"checkpoints/{name}"
        for steps in (0, 150, 300)
        for name in (f"model_vecnormalize_{steps}_steps.pkl", f"model_{steps}_steps.zip")
    ]
    for name in ("config.yaml", "evaluations.csv", ".commit.json"):
        assert name in written, name
    # files that belong together are replaced together (staged, journal, renames)
    assert together[-1] == ["model.zip", "vecnormalize.pkl"]
    assert ["best_model.zip", "best_vecnormalize.pkl", "best_model.json"] in together
    assert all(
        names in (["model.zip", "vecnormalize.pkl"], ["best_model.zip", "best_vecnormalize.pkl", "best_model.json"])
        for names in together
    )
    # no temporaries left
    assert not [p for p in (tmp_path / "run").rglob(".*") if p.name != ".commit.json"]
    assert not (tmp_path / "run" / ".commit.json").exists()


# =========================================================================== config validation


@pytest.mark.parametrize(
    ("overrides", "fragments"),
    [
        ({"n_steps": 0}, ["n_steps", "got 0"]),
        ({"batch_size": -3}, ["batch_size", "got -3"]),
        ({"n_epochs": 2.5}, ["n_epochs", "got 2.5"]),
        ({"n_steps": True}, ["n_steps", "got True"]),
        ({"algo": "sac", "buffer_size": 0}, ["buffer_size", "got 0"]),
        ({"algo": "sac", "learning_starts": -1}, ["learning_starts", "got -1"]),
        ({"algo": "sac", "train_freq": [4, "fortnight"]}, ["train_freq", "fortnight"]),
        ({"algo": "td3", "policy_delay": 0}, ["policy_delay", "got 0"]),
        ({"gamma": 1.5}, ["gamma", "got 1.5"]),
        ({"gamma": "x"}, ["gamma", "got 'x'"]),
        ({"gamma": float("nan")}, ["gamma", "got nan"]),  # NaN fails every comparison: refused, not let through
        ({"vf_coef": float("inf")}, ["vf_coef", "got inf"]),
        ({"learning_rate": 0}, ["learning_rate", "got 0"]),
        ({"learning_rate": "lin_-1"}, ["learning_rate", "lin_-1"]),
        ({"clip_range": "fish"}, ["clip_range", "'fish'"]),
        ({"ent_coef": "auto"}, ["ent_coef", "'auto'"]),  # 'auto' is SAC's, not PPO's
        ({"policy_kwargs": {"net_arch": "fish"}}, ["net_arch", "'fish'"]),
        ({"policy_kwargs": {"net_arch": [64, 0]}}, ["net_arch", "[64, 0]"]),
        ({"policy_kwargs": {"net_arch": {"pi": [8], "qf": [8]}}}, ["net_arch", "'qf'"]),
        ({"policy": "FishPolicy"}, ["policy", "'FishPolicy'", "MlpPolicy"]),
    ],
)
def test_validate_rejects_values_sb3_would_choke_on(overrides, fragments):
    with pytest.raises(TrainConfigError) as info:
        validate(overrides)
    for fragment in fragments:
        assert fragment in str(info.value), (fragment, str(info.value))


def test_validate_accepts_what_sb3_accepts():
    resolved = validate({"n_steps": 1.6e1, "policy_kwargs": {"net_arch": {"pi": [8.0], "vf": [8, 8]}}, "ent_coef": 0.0})
    assert resolved["n_steps"] == 16 and isinstance(resolved["n_steps"], int)
    assert resolved["policy_kwargs"]["net_arch"] == {"pi": [8], "vf": [8, 8]}
    sac = validate({"algo": "sac", "ent_coef": "auto_0.1", "train_freq": [1, "episode"], "gradient_steps": -1})
    assert sac["train_freq"] == (1, "episode") and sac["gradient_steps"] == -1


def test_malformed_yaml_names_the_file_and_the_parsers_line_and_column(tmp_path):
    text = "MarineFormation-v1:\n  algo: ppo\n  n_steps: [16, 32\n  gamma: 0.9\n"
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    with pytest.raises(yaml.MarkedYAMLError) as parser:
        yaml.safe_load(text)
    mark = parser.value.problem_mark
    with pytest.raises(TrainConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert "broken.yaml" in message
    assert f"line {mark.line + 1}, column {mark.column + 1}" in message
    assert parser.value.problem in message


def test_the_algorithm_is_built_once_and_its_errors_name_the_algo():
    # PPO asserts batch_size > 1 in its constructor: not checked by validate (≥ 1), caught by the dry build
    resolved = validate({"n_envs": 1, "n_steps": 16, "batch_size": 1})
    with pytest.raises(TrainConfigError, match=r"^ppo rejects this config: AssertionError: `batch_size`"):
        train_module.check_buildable(resolved, seed=0)
    resolved = validate({"n_envs": 1, "n_steps": 16, "batch_size": 48, "policy_kwargs": {"squeeze": 1}})
    with pytest.raises(TrainConfigError, match=r"^ppo rejects this config: TypeError: .*'squeeze'"):
        train_module.check_buildable(resolved, seed=0)
    train_module.check_buildable(validate({"n_envs": 1, "n_steps": 16, "batch_size": 48}), seed=0)


# =========================================================================== one-line CLI errors (subprocesses)


def _broken_yaml(folder: Path) -> tuple[Path, str]:
    path = folder / "broken.yaml"
    text = "MarineFormation-v1:\n  algo: ppo\n  policy_kwargs: {net_arch: [64, 64]\n  n_steps: 16\n"
    path.write_text(text)
    try:
        yaml.safe_load(text)
    except yaml.MarkedYAMLError as err:
        assert err.problem_mark is not None
        return path, f"line {err.problem_mark.line + 1}, column {err.problem_mark.column + 1}"
    raise AssertionError("the broken YAML parsed")


CLI_CASES = {
    "malformed-yaml": None,  # built in the fixture (needs a file)
    "n_steps-0-in-file": None,
    "batch_size": (["--set", "batch_size=-3"], ["batch_size", "-3"]),
    "net_arch": (["--set", "policy_kwargs.net_arch=fish"], ["net_arch", "'fish'"]),
    "policy": (["--set", "policy=FishPolicy"], ["'FishPolicy'"]),
    "constructor": (["--set", "batch_size=1"], ["ppo rejects this config", "batch_size"]),
    "threads": (["--threads", "0"], ["--threads", "got 0"]),
    "seed": (["--seed", "-5"], ["--seed", "got -5"]),
    "resume-and-overwrite": (["--resume", "--overwrite"], ["--overwrite", "--resume"]),
}


@pytest.fixture(scope="module")
def cli_errors(tmp_path_factory):
    """Run every refused command line once, three at a time (each pays torch's import)."""
    folder = tmp_path_factory.mktemp("cli")
    broken, where = _broken_yaml(folder)
    zero = folder / "zero.yaml"
    zero.write_text(SPEED_CONFIG.read_text().replace("n_steps: 128", "n_steps: 0"))
    assert "n_steps: 0" in zero.read_text()
    cases = dict(CLI_CASES)
    cases["malformed-yaml"] = (["--config", str(broken)], ["broken.yaml", where])
    cases["n_steps-0-in-file"] = (["--config", str(zero)], ["n_steps", "got 0"])

    def run(item):
        name, (args, _) = item
        out = folder / f"out-{name}"
        config = [] if "--config" in args or "--resume" in args else ["--config", str(SPEED_CONFIG)]
        result = cli(*config, *args, "--out", str(out), "--quiet")
        return name, (result, out)

    with ThreadPoolExecutor(max_workers=3) as pool:
        results = dict(pool.map(run, cases.items()))
    return {name: (*results[name], cases[name][1]) for name in cases}


@pytest.mark.parametrize("case", list(CLI_CASES))
def test_cli_error_is_one_line_exit_2_and_writes_nothing(cli_errors, case):
    result, out, fragments = cli_errors[case]
    one_line_error(result.returncode, result.stderr, *fragments)
    assert result.stdout == ""
    assert not out.exists()  # refused before anything was written


# =========================================================================== new runs, --overwrite


@pytest.mark.parametrize("artifact", ARTIFACTS)
def test_new_run_refuses_a_folder_holding_any_artifact(tmp_path, capsys, artifact):
    out = tmp_path / "run"
    out.mkdir()
    path = out / artifact
    if artifact in ("tb", "checkpoints"):
        path.mkdir()
        (path / "keep").write_bytes(b"x")
    else:
        path.write_bytes(b"x")
    before = snapshot(out)
    code, err = run_main([*TINY, "--out", str(out)], capsys)
    one_line_error(code, err, str(out), artifact, "--resume", "--overwrite")
    assert snapshot(out) == before


def test_overwrite_replaces_the_previous_run_and_keeps_other_files(run_copy, capsys):
    (run_copy / "notes.txt").write_text("mine")
    (run_copy / "checkpoints" / "model_999999_steps.zip").write_bytes(b"old run")
    old_wall = {row["wall_time"] for row in evaluation_rows(run_copy)}
    code, err = run_main(
        [*TINY, "--set", "n_timesteps=300", "--seed", "3", "--out", str(run_copy), "--overwrite"], capsys
    )
    assert code == 0, err
    assert "removed the previous run's config.yaml, model.zip" in err
    assert (run_copy / "notes.txt").read_text() == "mine"
    assert checkpoint_steps(run_copy) == [0, 150, 300]
    rows = evaluation_rows(run_copy)
    assert [int(r["timesteps"]) for r in rows] == [150, 300]
    assert not old_wall & {row["wall_time"] for row in rows}
    assert yaml.safe_load((run_copy / "config.yaml").read_text())["seed"] == 3
    assert 300 <= PPO.load(run_copy / "model.zip", device="cpu").num_timesteps < 300 + 48  # whole rollouts


def test_overwrite_with_a_bad_config_leaves_the_folder_untouched(run_copy, capsys):
    before = snapshot(run_copy)
    code, err = run_main([*TINY, "--set", "batch_size=1", "--out", str(run_copy), "--overwrite"], capsys)
    one_line_error(code, err, "ppo rejects this config", "batch_size")
    assert snapshot(run_copy) == before


# =========================================================================== --resume


def test_resume_refuses_a_changed_config_before_writing(run_copy, capsys):
    before = snapshot(run_copy)
    args = [*TINY, "--set", "n_envs=2", "--set", "env_kwargs.horizon=30.0", "--set", "learning_rate=0.1"]
    code, err = run_main([*args, "--resume", "--seed", "4", "--out", str(run_copy)], capsys)
    line = one_line_error(
        code,
        err,
        "n_envs (1 → 2)",
        "env_kwargs.horizon (10.0 → 30.0)",
        "learning_rate (0.01 → 0.1)",
        "seed (0 → 4)",
        "n_timesteps, eval_freq, eval_episodes, checkpoint_freq",
    )
    assert "batch_size" not in line  # unchanged keys are not listed
    assert snapshot(run_copy) == before
    # the stored config without --config, and a different --seed alone
    code, err = run_main(["--resume", "--out", str(run_copy), "--set", "n_steps=32", "--quiet"], capsys)
    one_line_error(code, err, "n_steps (16 → 32)")
    assert snapshot(run_copy) == before


def test_resume_with_the_same_config_may_change_the_resumable_keys(run_copy, capsys):
    args = [*TINY, "--set", "n_timesteps=1050", "--set", "eval_freq=300", "--set", "checkpoint_freq=300"]
    code, err = run_main([*args, "--resume", "--seed", "0", "--out", str(run_copy)], capsys)
    assert code == 0, err
    assert "resuming from" in err and "model_900_steps.zip at 900 steps" in err
    cfg = yaml.safe_load((run_copy / "config.yaml").read_text())
    assert (cfg["n_timesteps"], cfg["eval_freq"], cfg["checkpoint_freq"], cfg["seed"]) == (1050, 300, 300, 0)
    assert PPO.load(run_copy / "model.zip", device="cpu").num_timesteps >= 1050  # 1092: whole rollouts of 48
    # the new frequencies are in force: at 150 there would be a checkpoint and an evaluation at 1050
    assert max(checkpoint_steps(run_copy)) == 900
    assert int(evaluation_rows(run_copy)[-1]["timesteps"]) == 900


def test_resume_skips_unreadable_checkpoints_and_trims_evaluations(run_copy, capsys):
    ckpt = run_copy / "checkpoints"
    assert checkpoint_steps(run_copy) == [0, 150, 300, 450, 600, 750, 900]
    data = (ckpt / "model_900_steps.zip").read_bytes()
    (ckpt / "model_900_steps.zip").write_bytes(data[: len(data) // 2])  # truncated
    (ckpt / "model_750_steps.zip").write_bytes(b"")  # 0 bytes
    (ckpt / "model_vecnormalize_600_steps.pkl").write_bytes(b"not a pickle")
    # named as marine_formation_env.atomic names its temporary files: .NAME.<random>.tmp<suffix>
    stale = [ckpt / ".model_1050_steps.zip.abc12345.tmp.zip", run_copy / ".best_model.zip.xyz_9876.tmp.zip"]
    (run_copy / ".notes.tmp.txt.keep").write_bytes(b"not ours")
    for path in stale:
        path.write_bytes(b"half")
    rows_before = evaluation_rows(run_copy)
    assert [int(r["timesteps"]) for r in rows_before] == [150, 300, 450, 600, 750, 900]
    code, err = run_main(["--resume", "--out", str(run_copy), "--set", "n_timesteps=1050", "--quiet"], capsys)
    assert code == 0, err
    lines = err.strip().splitlines()
    for path in stale:
        assert f"removed stale temporary file {path} (left by an interrupted write)" in lines
    # a half zip: SB3 stores policy.pth (itself a zip) uncompressed, so the tail may still look like a zip
    skipped_900 = [line for line in lines if line.startswith(f"skipping checkpoint {ckpt / 'model_900_steps.zip'}: ")]
    assert len(skipped_900) == 1 and "truncated" in skipped_900[0], lines
    assert f"skipping checkpoint {ckpt / 'model_750_steps.zip'}: empty file" in lines
    skipped_600 = [line for line in lines if line.startswith(f"skipping checkpoint {ckpt / 'model_600_steps.zip'}: ")]
    assert (
        len(skipped_600) == 1
        and "unreadable VecNormalize statistics model_vecnormalize_600_steps.pkl" in skipped_600[0]
    )
    assert f"resuming from {ckpt / 'model_450_steps.zip'} at 450 steps" in lines
    assert "dropped 3 row(s) of evaluations.csv after step 450" in lines
    assert not any(path.exists() for path in stale)
    assert (run_copy / ".notes.tmp.txt.keep").read_bytes() == b"not ours"
    rows = evaluation_rows(run_copy)
    steps = [int(r["timesteps"]) for r in rows]
    assert steps == [150, 300, 450, 600, 750, 900, 1050]  # monotone: the old 600..900 rows were replaced
    assert rows[:3] == rows_before[:3]
    assert all(rows[k]["wall_time"] != rows_before[k]["wall_time"] for k in range(3, 6))
    # the checkpoints written after the resume replaced the broken ones
    for steps_ in (600, 750, 900, 1050):
        problem = run_folder.checkpoint_problem(
            run_folder.Checkpoint(
                steps_, ckpt / f"model_{steps_}_steps.zip", ckpt / f"model_vecnormalize_{steps_}_steps.pkl"
            ),
            needs_stats=True,
        )
        assert problem is None, (steps_, problem)
    assert train_module.latest_checkpoint(run_copy) == (
        ckpt / "model_1050_steps.zip",
        ckpt / "model_vecnormalize_1050_steps.pkl",
    )


def test_resume_without_a_readable_checkpoint_is_refused(run_copy, capsys):
    for path in (run_copy / "checkpoints").glob("model_*_steps.zip"):
        path.write_bytes(b"")
    code, err = run_main(["--resume", "--out", str(run_copy), "--quiet"], capsys)
    lines = err.strip().splitlines()
    assert code == 2 and "Traceback" not in err
    assert len([line for line in lines if line.startswith("skipping checkpoint")]) == 7
    assert lines[-1] == (
        f"{PROG}: error: --resume: cannot continue the run in {run_copy}: none of its 7 checkpoint(s) is "
        "readable; start it over with --overwrite"
    )


def test_best_score_survives_a_resume(run_copy, capsys):
    best = json.loads((run_copy / "best_model.json").read_text())
    assert best["return_learned"] == max(float(r["return_learned"]) for r in evaluation_rows(run_copy))
    assert reevaluate_best(run_copy) == pytest.approx(best["return_learned"], rel=1e-12)
    # Pretend the earlier part of the run had scored better than anything a later evaluation can reach:
    # the resumed run must compare against it (before the fix it restarted from −inf and replaced the model).
    unbeatable = {**best, "return_learned": 1.0}  # returns are ≤ 0
    (run_copy / "best_model.json").write_text(json.dumps(unbeatable))
    kept = {
        name: (run_copy / name).read_bytes() for name in ("best_model.zip", "best_vecnormalize.pkl", "best_model.json")
    }
    code, err = run_main(["--resume", "--out", str(run_copy), "--set", "n_timesteps=1200", "--quiet"], capsys)
    assert code == 0, err
    rows = evaluation_rows(run_copy)
    assert [int(r["timesteps"]) for r in rows][-2:] == [1050, 1200]  # evaluations did run
    assert {name: (run_copy / name).read_bytes() for name in kept} == kept


def test_changed_eval_episodes_rescore_the_best_model(run_copy, capsys):
    best = json.loads((run_copy / "best_model.json").read_text())
    assert best["eval_episodes"] == 1
    zip_before = (run_copy / "best_model.zip").read_bytes()
    code, err = run_main(
        ["--resume", "--out", str(run_copy), "--set", "n_timesteps=900", "--set", "eval_episodes=2", "--quiet"],
        capsys,
    )  # nothing left to train: only the best model is re-scored on the new evaluation seeds
    assert code == 0, err
    rescored = json.loads((run_copy / "best_model.json").read_text())
    assert rescored["eval_episodes"] == 2 and rescored["timesteps"] == best["timesteps"]
    assert (run_copy / "best_model.zip").read_bytes() == zip_before
    assert rescored["return_learned"] == pytest.approx(reevaluate_best(run_copy), rel=1e-12)


def test_train_api_keeps_working(tmp_path, capsys):
    resolved = validate(
        {**load_config(SPEED_CONFIG), "n_timesteps": 150, "n_envs": 1, "n_steps": 16, "batch_size": 48,
         "n_epochs": 1, "eval_freq": 0, "checkpoint_freq": 0, "env_kwargs": {"horizon": 10.0}}
    )  # fmt: skip
    model = train_module.train(resolved, tmp_path / "api", seed=0, progress=False)
    assert model.num_timesteps >= 150
    assert sorted(p.name for p in (tmp_path / "api").iterdir() if p.name != "tb") == [
        "config.yaml",
        "evaluation.json",
        "model.zip",
        "progress.csv",
        "vecnormalize.pkl",
    ]
    assert train_module.latest_checkpoint(tmp_path / "api") is None


# =========================================================================== SIGINT and SIGKILL (subprocesses)


def _wait_for(predicate, proc: subprocess.Popen, what: str, timeout: float = 90.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if proc.poll() is not None:
            raise AssertionError(f"the training process ended (status {proc.returncode}) before {what}")
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def test_sigint_saves_a_checkpoint_exits_130_and_resumes(tmp_path, capsys):
    out = tmp_path / "run"
    err_path = tmp_path / "stderr.txt"
    with err_path.open("w") as err_file:
        proc = subprocess.Popen(
            [sys.executable, "-m", "training.train", *TINY, "--set", "n_timesteps=1000000", "--out", str(out)],
            cwd=REPO,
            env=SUBPROCESS_ENV,
            stdout=subprocess.PIPE,
            stderr=err_file,
            text=True,
        )
        _wait_for(lambda: (out / "checkpoints" / "model_150_steps.zip").exists(), proc, "the first checkpoint")
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=60)
        assert proc.stdout is not None and proc.stdout.read() == ""
    err = err_path.read_text()
    assert code == 130, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    match = re.fullmatch(
        rf"{re.escape(PROG)}: interrupted at (\d+) steps; saved checkpoint (\S+); continue with: "
        rf"{re.escape(PROG)} --resume --out {re.escape(str(out))}",
        lines[0],
    )
    assert match, lines[0]
    steps, path = int(match.group(1)), Path(match.group(2))
    assert steps > 150 and path == out / "checkpoints" / f"model_{steps}_steps.zip"
    assert PPO.load(path, device="cpu").num_timesteps == steps
    assert (out / "checkpoints" / f"model_vecnormalize_{steps}_steps.pkl").is_file()
    assert not (out / "model.zip").exists()
    code, err = run_main(["--resume", "--out", str(out), "--set", f"n_timesteps={steps + 150}", "--quiet"], capsys)
    assert code == 0, err
    assert f"resuming from {path} at {steps} steps" in err
    assert PPO.load(out / "model.zip", device="cpu").num_timesteps >= steps + 150


#: ``python -c`` program: ``training.train.main`` with, if $SLOW_CHECKPOINT_MARKER is set, an atomic-write
#: helper that, for a periodic checkpoint zip, writes half of the file, reports its path in the marker file
#: and sleeps (so the test can kill the process in the middle of a checkpoint write).
KILL_SCRIPT = r"""
import os, sys, time
from contextlib import contextmanager
from pathlib import Path

import training.run_folder as rf

marker = os.environ.get("SLOW_CHECKPOINT_MARKER")
if marker:
    original = rf.atomic_write

    @contextmanager
    def slow_atomic_write(path):
        path = Path(path)
        with original(path) as handle:
            yield handle
            if path.parent.name == "checkpoints" and path.suffix == ".zip" and path.name != "model_0_steps.zip":
                handle.flush()
                handle.truncate(handle.tell() // 2)
                handle.flush()
                Path(marker + ".tmp").write_text(str(path))
                os.replace(marker + ".tmp", marker)
                time.sleep(300)

    rf.atomic_write = slow_atomic_write

from training.train import main

sys.exit(main(sys.argv[1:]))
"""


def assert_run_folder_consistent(out: Path) -> None:
    """Every file under its final name is complete; evaluations are monotone and never beat the best."""
    assert run_folder.read_config(out)["seed"] == 0
    for checkpoint in run_folder.list_checkpoints(out):
        assert run_folder.checkpoint_problem(checkpoint, needs_stats=True) is None, checkpoint
    rows = evaluation_rows(out) if (out / "evaluations.csv").exists() else []
    steps = [int(r["timesteps"]) for r in rows]
    assert steps == sorted(set(steps)), steps
    assert all(None not in row and None not in row.values() for row in rows)
    if (out / ".commit.json").exists():
        return  # killed between the renames of the best model's files: the next start completes them
    best = run_folder.read_best(out)
    if rows:
        assert best is not None
        assert best["return_learned"] >= max(float(r["return_learned"]) for r in rows)
    if best is not None:
        assert (out / "best_model.zip").is_file() and (out / "best_vecnormalize.pkl").is_file()
        PPO.load(out / "best_model.zip", device="cpu")


@pytest.mark.slow  # seven training subprocesses killed at random points: about 25 s
def test_sigkill_at_random_points_never_loses_the_run(tmp_path):
    out = tmp_path / "run"
    marker = tmp_path / "slow-checkpoint"
    rng = random.Random(9)
    kills = 6  # five at seeded random instants, one (the third) in the middle of a checkpoint write
    resumed_at: list[int] = []
    for k in range(kills + 1):
        err_path = tmp_path / f"stderr-{k}.txt"
        resume = k > 0
        args = (
            ["--resume", "--out", str(out), "--quiet"]
            if resume
            else [*TINY, "--set", "n_timesteps=5000", "--out", str(out)]
        )
        final = k == kills
        if final:  # finish the run: 600 steps beyond the newest checkpoint (n_timesteps may change on resume)
            args += ["--set", f"n_timesteps={max(checkpoint_steps(out)) + 600}"]
        slow = k == 2
        env = {**SUBPROCESS_ENV, "SLOW_CHECKPOINT_MARKER": str(marker)} if slow else SUBPROCESS_ENV
        with err_path.open("w") as err_file:
            proc = subprocess.Popen(
                [sys.executable, "-c", KILL_SCRIPT, *args],
                cwd=REPO,
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=err_file,
            )
            if final:
                assert proc.wait(timeout=120) == 0, err_path.read_text()
            else:
                if resume:
                    _wait_for(lambda p=err_path: "resuming from" in p.read_text(), proc, "the resume")
                else:
                    _wait_for(
                        lambda: (out / "checkpoints" / "model_0_steps.zip").exists(), proc, "the first checkpoint"
                    )
                if slow:
                    _wait_for(marker.exists, proc, "the slow checkpoint write")
                else:
                    time.sleep(rng.uniform(0.05, 1.5))
                assert proc.poll() is None, f"run {k} ended before it was killed:\n{err_path.read_text()}"
                proc.send_signal(signal.SIGKILL)
                proc.wait(timeout=30)
        err = err_path.read_text()
        assert "Traceback" not in err, err
        if resume:
            match = re.search(r"resuming from \S+ at (\d+) steps", err)
            assert match, err
            resumed_at.append(int(match.group(1)))
            assert resumed_at == sorted(resumed_at)  # never goes back behind a checkpoint it had
        if slow:
            interrupted = Path(marker.read_text())
            assert not interrupted.exists()  # the half-written checkpoint never appeared under its name
            partial = list(interrupted.parent.glob(f".{interrupted.name}.*"))
            assert len(partial) == 1 and 0 < partial[0].stat().st_size
            slow_steps = int(interrupted.stem.split("_")[1])
        if k == 3:  # the run after the slow write removes its temporary file and resumes from an older checkpoint
            assert f"removed stale temporary file {partial[0]} (left by an interrupted write)" in err
            assert resumed_at[-1] < slow_steps
        assert_run_folder_consistent(out)
    assert "saved" in err and str(out / "model.zip") in err
    assert PPO.load(out / "model.zip", device="cpu").num_timesteps >= resumed_at[-1] + 600
    assert not [p for p in out.rglob(".*") if p.is_file()]  # no temporary file, no journal
    rows = evaluation_rows(out)
    best = json.loads((out / "best_model.json").read_text())
    assert len(rows) >= 3
    assert best["return_learned"] >= max(float(r["return_learned"]) for r in rows)
    # best_model.zip is the model that scored it: a fresh evaluation on the evaluation seeds reproduces the score
    assert reevaluate_best(out) == pytest.approx(best["return_learned"], rel=1e-12)


# =========================================================================== the run-folder contract


def test_a_run_folder_names_its_trainer_and_loads_by_it(run_copy):
    from training.learned import load_sb3_run

    record = run_folder.read_config(run_copy)
    assert list(record)[:3] == ["trainer", "env_id", "seed"] and record["trainer"] == "sb3"
    policy, config = load_sb3_run(run_copy)
    assert config == record and policy.observation_dim == 10 + 4 * 2
    again, _ = load_learned_policy(run_copy)
    obs = np.random.default_rng(0).uniform(-5, 5, (4, policy.observation_dim)).astype(np.float32)
    np.testing.assert_array_equal(again.act_batch(obs), policy.act_batch(obs))


def test_a_run_folder_without_its_trainer_is_refused_naming_the_folder_and_the_field(run_copy):
    record = yaml.safe_load((run_copy / "config.yaml").read_text())
    del record["trainer"]
    (run_copy / "config.yaml").write_text(yaml.safe_dump(record))
    message = f"run folder '{run_copy}': config.yaml has no 'trainer' field"
    with pytest.raises(run_folder.RunFolderError, match=re.escape(message)):
        load_learned_policy(run_copy)
    with pytest.raises(run_folder.RunFolderError, match="'trainer' field"):
        load_learned_policy(run_copy / "model.zip")
    (run_copy / "config.yaml").write_text(yaml.safe_dump({**record, "trainer": "keras"}))
    with pytest.raises(
        run_folder.RunFolderError, match="trainer must be one of \\['rllib', 'sb3', 'torchrl'\\], got 'keras'"
    ):
        load_learned_policy(run_copy)
    (run_copy / "config.yaml").unlink()
    with pytest.raises(run_folder.RunFolderError, match=rf"'{run_copy}' is not a run folder: .* config\.yaml"):
        load_learned_policy(run_copy)


@pytest.mark.parametrize(("key", "new"), [("num_envs", "n_envs"), ("lr", "learning_rate"), ("lmbda", "gae_lambda")])
def test_an_old_key_is_refused_naming_its_new_name(tmp_path, capsys, key, new):
    code, err = run_main([*TINY, "--set", f"{key}=1", "--out", str(tmp_path / "run")], capsys)
    one_line_error(code, err, f"the key '{key}' is now '{new}'")
    assert not (tmp_path / "run").exists()
