"""benchmarks.transfer: which settings each shipped policy takes, the best reference, the scores, the command line."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

import marine_formation_env
from baselines.engine import episode_reports
from baselines.pretrained import check_compatible, list_pretrained, load_pretrained
from baselines.reference import ReferencePolicy
from baselines.rollout import RandomPolicy
from baselines.seeds import benchmark_seeds
from benchmarks.transfer import (
    compatibility,
    holds_target,
    level_settings,
    main,
    normalized_score,
    return_ratio,
    transfer,
)
from marine_formation_env.scenarios import GENERATED_INIT_NOISE, SCENARIOS

pytestmark = pytest.mark.backend_independent  # a tool above the env (tests/conftest.py)

INFOS = {info.name: info for info in list_pretrained()}


def _directly(info, scenario, **overrides):
    """Whether ``check_compatible`` accepts the env built here, by hand, at the policy's level."""
    env = marine_formation_env.parallel_env(scenario, action_level=info.action_level, **overrides)
    try:
        check_compatible(info, env.config, env.observation_space(env.possible_agents[0]).shape[0])
    except ValueError:
        return False
    return True


def test_each_policy_takes_what_check_compatible_accepts():
    infos = list(INFOS.values())
    unbuildable = []
    for level in ("speed", "guidance", "force"):
        settings = level_settings(level, infos, list(SCENARIOS), (3, 8, 20), {}, unbuildable)
        labels = [s.label for s in settings]
        # every preset with its own team of 3 is a setting of every level
        assert set(SCENARIOS) <= set(labels)
        for info in (i for i in infos if i.action_level == level):
            for s in settings:
                taken = compatibility(info, s) is None
                assert taken == _directly(info, s.scenario, **s.overrides), (info.name, s.label)
    # by hand: a 3-vessel MLP is refused a team of 8, a slot network takes it; the any-team policy's training team
    # (6 vessels) is refused to the 3-vessel ones
    noise = {"init_noise": GENERATED_INIT_NOISE}
    assert not _directly(INFOS["paper_speed"], "paper", n_vessels=8, topology="ring", **noise)
    assert _directly(INFOS["any_n_speed"], "paper", n_vessels=8, topology="ring", **noise)
    speed = {s.label: s for s in level_settings("speed", infos, list(SCENARIOS), (3, 8, 20), {})}
    assert "cannot take" not in str(compatibility(INFOS["acoustic_speed"], speed["paper n=20 ring"]))
    assert "takes teams of 3 vessels" in str(compatibility(INFOS["paper_speed"], speed["paper n=20 ring"]))
    assert "takes teams of 3 vessels" in str(compatibility(INFOS["survey_speed"], speed["paper n=6 random (training)"]))
    # force has no slot network, so no big teams; a team of 8 on the circle's lanes cannot be built, and says why
    force = level_settings("force", infos, list(SCENARIOS), (3, 8, 20), {})
    assert all(s.env().config.n_vessels == 3 for s in force)
    circle = [u for u in unbuildable if u["label"] == "circle n=8 ring"]
    assert circle and "generalized assumption (19) fails" in circle[0]["reason"]
    with pytest.raises(ValueError, match="lane of vessel_3"):
        marine_formation_env.parallel_env("circle", n_vessels=8, topology="ring")


def test_best_reference_is_the_best_of_the_variants_evaluated_here():
    episodes, horizon = 2, 30.0
    report = transfer(
        ["paper_guidance", "paper_speed"], ["current", "acoustic"], [3], episodes, {"horizon": horizon}, False
    )
    seeds = benchmark_seeds(episodes)
    checked = 0
    for row in report["settings"]:
        level, scenario = row["level"], row["scenario"]
        kwargs = {"action_level": level, "init_noise": GENERATED_INIT_NOISE, "horizon": horizon}
        env = marine_formation_env.parallel_env(scenario, **kwargs)
        mine = {"reference": ReferencePolicy(env)}
        if scenario == "acoustic":
            mine["reference:extrapolate"] = ReferencePolicy(env, extrapolate=True)
        if scenario == "current" and level == "guidance":
            mine["reference:ilos"] = ReferencePolicy(env, integral_los=1.0)
        returns = {
            label: np.mean([e["return"] for e in episode_reports(p, env.config, seeds)[0]]) for label, p in mine.items()
        }
        if scenario == "current" and level == "speed":  # the speed level's integral LOS is the env's
            ilos_env = marine_formation_env.parallel_env(scenario, **kwargs, los_integral_gain=1.0)
            reports = episode_reports(ReferencePolicy(ilos_env), ilos_env.config, seeds)[0]
            returns["reference:ilos"] = np.mean([e["return"] for e in reports])
        assert set(row["reference"]) == set(returns)
        for label, value in returns.items():
            assert row["reference"][label]["return"] == pytest.approx(value, rel=1e-12)
        best = max(returns, key=returns.get)
        assert row["best_reference"] == best
        random = np.mean([e["return"] for e in episode_reports(RandomPolicy(env, seed=0), env.config, seeds)[0]])
        assert row["random"]["return"] == pytest.approx(random, rel=1e-12)
        # the policy's cell is scored against that best variant
        name = f"paper_{level}"
        policy, _ = load_pretrained(name)
        r = np.mean([e["return"] for e in episode_reports(policy, env.config, seeds)[0]])
        cell = next(p for p in report["policies"] if p["name"] == name)["cells"][row["label"]]
        assert cell["return"] == pytest.approx(r, rel=1e-12)
        assert cell["ratio"] == pytest.approx(returns[best] / r)
        assert cell["score"] == pytest.approx((r - random) / (returns[best] - random))
        checked += 1
    assert checked == 6  # current and acoustic at both levels, and each policy's training setting (paper)
    # the variants do differ there: under the current integral LOS beats plain LOS at both levels
    current = [row for row in report["settings"] if row["scenario"] == "current"]
    assert all(row["best_reference"] == "reference:ilos" for row in current)


def test_scores_on_hand_made_numbers():
    # returns ≤ 0: a policy at −50 beside a reference at −100 returns twice as much
    assert return_ratio(-100.0, -50.0) == 2.0
    assert return_ratio(-100.0, -200.0) == 0.5
    assert return_ratio(-100.0, 0.0) is None
    # random −300, reference −100: a policy at −50 is 250/200 of the way from random to the reference
    assert normalized_score(-50.0, -100.0, -300.0) == 1.25
    assert normalized_score(-100.0, -100.0, -300.0) == 1.0
    assert normalized_score(-300.0, -100.0, -300.0) == 0.0
    assert normalized_score(-400.0, -100.0, -300.0) == -0.5
    assert normalized_score(-50.0, -300.0, -300.0) is None


def test_the_target_needs_the_ratio_and_success_where_the_reference_succeeds():
    assert holds_target(0.95, 0.9, 1.0)
    assert not holds_target(0.85, 1.0, 1.0)  # returns too little
    assert not holds_target(None, 1.0, 1.0)  # R = 0: no ratio
    assert not holds_target(1.2, 0.75, 0.8)  # the reference succeeds (80 %), the policy does not
    assert holds_target(1.2, 0.0, 0.75)  # the reference does not succeed either: the return decides
    assert holds_target(0.9, 0.8, 0.8)  # both bars are inclusive


def test_quick_run_end_to_end(tmp_path):
    prefix = tmp_path / "transfer"
    start = time.perf_counter()
    assert main(["--quick", "--out", str(prefix), "--quiet"]) == 0
    assert time.perf_counter() - start < 30.0
    report = json.loads(prefix.with_suffix(".json").read_text())
    assert report["provenance"]["command"].startswith("python -m benchmarks.transfer --quick")
    assert {"commit", "machine"} <= set(report["provenance"])
    assert report["episodes"] == 2 and report["seeds"] == benchmark_seeds(2)
    assert prefix.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = prefix.with_suffix(".md").read_text()
    assert "Precision on the training setting" in text and "✗ team size" in text
    assert "## The generalization target" in text
    policies = {p["name"]: p for p in report["policies"]}
    assert set(policies) == set(INFOS)
    # the 3-vessel MLPs are listed as refusing the team of 8, with check_compatible's reason
    refused = policies["paper_speed"]["cells"]["paper n=8 ring"]
    assert not refused["compatible"] and "takes teams of 3 vessels" in refused["reason"]
    assert policies["any_n_speed"]["cells"]["paper n=8 ring"]["compatible"]
    for row in report["settings"]:
        assert row["horizon"] == 20.0
    # every policy has a precision row on its training setting
    assert [p["policy"] for p in report["precision"]] == [p["name"] for p in report["policies"]]
    assert policies["any_n_speed"]["training_setting"] == "paper n=6 random (training)"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--episodes", "0"], "--episodes"),
        (["--preset", "lake"], "no preset 'lake'"),
        (["--policy", "paper_sail"], "no pretrained policy ['paper_sail']"),
        (["--team", "5"], "team size 5 is not in the grid"),
        (["--set", "action_level=force"], "--set action_level"),
        (["--set", "horizon=-1"], "horizon"),
    ],
)
def test_bad_arguments_are_refused_in_one_line(argv, message, capsys, tmp_path):
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--quick", "--quiet", "--out", str(tmp_path / "t")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "t.json").exists()


def test_a_speed_policy_trained_on_integral_los_keeps_it_everywhere():
    from baselines.pretrained import PretrainedInfo
    from benchmarks.transfer import policy_overrides

    def info(level, **env_kwargs):
        return PretrainedInfo("p", "paper", {"action_level": level, **env_kwargs}, level, None, None, 1)

    assert policy_overrides(info("speed", los_integral_gain=1.0)) == {"los_integral_gain": 1.0}
    assert policy_overrides(info("speed")) == {}
    assert policy_overrides(info("speed", los_integral_gain=0.0)) == {}
    assert policy_overrides(info("guidance")) == {}  # a guidance policy steers itself
