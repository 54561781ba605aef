"""``python -m benchmarks.learned_baselines``: the table of learned baselines over training seeds.

Truth: hand-computed statistics of made-up runs (mean, sample standard
deviation, the targets' rules of the learning issue), the markdown document
around the markers left as it was, and a run that already has its result not
trained again. A real smoke run (training and evaluation) is marked slow.
"""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

import benchmarks.learned_baselines as lb

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)


def _record(seed: int, learned: float, reference: float, success: float, change: float, extra=None) -> dict:
    record = {
        "row": "paper_speed",
        "seed": seed,
        "seeds": [10_000, 10_001],
        "learned": {"return": learned, "returns": [learned] * 2, "success": success, "action_change": change},
        "reference": {"return": reference, "returns": [reference] * 2, "success": 1.0, "action_change": 0.01},
    }
    if extra is not None:
        record["reference_extrapolate"] = {"return": extra, "returns": [extra] * 2, "success": 1.0,
                                           "action_change": 0.01}  # fmt: skip
    return record


def test_a_row_s_summary_is_the_mean_and_sample_std_over_seeds_and_applies_the_targets():
    records = [_record(0, -100.0, -90.0, 1.0, 0.02), _record(1, -90.0, -90.0, 0.8, 0.04), {"row": "paper_speed",
               "seed": 2, "failed": "exit 1"}]  # fmt: skip
    s = lb.row_summary(lb.ROWS["paper_speed"], records)
    assert s["seeds"] == [0, 1] and s["failed"] == {"2": "exit 1"}
    assert s["learned"]["return"]["mean"] == -95.0
    assert s["learned"]["return"]["std"] == pytest.approx(np.sqrt(50.0))  # ddof 1: ((5² + 5²) / 1)^½
    assert s["performance"]["per_seed"] == pytest.approx([0.9, 1.0])
    assert s["performance"]["mean"] == pytest.approx(0.95)
    assert s["learned"]["success"]["mean"] == pytest.approx(0.9)
    assert s["smoothness_ratio"]["mean"] == pytest.approx(3.0)  # (2 + 4) / 2 times the reference's 0.01
    assert s["target_met"] and s["smoothness_met"]  # 0.95 ≥ 0.9, 90 % ≥ 80 %, 3.0 ≤ 3
    worse = lb.row_summary(lb.ROWS["paper_speed"], [_record(0, -100.0, -89.0, 1.0, 0.05)])
    assert not worse["target_met"] and not worse["smoothness_met"]  # 0.89 < 0.9, 5× the reference's Δa


def test_a_lossy_channel_row_is_measured_against_the_extrapolating_reference():
    row = lb.ROWS["acoustic_speed"]
    beats = lb.row_summary(row, [{**_record(0, -120.0, -400.0, 0.9, 0.01, extra=-125.0), "row": row.name}])
    assert beats["target_met"]  # 90 % success and a return above the extrapolating reference's
    short = lb.row_summary(row, [{**_record(0, -120.0, -400.0, 0.8, 0.01, extra=-125.0), "row": row.name}])
    below = lb.row_summary(row, [{**_record(0, -130.0, -400.0, 1.0, 0.01, extra=-125.0), "row": row.name}])
    assert not short["target_met"] and not below["target_met"]
    table = lb.format_table([beats], {row.name: 30.0})
    assert "| `acoustic_speed` | sb3 | 30 | 1 | -120.0 | -400.0 | 3.33 | 90% / 100% |" in table
    assert "-125.0, 100%" in table and table.endswith("| met, smooth |")


def test_publishing_replaces_only_the_rows_it_ran_and_keeps_the_others_with_their_provenance(tmp_path):
    header = "| row | minutes |\n|---|---|"
    document = tmp_path / "results.md"
    old = f"{header}\n| `survey_speed` | 30 |\n| `paper_speed` | 15 |\n\n- `survey_speed`: by hand\n- `paper_speed`: x"
    document.write_text(f"# Results\n\nbefore\n\n{lb.MARKERS[0]}\n{old}\n{lb.MARKERS[1]}\n\nafter\n")
    new = f"{header}\n| `any_n_speed` | 31 |\n| ↳ n = 8, `ring` | |\n| `paper_speed` | 16 |"
    lb.publish_markdown(new, dict.fromkeys(("any_n_speed", "paper_speed"), "measured on commit abc"), document)
    text = document.read_text()
    assert text.startswith("# Results\n\nbefore\n\n") and text.endswith("\n\nafter\n")
    block = text.split(lb.MARKERS[0])[1].split(lb.MARKERS[1])[0]
    rows = [line for line in block.splitlines() if line.startswith("| `") or line.startswith("| ↳")]
    # the order of ROWS, not of the document or the call; a generalization row keeps its sub-rows under it
    assert rows == ["| `paper_speed` | 16 |", "| `survey_speed` | 30 |", "| `any_n_speed` | 31 |",
                    "| ↳ n = 8, `ring` | |"]  # fmt: skip
    assert block.count(header) == 1 and "| `paper_speed` | 15 |" not in block
    sources = [line for line in block.splitlines() if line.startswith("- `")]
    assert sources == ["- `paper_speed`: measured on commit abc", "- `survey_speed`: by hand",
                       "- `any_n_speed`: measured on commit abc"]  # fmt: skip
    assert "![any_n_speed: learning curves](learning_curves/any_n_speed.png)" in block
    fresh = tmp_path / "empty.md"
    fresh.write_text("# Results\n")
    lb.publish_markdown(new, dict.fromkeys(("any_n_speed", "paper_speed"), "cmd"), fresh)
    assert fresh.read_text().startswith("# Results\n\n") and fresh.read_text().count(lb.MARKERS[0]) == 1


def test_a_run_with_a_result_is_not_trained_again(tmp_path, monkeypatch):
    folder = tmp_path / "paper_speed" / "seed_4"
    folder.mkdir(parents=True)
    stored = {**_record(4, -80.0, -90.0, 1.0, 0.01), "minutes": 15.0, "episodes": 10}
    (folder / "result.json").write_text(json.dumps(stored))

    def no_training(*args, **kwargs):
        raise AssertionError("trained again")

    monkeypatch.setattr(lb.subprocess, "run", no_training)
    assert lb.run_row_seed(lb.ROWS["paper_speed"], 4, 15.0, 10, tmp_path, fresh=False) == stored
    with pytest.raises(AssertionError, match="trained again"):  # another budget is another run
        lb.run_row_seed(lb.ROWS["paper_speed"], 4, 1.0, 10, tmp_path, fresh=False)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--rows", "paper_speed,fish"], "--rows: unknown row(s) ['fish']"),
        (["--seeds", "0,x"], "expected comma-separated whole numbers ≥ 0, got 'x'"),
        (["--minutes", "0"], "--minutes must be > 0, got 0.0"),
        (["--minutes", "1", "--publish"], "--publish writes the shipped results"),
    ],
)
def test_bad_arguments_are_refused_in_one_line(argv, message, capsys, tmp_path):
    with pytest.raises(SystemExit) as stop:
        lb.main([*argv, "--out", str(tmp_path / "out")])
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_every_row_s_config_exists_and_names_its_scenario():
    from training.config import load_config

    for row in lb.ROWS.values():
        config = load_config(row.path)
        scenario, level = row.name.rsplit("_", 1)
        expected = "paper" if row.generalization else scenario
        assert config["scenario"] == expected and config["env_kwargs"]["action_level"] == level, row.name


def test_the_any_team_row_is_judged_on_every_team_size_and_graph():
    row = lb.ROWS["any_n_speed"]
    assert row.generalization == tuple((n, t) for n in (8, 12, 20) for t in ("ring", "chain", "random"))

    def member(value, success):
        return {"return": value, "returns": [value], "success": success, "action_change": 0.01}

    settings = {"n8_ring": {"learned": member(-100.0, 1.0), "reference": member(-95.0, 1.0)},
                "n20_chain": {"learned": member(-200.0, 1.0), "reference": member(-100.0, 1.0)}}  # fmt: skip
    record = {"row": row.name, "seed": 0, "seeds": [10_000], "settings": settings,
              "learned": member(-150.0, 1.0), "reference": member(-97.5, 1.0)}  # fmt: skip
    s = lb.row_summary(row, [record])
    assert s["settings"]["n8_ring"]["target_met"] and not s["settings"]["n20_chain"]["target_met"]
    assert s["settings"]["n20_chain"]["performance"]["mean"] == 0.5
    assert not s["target_met"]  # one team size fails: the row fails
    table = lb.format_table([s], {row.name: 30.0}).splitlines()
    assert table[3].startswith("| ↳ n = 8, `ring` |") and table[3].endswith("| met, smooth |")
    assert table[4].startswith("| ↳ n = 20, `chain` |") and "| 0.50 |" in table[4]


def test_a_published_row_names_the_commit_its_runs_trained_on_not_only_the_publishing_one():
    def line(commit, runs, command="cmd"):
        return lb._provenance(lb.provenance_fields(commit, runs, command), "paper_force")

    same = line("abc1234", [{"learned": {}, "commit": "abc1234"}], "python -m x --publish")
    assert same.startswith("measured on commit abc1234, ") and same.endswith("with `python -m x --publish`")
    runs = [{"learned": {}, "commit": "feec4e0"}, {"learned": {}, "commit": "feec4e0"}, {"failed": "exit 1"}]
    assert lb.provenance_fields("abc1234", runs, "cmd")["trained_on"] == "feec4e0"
    assert line("abc1234", runs).startswith("trained on commit feec4e0 and published from commit abc1234, ")
    mixed = [
        {"row": "paper_force", "seed": 0, "learned": {}, "commit": "b"},
        {"row": "paper_force", "seed": 1, "learned": {}},
    ]
    assert lb.provenance_fields("abc1234", mixed, "cmd")["trained_on"] == {"seed 0": "b", "seed 1": "unknown"}
    assert line("abc1234", mixed).startswith(
        "trained on several commits (paper_force seed 0 on b, paper_force seed 1 on unknown) and published from commit"
        " abc1234, "
    )


def test_publishing_the_json_replaces_only_the_rows_it_ran_and_its_record_is_the_table_s_line(tmp_path):
    row = lb.ROWS["acoustic_speed"]
    summary = lb.row_summary(row, [{**_record(0, -120.0, -400.0, 0.9, 0.01, extra=-125.0), "row": row.name}])
    fields = {"trained_on": "abc", "commit": "abc", "machine": "m", "command": "c"}
    record = lb.json_record(row, summary, 30.0, "acoustic", "speed", fields)
    line = lb.format_table([summary], {row.name: 30.0}).splitlines()[2]
    for key in ("learned_return", "reference_return", "performance", "action_change_learned"):
        assert f"| {record[key]['text']} |" in line or f"| {record[key]['text']} /" in line, key
    assert record["success_learned"]["mean"] == pytest.approx(90.0) and record["success_learned"]["text"] == "90%"
    assert record["performance"]["mean"] == pytest.approx(400.0 / 120.0)
    assert record["extrapolating_reference"]["return"]["text"] == "-125.0" and record["target"] == "met, smooth"
    assert record["learner"] == "SB3 PPO" and record["config"] == "training/configs/acoustic_speed_ppo.yaml"
    document = tmp_path / "learned_baselines.json"
    document.write_text(json.dumps({"description": "d", "rows": [{"row": "any_n_speed"}, {"row": row.name}]}))
    lb.publish_json([record], document)
    data = json.loads(document.read_text())
    assert data["description"] == "d" and [r["row"] for r in data["rows"]] == ["acoustic_speed", "any_n_speed"]
    assert data["rows"][0] == json.loads(json.dumps(record))


def test_a_run_s_reward_shaping_is_read_from_its_config(tmp_path):
    assert lb._shaping(tmp_path) == {}  # no config.yaml: an SB3 run folder, say
    (tmp_path / "config.yaml").write_text("algo: mappo\ntrain_reward: {}\n")
    assert lb._shaping(tmp_path) == {}
    (tmp_path / "config.yaml").write_text("algo: mappo\ntrain_reward: {sigma_coordination: 5.0}\n")
    assert lb._shaping(tmp_path) == {"sigma_coordination": 5.0}


def test_a_policy_s_description_says_how_its_run_was_trained(tmp_path, monkeypatch):
    monkeypatch.setattr(lb, "_scenario_of", lambda folder: ("paper", {"action_level": "force"}))
    record = {"minutes": 60.0, "seed": 0}
    (tmp_path / "config.yaml").write_text("algo: mappo\ntrain_reward: {sigma_cross_track: 5.0}\ntrain_dt: 0.5\n")
    text = lb._description(lb.ROWS["paper_force"], tmp_path, record)
    assert text.startswith("paper scenario, force level: TorchRL MAPPO, 60 min, training seed 0")
    assert "shaped reward (sigma_cross_track=5.0)" in text and text.endswith("deciding every 0.5 s in training")
    (tmp_path / "config.yaml").write_text("algo: mappo\ntrain_dt: null\n")
    assert "deciding" not in lb._description(lb.ROWS["paper_force"], tmp_path, record)
    (tmp_path / "config.yaml").write_text("algo: mappo\ntrain_dt: 1.0\ndrop_inputs: [lane_offset, linked, age]\n")
    text = lb._description(lb.ROWS["paper_force"], tmp_path, record)
    assert text.endswith("deciding every 1 s in training, not reading lane_offset, linked, age")
    (tmp_path / "config.yaml").write_text("algo: mappo\ndrop_inputs: []\n")
    assert "reading" not in lb._description(lb.ROWS["paper_force"], tmp_path, record)
    (tmp_path / "config.yaml").write_text("algo: ppo\ntemporal_smoothness: 0.01\n")
    assert lb._description(lb.ROWS["paper_force"], tmp_path, record).endswith("temporal smoothness term λ=0.01")
    (tmp_path / "config.yaml").write_text("algo: ppo\ntemporal_smoothness: 0.0\n")
    assert "smoothness" not in lb._description(lb.ROWS["paper_force"], tmp_path, record)


def test_the_learning_curves_draw_the_reference_only_where_the_learner_trained_on_the_benchmark_s_reward(
    tmp_path, monkeypatch
):
    """A shaped row's curve is in its own reward: a reference line beside it would compare different rewards."""
    pytest.importorskip("matplotlib")
    records = []
    for name, shaping in (("paper_speed", "{sigma_coordination: 5.0}"), ("paper_guidance", "{}")):
        for seed, base in ((0, 0), (1, -10_000)):
            folder = tmp_path / name / f"seed_{seed}"
            folder.mkdir(parents=True)
            (folder / "config.yaml").write_text(f"algo: mappo\ntrain_reward: {shaping}\n")
            # minutes 1, 3, 4 (the row at 2 min has no finished episode)
            returns = [base - 300, "", base - 200, base - 100]
            rows = "".join(f"{60 * (k + 1)},{value}\n" for k, value in enumerate(returns))
            (folder / "progress.csv").write_text("wall_time_s,episode_return_mean\n" + rows)
            records.append({"row": name, "seed": seed, "learned": {}, "reference": {"return": -87.0}})
    figures = []
    monkeypatch.setattr(lb, "_save_figure", lambda fig, path: figures.append(fig))
    lb.plot_learning_curves([lb.ROWS["paper_speed"], lb.ROWS["paper_guidance"]], records, tmp_path, tmp_path / "x.png")
    shaped, plain = figures[0].axes[:2]

    def horizontal(ax):
        return [line.get_ydata()[0] for line in ax.get_lines() if len(set(np.asarray(line.get_ydata()))) == 1]

    assert horizontal(shaped) == [] and "shaped training reward" in shaped.get_title()
    assert horizontal(plain) == [-87.0]
    assert "training reward" in shaped.get_ylabel() and plain.get_ylabel() == "episode return"
    assert "against the reference" in figures[0]._suptitle.get_text()
    figures.clear()
    lb.plot_learning_curves([lb.ROWS["paper_speed"]], records, tmp_path, tmp_path / "y.png")
    assert "reference" not in figures[0]._suptitle.get_text()  # no row of the figure has a reference line
    mean = figures[0].axes[0].get_lines()[0].get_ydata()
    assert mean[-1] == pytest.approx((-100 - 10_100) / 2)  # mean of the two seeds at the last common minute


@pytest.mark.slow
def test_a_smoke_run_trains_evaluates_and_plots(tmp_path):
    out = tmp_path / "out"
    argv = ["--rows", "paper_speed,paper_guidance", "--seeds", "0", "--minutes", "0.1", "--episodes", "1",
            "--out", str(out), "--quiet"]  # fmt: skip
    assert lb.main(argv) == 0
    report = json.loads((out / "learned_baselines.json").read_text())
    assert report["complete"] and [r["row"] for r in report["rows"]] == ["paper_speed", "paper_guidance"]
    for row in report["rows"]:
        assert row["seeds"] == [0] and row["learned"]["return"]["mean"] < 0.0
    assert (out / "learning_curves.png").stat().st_size > 0
    assert (out / "episodes" / "paper_guidance.png").stat().st_size > 0


@pytest.mark.slow
def test_publishing_writes_the_table_the_figures_and_loadable_pretrained_policies(tmp_path, monkeypatch):
    import dataclasses

    import baselines.pretrained as pretrained

    rows = {name: dataclasses.replace(lb.ROWS[name], minutes=0.1) for name in ("paper_speed", "any_n_speed")}
    monkeypatch.setattr(lb, "ROWS", rows)
    monkeypatch.setattr(lb, "DOCS", tmp_path / "docs")  # the runs still train from the repository (ROOT)
    monkeypatch.setattr(pretrained, "PRETRAINED_DIR", tmp_path / "shipped")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "results.md").write_text("# Results\n")
    argv = ["--rows", "paper_speed,any_n_speed", "--seeds", "0", "--episodes", "1", "--out", str(tmp_path / "out"),
            "--publish", "--quiet"]  # fmt: skip
    assert lb.main(argv) == 0
    text = (tmp_path / "docs" / "results.md").read_text()
    assert lb.MARKERS[0] in text and "| `paper_speed` | torchrl | 0.1 | 1 |" in text
    assert "| ↳ n = 20, `random` |" in text
    assert (tmp_path / "docs" / "learning_curves" / "any_n_speed.png").is_file()
    assert (tmp_path / "docs" / "episodes" / "any_n_speed.png").is_file()
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=lb.ROOT, capture_output=True, text=True)
    for name in rows:
        _, info = pretrained.load_pretrained(name)
        assert info.training["minutes"] == 0.1 and len(info.evaluation["learned_returns"]) == 1
        # the commit its run trained with, kept by the run's result.json for a later publish
        trained = json.loads((tmp_path / "out" / name / "seed_0" / "result.json").read_text())["commit"]
        assert info.training["commit"] == trained == (head.stdout.strip() or "unknown")
        assert "training seed 0" in info.description and "0.1 min" in info.description
    assert pretrained.load_pretrained("any_n_speed")[1].kind == "slots"
    assert set(pretrained.load_pretrained("any_n_speed")[1].evaluation["settings"]) == {
        f"n{n}_{t}" for n in (8, 12, 20) for t in ("ring", "chain", "random")
    }


def test_member_metrics_measures_each_policy_on_the_same_seeds():
    from baselines.reference import ReferencePolicy
    from baselines.rollout import BatchPolicy
    from marine_formation_env.env import parallel_env
    from training.learned import member_metrics

    class Constant(BatchPolicy):
        def act_batch(self, obs):
            return np.full((*obs.shape[:-1], 1), 0.3)

    env = parallel_env("paper", action_level="speed")
    out = member_metrics({"reference": ReferencePolicy(env), "constant": Constant()}, env.config, [10_000, 10_001])
    reference, constant = out["reference"], out["constant"]
    assert len(reference["returns"]) == 2 and reference["return"] == pytest.approx(np.mean(reference["returns"]))
    # the paper's controller settles the formation (its claim): every episode in the success band (spread ≤ 1 m)
    assert reference["success"] == 1.0 and reference["final_spread"] <= 1.0
    # one speed for every vessel never closes the initial along-path gaps (tens of metres), and never changes
    assert constant["success"] == 0.0 and constant["final_spread"] > 5.0
    assert constant["action_change"] == 0.0 and reference["action_change"] > 0.0
