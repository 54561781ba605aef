"""Pretrained policies (``baselines.pretrained``) and ``baselines.evaluate --policy pretrained:NAME``.

Truth: the library's own deterministic action of the exported run (SB3's
``predict(deterministic=True)`` behind its ``VecNormalize``; TorchRL's
squashed mode), which the numpy network must reproduce; the refusal rules of
the learning issue (team size, action level, layout; another scenario with
the same layout is allowed); and, for every shipped file, the return its
header claims, re-measured here.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

import baselines.pretrained as pretrained
from baselines import evaluate as evaluate_module
from baselines.engine import episode_reports
from baselines.pretrained import (
    MLPPolicy,
    PretrainedInfo,
    check_compatible,
    list_pretrained,
    load_pretrained,
    save_pretrained,
)
from marine_formation_env import ENV_ID, parallel_env
from marine_formation_env.scenarios import make_config

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)

REPO = Path(__file__).resolve().parents[1]
SHIPPED = sorted(pretrained.PRETRAINED_DIR.glob("*.npz"))


def _tiny_policy(obs_dim: int = 18, action_dim: int = 1, seed: int = 0) -> MLPPolicy:
    rng = np.random.default_rng(seed)
    sizes = [obs_dim, 8, 8, action_dim]
    weights = [rng.normal(size=(a, b)) / np.sqrt(a) for a, b in itertools.pairwise(sizes)]
    biases = [rng.normal(size=b) * 0.1 for b in sizes[1:]]
    return MLPPolicy(weights, biases, rng.normal(size=obs_dim), 1.0 + rng.random(obs_dim), 10.0, "tanh", action_dim)


def _info(name: str = "tiny", **changes) -> PretrainedInfo:
    fields = dict(
        name=name,
        scenario="paper",
        env_kwargs={"action_level": "speed"},
        action_level="speed",
        n_vessels=3,
        observation_dim=18,
        action_dim=1,
        description="a random network",
    )
    fields.update(changes)
    return PretrainedInfo(**fields)


def test_the_mlp_is_the_formula_of_its_docstring():
    policy = _tiny_policy()
    obs = np.random.default_rng(1).normal(size=(5, 3, 18)) * 30.0
    x = np.clip((obs - policy.mean) / policy.std, -10.0, 10.0)
    x = np.tanh(x @ policy.weights[0] + policy.biases[0])
    x = np.tanh(x @ policy.weights[1] + policy.biases[1])
    expected = np.tanh(x @ policy.weights[2] + policy.biases[2])
    np.testing.assert_allclose(policy.act_batch(obs), expected, rtol=1e-6, atol=1e-7)  # float32 output
    assert policy.act_batch(obs).shape == (5, 3, 1)
    with pytest.raises(ValueError, match="observations of size 17 given, this policy takes 18"):
        policy.act_batch(obs[..., :17])


def test_a_saved_policy_reloads_with_its_header_and_acts_the_same(tmp_path):
    policy = _tiny_policy()
    path = save_pretrained(policy, _info(), tmp_path)
    assert path == tmp_path / "tiny.npz" and not list(tmp_path.glob(".*tmp*"))
    loaded, info = load_pretrained("tiny", tmp_path)
    assert info == _info() and loaded.info == info
    obs = np.random.default_rng(2).normal(size=(7, 18))
    np.testing.assert_array_equal(loaded.act_batch(obs), policy.act_batch(obs))
    assert [i.name for i in list_pretrained(tmp_path)] == ["tiny"]


def test_unknown_and_unreadable_policies_are_named(tmp_path):
    save_pretrained(_tiny_policy(), _info("known"), tmp_path)
    with pytest.raises(ValueError, match=r"no pretrained policy 'nope'; shipped: \['known'\]"):
        load_pretrained("nope", tmp_path)
    (tmp_path / "broken.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"broken\.npz is not a readable pretrained policy"):
        load_pretrained("broken", tmp_path)
    whole = save_pretrained(_tiny_policy(), _info("cut"), tmp_path).read_bytes()
    (tmp_path / "cut.npz").write_bytes(whole[: len(whole) // 2])  # a copy interrupted half-way
    with pytest.raises(ValueError, match=r"cut\.npz is not a readable pretrained policy \(BadZipFile"):
        load_pretrained("cut", tmp_path)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"action_level": "guidance"}, "acts at action_level 'speed', this scenario has 'guidance'"),
        ({"n_vessels": 5, "topology": "ring"}, "takes teams of 3 vessels, this scenario has n_vessels = 5"),
    ],
)
def test_a_scenario_the_policy_cannot_take_is_refused(changes, message):
    cfg = make_config("paper", **changes)
    env = parallel_env("paper", **changes)
    with pytest.raises(ValueError, match=message):
        check_compatible(_info(), cfg, env.observation_space("vessel_0").shape[0])


def test_another_layout_or_env_version_is_refused_and_another_scenario_is_allowed():
    with pytest.raises(ValueError, match="takes observations of size 18, this scenario gives 22"):
        check_compatible(_info(), make_config("paper"), 22)
    with pytest.raises(ValueError, match=f"reads another observation layout than {ENV_ID}"):
        check_compatible(_info(env_id="MarineFormation-v0"), make_config("paper"), 18)
    for scenario in ("acoustic", "radio", "circle"):  # same team, level and layout: a generalization test
        env = parallel_env(scenario, action_level="speed")
        check_compatible(_info(), env.config, env.observation_space("vessel_0").shape[0])


def test_evaluate_runs_a_pretrained_policy_next_to_the_reference_and_refuses_a_wrong_level(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.setattr(pretrained, "PRETRAINED_DIR", tmp_path)
    save_pretrained(_tiny_policy(), _info(env_kwargs={"action_level": "speed", "horizon": 20.0}), tmp_path)
    out = tmp_path / "report.json"
    args = ["--policy", "pretrained:tiny", "--policy", "reference", "--episodes", "2", "--quiet", "--json", str(out)]
    assert evaluate_module.main(args) == 0
    report = json.loads(out.read_text())
    assert report["overrides"]["horizon"] == 20.0  # the header's env overrides are the default
    env = parallel_env("paper", action_level="speed", horizon=20.0)
    direct, _ = episode_reports(load_pretrained("tiny", tmp_path)[0], env.config, [0, 1])
    assert report["policies"]["pretrained:tiny"]["summary"]["return"]["mean"] == pytest.approx(
        np.mean([m["return"] for m in direct]), rel=1e-12
    )
    with pytest.raises(SystemExit):
        evaluate_module.main(["--policy", "pretrained:tiny", "--set", "action_level=force", "--quiet"])
    assert "acts at action_level 'speed', this scenario has 'force'" in capsys.readouterr().err
    assert evaluate_module.main(["--list-pretrained"]) == 0
    listing = capsys.readouterr().out.splitlines()
    assert listing[0].split()[:4] == ["name", "scenario", "level", "vessels"]
    assert listing[1].split()[:4] == ["tiny", "paper", "speed", "3"]


# ----------------------------------------------------------------------------- export from the trainers


def test_an_exported_sb3_run_acts_as_sb3_s_deterministic_policy(tmp_path):
    pytest.importorskip("stable_baselines3")
    import torch

    from training import train as train_module
    from training.export import export_run
    from training.learned import load_learned_policy

    torch.set_num_threads(1)
    run = tmp_path / "run"
    config = REPO / "training" / "configs" / "paper_speed_ppo.yaml"
    sets = ["n_timesteps=600", "n_envs=2", "n_steps=64", "batch_size=128", "eval_freq=600", "eval_episodes=1",
            "checkpoint_freq=600", "env_kwargs.horizon=20.0"]  # fmt: skip
    argv = ["--config", str(config), "--seed", "0", "--quiet", "--out", str(run)]
    for item in sets:
        argv += ["--set", item]
    assert train_module.main(argv) == 0
    path = export_run(run, "sb3_tiny", "smoke", tmp_path / "shipped")
    exported, info = load_pretrained("sb3_tiny", tmp_path / "shipped")
    assert path.stat().st_size < 50_000
    # the header carries the run's closing evaluation (evaluation.json: eval_episodes=1 on the evaluation seeds)
    assert info.evaluation == json.loads((run / "evaluation.json").read_text())
    assert info.evaluation["seeds"] == [10_000] and len(info.evaluation["learned_returns"]) == 1
    assert (info.scenario, info.action_level, info.n_vessels, info.training["pipeline"]) == ("paper", "speed", 3, "sb3")
    original, _ = load_learned_policy(run)
    obs = np.stack([o for o, _ in (_observations(s) for s in range(4))]).reshape(-1, info.observation_dim)
    obs = np.concatenate([obs, obs * 3.0])  # beyond the normalization's clip too
    # torch float32 against numpy float64: agree to float32 rounding of a 64-wide network
    np.testing.assert_allclose(exported.act_batch(obs), original.act_batch(obs), atol=2e-5)


@pytest.mark.parametrize(
    ("distribution", "scale", "action_scale"),
    [
        ("tanh_normal", "state_dependent", 1.0),
        ("normal", "state_dependent", 1.0),
        ("normal", "state_independent", 1.0),
        ("normal", "state_dependent", 0.05),  # the action units are folded into the last layer's means
    ],
)
def test_an_exported_torchrl_run_acts_as_torchrl_s_deterministic_policy(tmp_path, distribution, scale, action_scale):
    pytest.importorskip("torchrl")
    from training.export import export_run
    from training.torchrl_networks import load_torch_policy
    from training.torchrl_ppo import main as torchrl_main

    run = tmp_path / "run"
    argv = ["--out", str(run), "--no-progress"]
    for item in ["n_envs=4", "frames_per_batch=40", "total_frames=80", "minibatch_size=20", "n_epochs=1",
                 "eval_episodes=1", "hidden=[16, 16]", "env_kwargs.horizon=4.0", "env_kwargs.action_level=speed",
                 "normalize_observations=true", f"distribution={distribution}", f"scale={scale}",
                 f"action_scale={action_scale}"]:  # fmt: skip
        argv += ["--set", item]
    assert torchrl_main(argv) == 0
    export_run(run, "torchrl_tiny", "smoke", tmp_path / "shipped")
    exported, info = load_pretrained("torchrl_tiny", tmp_path / "shipped")
    assert info.training["pipeline"] == "torchrl" and info.evaluation["learned_return"] < 0.0
    assert str(np.load(tmp_path / "shipped" / "torchrl_tiny.npz")["squash"]) == (
        "clip" if distribution == "normal" else "tanh"
    )
    original, _ = load_torch_policy(run)
    obs = np.stack([o for o, _ in (_observations(s) for s in range(4))]).reshape(-1, info.observation_dim)
    np.testing.assert_allclose(exported.act_batch(obs), original.act_batch(obs), atol=2e-5)
    assert not np.allclose(exported.mean, 0.0)  # the running norm's statistics came along


def _observations(seed: int) -> tuple[np.ndarray, dict]:
    env = parallel_env("paper", action_level="speed", init_noise={"x": 40.0, "y": 20.0, "psi": 0.3, "u": 1.0})
    obs, infos = env.reset(seed=seed)
    return np.stack(list(obs.values())), infos


# ----------------------------------------------------------------------------- the shipped files


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_a_shipped_policy_is_small_and_reproduces_the_return_its_header_claims(path):
    policy, info = load_pretrained(path.stem)
    assert path.stat().st_size < 400_000
    assert info.name == path.stem and info.env_id == ENV_ID
    env = parallel_env(info.scenario, **info.env_kwargs)
    check_compatible(info, env.config, env.observation_space("vessel_0").shape[0])
    seeds = info.evaluation["seeds"][:3]
    learned, _ = episode_reports(policy, env.config, seeds)
    claimed = info.evaluation["learned_returns"][:3]
    # the header was measured with the trainer's torch network, this is the numpy copy: float32 against float64
    # rounding in a closed loop that contracts, so the returns agree far inside 1 %
    np.testing.assert_allclose([m["return"] for m in learned], claimed, rtol=1e-2)


def test_every_pretrained_policy_the_documentation_names_is_shipped():
    import re

    named = set()
    for page in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), REPO / "baselines" / "pretrained.py"]:
        named |= set(re.findall(r"pretrained:([A-Za-z0-9_]+)", page.read_text()))
    named -= {"NAME"}
    shipped = {path.stem for path in SHIPPED}
    assert named and named <= shipped, f"named in the docs but not shipped: {sorted(named - shipped)}"
