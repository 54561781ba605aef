"""Generalization: every shipped policy, zero-shot, on every preset it can take.

For each action level of a shipped policy (``baselines.pretrained``), the grid
of settings is every preset (``marine_formation_env.scenarios.SCENARIOS``) at
that level, with the preset's team of 3 and, where a policy of that level
takes any team (a slot network), teams of 8 and 20 vessels on a ring (on the
presets of horizon ≤ 400 s: not the two 2000 s surveys); plus the
training setting of each policy of that level (``info.scenario``,
``info.env_kwargs``). Every setting draws each episode's initial state with
``GENERATED_INIT_NOISE`` (the noise every shipped policy was trained with, and
the one a generated team gets), so that its seeds are different starts.

Each policy is run on every setting of its level that ``check_compatible``
accepts; a setting it refuses is listed with the reason. A speed-level policy
trained with the env's integral LOS runs with it everywhere
(``policy_overrides``): the path follower is part of what it learned on.
Per setting, once for all policies: the reference's variants that apply there (``reference``;
``reference:extrapolate`` over a lossy channel; integral LOS under a current:
``ReferencePolicy(integral_los=1)`` at guidance and force,
``los_integral_gain = 1`` at speed, where the env steers) and the random
policy. Per cell: the policy's mean return R, success, final spread and final
max |e|; the best reference variant's return R_ref (the highest mean return),
which variant and its success; ``R_ref / R`` (returns are ≤ 0, so > 1: the
policy returns more) and the normalized score ``(R − R_rand) / (R_ref − R_rand)``
(1: the best reference, 0: random); and whether the cell holds the generalization
target (``holds_target``: R_ref / R ≥ 0.9, and success ≥ 80 % wherever the
best reference reaches 80 %). Then, for each policy on its own training
setting, the final spread and max |e| (mean and max over episodes) beside the
best reference's, on the same seeds. Every run uses the reserved benchmark
seeds (``baselines.seeds.benchmark_seeds``)::

    python -m benchmarks.transfer --out docs/transfer
    python -m benchmarks.transfer --quick --out /tmp/transfer     # 2 episodes, 20 s, paper and acoustic
    python -m benchmarks.transfer --preset paper --preset current --team 3 --episodes 5

Writes ``OUT.json`` (with provenance), ``OUT.md`` (the tables) and ``OUT.png``
(a heat map of the normalized score, one row per policy).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baselines.engine import episode_reports
from baselines.evaluate import DEFAULT_ILOS_GAIN, progress_bar
from baselines.plots import save_figure, write_report
from baselines.pretrained import PretrainedInfo, check_compatible, list_pretrained, load_pretrained
from baselines.reference import ReferencePolicy
from baselines.rollout import RandomPolicy
from baselines.seeds import benchmark_seeds
from marine_formation_env.atomic import check_writable
from marine_formation_env.cli import ArgumentParser, int_at_least, parse_overrides
from marine_formation_env.env import parallel_env
from marine_formation_env.provenance import command_line
from marine_formation_env.render import require_matplotlib
from marine_formation_env.scenarios import GENERATED_INIT_NOISE, SCENARIOS, ScenarioConfig

__all__ = [
    "BIG_TEAMS",
    "Setting",
    "best_reference",
    "compatibility",
    "holds_target",
    "level_settings",
    "main",
    "normalized_score",
    "policy_overrides",
    "reference_variants",
    "return_ratio",
    "transfer",
]

#: Teams a slot network (any team) is also run on, besides the preset's own: (vessels, topology).
BIG_TEAMS = ((8, "ring"), (20, "ring"))
#: Teams of ``BIG_TEAMS`` run on presets of at most this horizon [s]: the two 2000 s survey presets at 8 and
#: 20 vessels would take most of the run's time (their curved-path metrics dominate).
BIG_TEAM_MAX_HORIZON = 400.0
#: ``--quick``: episodes, horizon [s], presets and team sizes.
QUICK_EPISODES, QUICK_HORIZON, QUICK_PRESETS, QUICK_TEAMS = 2, 20.0, ("paper", "acoustic"), (3, 8)
#: The generalization target of a cell: R_ref / R at least TARGET_RATIO, and a success rate at least
#: TARGET_SUCCESS wherever the best reference's reaches TARGET_SUCCESS.
TARGET_RATIO, TARGET_SUCCESS = 0.9, 0.8
#: Seed of the random policy's action stream.
RANDOM_SEED = 0


@dataclass(frozen=True)
class Setting:
    """One column of the grid: a scenario and its overrides, at one action level.

    ``label`` names it across levels (``paper``, ``acoustic n=8 ring``, ``paper n=6 random (training)``).
    """

    label: str
    scenario: str
    overrides: dict[str, Any] = field(hash=False)
    level: str

    def env(self, extra: dict[str, Any] | None = None) -> Any:
        return parallel_env(self.scenario, **{**self.overrides, "action_level": self.level, **(extra or {})})


def _team_label(scenario: str, n: int | None, topology: str | None) -> str:
    return scenario if n is None else f"{scenario} n={n} {topology}"


def _config_key(env: Any) -> str:
    return json.dumps(env.config.to_dict(), sort_keys=True, default=repr)


def level_settings(
    level: str,
    infos: Sequence[PretrainedInfo],
    presets: Sequence[str],
    teams: Sequence[int],
    overrides: dict[str, Any],
    unbuildable: list[dict[str, Any]] | None = None,
) -> list[Setting]:
    """The settings of ``level``: each preset with its own team (if 3 is in ``teams``) and, if some policy of
    the level takes any team, with the ``BIG_TEAMS`` in ``teams``; then each policy's training setting not
    already among them (same configuration). ``overrides`` apply to every setting. A preset's big team that
    cannot be built (``ValueError``) is left out and, if ``unbuildable`` is a list, appended to it with the reason."""
    of_level = [info for info in infos if info.action_level == level]
    any_team = any(info.n_vessels is None for info in of_level)
    noise = {"init_noise": GENERATED_INIT_NOISE}
    out: list[Setting] = []
    for preset in presets:
        if 3 in teams:
            out.append(Setting(preset, preset, {**noise, **overrides}, level))
        if any_team and parallel_env(preset, **overrides).config.horizon <= BIG_TEAM_MAX_HORIZON:
            for n, topology in BIG_TEAMS:
                if n in teams:
                    label = _team_label(preset, n, topology)
                    out.append(
                        Setting(label, preset, {**noise, "n_vessels": n, "topology": topology, **overrides}, level)
                    )
    for s in list(out):  # a team the preset cannot hold (a path too tight for its lanes): listed, not run
        try:
            s.env().close()
        except ValueError as err:
            if unbuildable is not None:
                unbuildable.append({"label": s.label, "level": level, "reason": str(err)})
            out.remove(s)
    seen = {_config_key(s.env()): s for s in out}
    for info in of_level:
        kwargs = {k: v for k, v in info.env_kwargs.items() if k != "action_level"}
        candidate = Setting(info.scenario, info.scenario, {**kwargs, **overrides}, level)
        key = _config_key(candidate.env())
        if key in seen:
            continue
        cfg, preset_cfg = candidate.env().config, parallel_env(info.scenario).config
        own_team = cfg.n_vessels == preset_cfg.n_vessels and cfg.topology == preset_cfg.topology
        label = f"{_team_label(info.scenario, None if own_team else cfg.n_vessels, cfg.topology.name)} (training)"
        seen[key] = Setting(label, info.scenario, candidate.overrides, level)
        out.append(seen[key])
    return out


def training_setting(info: PretrainedInfo, settings: Sequence[Setting], overrides: dict[str, Any]) -> Setting:
    """The setting among ``settings`` whose configuration is ``info``'s training one (with ``overrides``)."""
    kwargs = {k: v for k, v in info.env_kwargs.items() if k != "action_level"}
    key = _config_key(Setting(info.scenario, info.scenario, {**kwargs, **overrides}, info.action_level).env())
    for setting in settings:
        if setting.level == info.action_level and _config_key(setting.env()) == key:
            return setting
    raise ValueError(f"the training setting of {info.name!r} is not in the grid")


def compatibility(info: PretrainedInfo, setting: Setting) -> str | None:
    """None if ``info``'s policy can run on ``setting``, else ``check_compatible``'s reason."""
    env = setting.env()
    try:
        check_compatible(info, env.config, env.observation_space(env.possible_agents[0]).shape[0])
    except ValueError as err:
        return str(err)
    finally:
        env.close()
    return None


def reference_variants(config: ScenarioConfig) -> dict[str, tuple[dict[str, Any], dict[str, Any]]]:
    """The reference variants that apply to ``config``: ``{label: (ReferencePolicy kwargs, env overrides)}``.

    ``reference`` always; ``reference:extrapolate`` when observations are not ideal (over ideal links it is the
    plain reference); integral LOS (σ = ``DEFAULT_ILOS_GAIN``) under a current: the policy's at guidance and force,
    the env's ``los_integral_gain`` at speed (the env steers there); both when both apply. Where the policies
    decide when to broadcast (``transmit``), every variant broadcasts by the channel's rule instead.
    """
    lossy = not config.ideal_observations
    current = not config.current.is_zero
    out: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {"reference": ({}, {})}
    ilos: tuple[dict[str, Any], dict[str, Any]] = (
        ({}, {"los_integral_gain": DEFAULT_ILOS_GAIN})
        if config.action_level == "speed"
        else ({"integral_los": DEFAULT_ILOS_GAIN}, {})
    )
    if lossy:
        out["reference:extrapolate"] = ({"extrapolate": True}, {})
    if current:
        out["reference:ilos"] = ilos
    if lossy and current:
        out["reference:extrapolate,ilos"] = ({"extrapolate": True, **ilos[0]}, ilos[1])
    if config.transmit:  # the reference does not send the transmit action: it broadcasts by the channel's rule
        out = {label: (kwargs, {**extra, "transmit": False}) for label, (kwargs, extra) in out.items()}
    return out


def policy_overrides(info: PretrainedInfo) -> dict[str, Any]:
    """The env settings a policy takes with it to every setting: a speed-level policy trained with the env's
    integral LOS (``los_integral_gain`` > 0) keeps that path follower, which is part of what it learned on."""
    gain = info.env_kwargs.get("los_integral_gain", 0.0)
    return {"los_integral_gain": gain} if info.action_level == "speed" and gain else {}


def best_reference(summaries: dict[str, dict[str, Any]]) -> str:
    """The variant with the highest mean return (the first listed on a tie)."""
    return max(summaries, key=lambda label: summaries[label]["return"])


def return_ratio(reference_return: float, policy_return: float) -> float | None:
    """``R_ref / R`` (returns ≤ 0: > 1 means the policy returns more); None if R = 0."""
    return None if policy_return == 0 else reference_return / policy_return


def normalized_score(policy_return: float, reference_return: float, random_return: float) -> float | None:
    """``(R − R_rand) / (R_ref − R_rand)``: 1 at the reference, 0 at random; None if R_ref = R_rand."""
    span = reference_return - random_return
    return None if span == 0 else (policy_return - random_return) / span


def holds_target(ratio: float | None, success: float, reference_success: float) -> bool:
    """``R_ref / R ≥ TARGET_RATIO``, and ``success ≥ TARGET_SUCCESS`` if ``reference_success ≥ TARGET_SUCCESS``."""
    if ratio is None or ratio < TARGET_RATIO:
        return False
    return reference_success < TARGET_SUCCESS or success >= TARGET_SUCCESS


def _summary(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    spread = [e["final_coordination_spread"] for e in episodes]
    cross = [e["final_cross_track_max"] for e in episodes]
    return {
        "return": float(np.mean([e["return"] for e in episodes])),
        "return_std": float(np.std([e["return"] for e in episodes])),
        "success": float(np.mean([e["success"] for e in episodes])),
        "final_spread": float(np.mean(spread)),
        "final_spread_max": float(np.max(spread)),
        "final_cross_track_max": float(np.mean(cross)),
        "final_cross_track_max_max": float(np.max(cross)),
        "action_change": float(np.mean([e["action_change"] for e in episodes])),
        "collision_rate": float(np.mean([e["collision"] for e in episodes])),
    }


def _run(policy: Any, config: ScenarioConfig, seeds: Sequence[int]) -> dict[str, Any]:
    return _summary(episode_reports(policy, config, seeds)[0])


def transfer(
    names: Sequence[str] | None,
    presets: Sequence[str],
    teams: Sequence[int],
    episodes: int,
    overrides: dict[str, Any],
    progress: bool = True,
) -> dict[str, Any]:
    """Run the grid (module docstring) and return a JSON-friendly report."""
    infos = list_pretrained()
    if names:
        known = {info.name: info for info in infos}
        unknown = [name for name in names if name not in known]
        if unknown:
            raise ValueError(f"no pretrained policy {unknown}; shipped: {sorted(known)}")
        infos = [known[name] for name in names]
    for preset in presets:
        if preset not in SCENARIOS:
            raise ValueError(f"no preset {preset!r}; presets: {sorted(SCENARIOS)}")
    for n in teams:
        if n != 3 and n not in {size for size, _ in BIG_TEAMS}:
            raise ValueError(f"team size {n} is not in the grid; sizes: {[3] + [size for size, _ in BIG_TEAMS]}")
    seeds = benchmark_seeds(episodes)
    levels = list(dict.fromkeys(info.action_level for info in infos))
    unbuildable: list[dict[str, Any]] = []
    settings = [s for level in levels for s in level_settings(level, infos, presets, teams, overrides, unbuildable)]
    cells: dict[str, dict[str, Any]] = {info.name: {} for info in infos}
    runs: list[tuple[PretrainedInfo, Setting]] = []
    for info in infos:
        for s in settings:
            if s.level != info.action_level:
                continue
            reason = compatibility(info, s)
            cells[info.name][s.label] = {"compatible": reason is None, "reason": reason}
            if reason is None:
                runs.append((info, s))
    variants = {id(s): reference_variants(s.env().config) for s in settings}
    total = episodes * (len(runs) + sum(len(v) + 1 for v in variants.values()))
    bar = progress_bar(total, progress, desc="transfer")
    rows: list[dict[str, Any]] = []
    for s in settings:
        env = s.env()
        config = env.config
        references: dict[str, dict[str, Any]] = {}
        for label, (kwargs, extra) in variants[id(s)].items():
            ref_env = s.env(extra) if extra else env
            references[label] = _run(ReferencePolicy(ref_env, **kwargs), ref_env.config, seeds)
            if bar is not None:
                bar.update(episodes)
        random = _run(RandomPolicy(env, seed=RANDOM_SEED), config, seeds)
        if bar is not None:
            bar.update(episodes)
        best = best_reference(references)
        rows.append(
            {
                "label": s.label,
                "level": s.level,
                "scenario": s.scenario,
                "overrides": {
                    k: v if isinstance(v, (int, float, str, bool)) else repr(v) for k, v in s.overrides.items()
                },
                "n_vessels": config.n_vessels,
                "topology": config.topology.name,
                "horizon": config.horizon,
                "reference": references,
                "best_reference": best,
                "random": random,
            }
        )
        ref_return, rand_return = references[best]["return"], random["return"]
        for info, setting in runs:
            if setting is not s:
                continue
            policy, _ = load_pretrained(info.name)
            carried = policy_overrides(info)
            result = _run(policy, s.env(carried).config if carried else config, seeds)
            if carried:
                result["env_overrides"] = carried
            result["ratio"] = return_ratio(ref_return, result["return"])
            result["score"] = normalized_score(result["return"], ref_return, rand_return)
            result["holds_target"] = holds_target(result["ratio"], result["success"], references[best]["success"])
            cells[info.name][s.label].update(result)
            if bar is not None:
                bar.update(episodes)
        env.close()
    if bar is not None:
        bar.close()
    by_label = {(row["level"], row["label"]): row for row in rows}
    policies: list[dict[str, Any]] = []
    for info in infos:
        own = training_setting(info, settings, overrides)
        policies.append(
            {
                "name": info.name,
                "level": info.action_level,
                "kind": info.kind,
                "n_vessels": info.n_vessels,
                "training_setting": own.label,
                "cells": cells[info.name],
            }
        )
    precision = []
    for entry in policies:
        row = by_label[(entry["level"], entry["training_setting"])]
        mine, ref = entry["cells"][entry["training_setting"]], row["reference"][row["best_reference"]]
        precision.append(
            {
                "policy": entry["name"],
                "setting": entry["training_setting"],
                "reference": row["best_reference"],
                **{
                    f"{who}_{key}": part[key]
                    for who, part in (("policy", mine), ("ref", ref))
                    for key in (
                        "final_spread",
                        "final_spread_max",
                        "final_cross_track_max",
                        "final_cross_track_max_max",
                    )
                },
            }
        )
    return {
        "episodes": episodes,
        "seeds": seeds,
        "presets": list(presets),
        "teams": list(teams),
        "overrides": {k: v if isinstance(v, (int, float, str, bool)) else repr(v) for k, v in overrides.items()},
        "init_noise": repr(GENERATED_INIT_NOISE),
        "settings": rows,
        "unbuildable": unbuildable,
        "policies": policies,
        "precision": precision,
    }


# ----------------------------------------------------------------------------- tables and figure


def _fmt(value: float | None, spec: str) -> str:
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def _short_reason(reason: str) -> str:
    if "takes teams of" in reason:
        return "✗ team size"
    if "observations of size" in reason:
        return "✗ layout"
    return "✗"


def format_matrix(report: dict[str, Any]) -> str:
    """Policies × settings: ``R_ref/R · success`` of each cell (✗: a setting the policy cannot take)."""
    labels = list(dict.fromkeys(row["label"] for row in report["settings"]))
    out = [
        "| policy (level) | " + " | ".join(labels) + " |",
        "|---|" + "---|" * len(labels),
    ]
    for entry in report["policies"]:
        cells = []
        for label in labels:
            cell = entry["cells"].get(label)
            if cell is None:
                cells.append("")
            elif not cell["compatible"]:
                cells.append(_short_reason(cell["reason"]))
            else:
                mark = " ‡" if label == entry["training_setting"] else ""
                cells.append(f"{_fmt(cell['ratio'], '.2f')} · {cell['success']:.0%}{mark}")
        out.append(f"| {entry['name']} ({entry['level']}) | " + " | ".join(cells) + " |")
    return "\n".join(out)


def format_target(report: dict[str, Any]) -> str:
    """Per policy: the settings it takes, how many hold the target, and the ones that do not."""
    out = ["| policy (level) | settings taken | target held | not held (R_ref/R · success) |", "|---|---|---|---|"]
    for entry in report["policies"]:
        taken = {label: cell for label, cell in entry["cells"].items() if cell["compatible"]}
        missed = [
            f"{label} ({_fmt(cell['ratio'], '.2f')} · {cell['success']:.0%})"
            for label, cell in taken.items()
            if not cell["holds_target"]
        ]
        out.append(
            f"| {entry['name']} ({entry['level']}) | {len(taken)} | {len(taken) - len(missed)} "
            f"| {', '.join(missed) or '–'} |"
        )
    return "\n".join(out)


def format_cells(report: dict[str, Any]) -> str:
    """Every cell, one row: the policy's numbers beside the best reference's and random's."""
    rows = {(row["level"], row["label"]): row for row in report["settings"]}
    out = [
        "| policy | setting | R | success | final spread [m] | final max \\|e\\| [m] | best reference | R_ref "
        "| ref. success | R_rand | R_ref/R | score |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for entry in report["policies"]:
        for label, cell in entry["cells"].items():
            row = rows[(entry["level"], label)]
            own = " ‡" if label == entry["training_setting"] else ""
            if not cell["compatible"]:
                out.append(f"| {entry['name']} | {label}{own} | cannot take: {cell['reason']} ||||||||||")
                continue
            ref = row["reference"][row["best_reference"]]
            out.append(
                f"| {entry['name']} | {label}{own} | {cell['return']:.1f} | {cell['success']:.0%} "
                f"| {cell['final_spread']:.3g} | {cell['final_cross_track_max']:.3g} | {row['best_reference']} "
                f"| {ref['return']:.1f} | {ref['success']:.0%} | {row['random']['return']:.1f} "
                f"| {_fmt(cell['ratio'], '.2f')} | {_fmt(cell['score'], '.2f')} |"
            )
    return "\n".join(out)


def format_precision(report: dict[str, Any]) -> str:
    """Each policy on its training setting: final spread and max |e|, mean (max) over episodes, beside the
    best reference's."""
    out = [
        "| policy | training setting | spread [m] | ref. spread [m] | max \\|e\\| [m] | ref. max \\|e\\| [m] "
        "| best reference |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in report["precision"]:
        out.append(
            f"| {p['policy']} | {p['setting']} | {p['policy_final_spread']:.3g} ({p['policy_final_spread_max']:.3g}) "
            f"| {p['ref_final_spread']:.3g} ({p['ref_final_spread_max']:.3g}) "
            f"| {p['policy_final_cross_track_max']:.3g} ({p['policy_final_cross_track_max_max']:.3g}) "
            f"| {p['ref_final_cross_track_max']:.3g} ({p['ref_final_cross_track_max_max']:.3g}) | {p['reference']} |"
        )
    return "\n".join(out)


def format_markdown(report: dict[str, Any]) -> str:
    return (
        "\n\n".join(
            [
                f"# Shipped policies off their training setting\n\n{report['episodes']} episodes per cell (benchmark "
                f"seeds {report['seeds'][0]}–{report['seeds'][-1]}); ‡: the policy's training setting.",
                "## R_ref / R · success\n\nR_ref: the best reference variant's mean return; > 1: the policy returns "
                "more. ✗: a setting the policy cannot take.\n\n" + format_matrix(report),
                f"## The generalization target\n\nA cell holds it with R_ref / R ≥ {TARGET_RATIO} and, wherever "
                f"the best reference's success reaches {TARGET_SUCCESS:.0%}, a success of at least "
                f"{TARGET_SUCCESS:.0%}.\n\n" + format_target(report),
                "## Settings that cannot be built\n\n"
                + ("\n".join(f"- {u['label']} ({u['level']}): {u['reason']}" for u in report["unbuildable"]) or "none"),
                "## Every cell\n\nscore = (R − R_rand) / (R_ref − R_rand).\n\n" + format_cells(report),
                "## Precision on the training setting\n\nFinal values, mean (max) over episodes.\n\n"
                + format_precision(report),
            ]
        )
        + "\n"
    )


def plot_transfer(report: dict[str, Any], path: str | Path) -> Any:
    """Heat map of the normalized score: one row per policy, one column per setting (✗: cannot take)."""
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    labels = list(dict.fromkeys(row["label"] for row in report["settings"]))
    policies = report["policies"]
    values = np.full((len(policies), len(labels)), np.nan)
    fig = Figure(figsize=(1.0 + 0.62 * len(labels), 1.6 + 0.55 * len(policies)), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for i, entry in enumerate(policies):
        for k, label in enumerate(labels):
            cell = entry["cells"].get(label)
            if cell is not None and cell["compatible"] and cell["score"] is not None:
                values[i, k] = cell["score"]
    low, high = 0.0, 1.5
    image = ax.imshow(np.clip(values, low, high), aspect="auto", cmap="viridis", vmin=low, vmax=high)
    fig.colorbar(image, ax=ax, fraction=0.03, label="(R − R_rand) / (R_ref − R_rand)")
    for i, entry in enumerate(policies):
        for k, label in enumerate(labels):
            cell = entry["cells"].get(label)
            if cell is None:
                continue
            if not cell["compatible"]:
                ax.text(k, i, "✗", ha="center", va="center", fontsize=8, color="0.4")
                continue
            text = f"{_fmt(cell['score'], '.2f')}\n{cell['success']:.0%}"
            light = not np.isnan(values[i, k]) and values[i, k] > 0.6 * high
            ax.text(k, i, text, ha="center", va="center", fontsize=6, color="black" if light else "white")
            if label == entry["training_setting"]:
                ax.add_patch(_frame(k, i))
    ax.set_xticks(range(len(labels)), labels, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(policies)), [f"{p['name']} ({p['level']})" for p in policies], fontsize=8)
    ax.set_title(
        f"Zero-shot transfer: normalized score and success, {report['episodes']} episodes per cell "
        "(frame: training setting; ✗: cannot take; blank: other action level)",
        fontsize=9,
    )
    fig.tight_layout()
    save_figure(fig, path)
    return fig


def _frame(k: int, i: int) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((k - 0.5, i - 0.5), 1.0, 1.0, fill=False, edgecolor="red", linewidth=1.5)


# ----------------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m benchmarks.transfer", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results/transfer"), help="output prefix (.json/.md/.png)")
    parser.add_argument("--episodes", type=int_at_least(1), default=None, help="episodes per cell (default 20)")
    parser.add_argument(
        "--policy", action="append", dest="policies", metavar="NAME", help="a shipped policy; repeatable (default all)"
    )
    parser.add_argument(
        "--preset",
        action="append",
        dest="presets",
        metavar="NAME",
        help=f"repeatable (default all: {sorted(SCENARIOS)})",
    )
    parser.add_argument(
        "--team", action="append", dest="teams", type=int_at_least(1), metavar="N", help="3, 8 or 20; repeatable"
    )
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override of every setting")
    parser.add_argument("--quick", action="store_true", help="2 episodes, 20 s horizon, paper and acoustic, teams 3, 8")
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no table")
    args = parser.parse_args(argv)
    try:
        overrides = parse_overrides(args.set)
        if args.quick:
            overrides.setdefault("horizon", QUICK_HORIZON)
        episodes = args.episodes or (QUICK_EPISODES if args.quick else 20)
        presets = args.presets or list(QUICK_PRESETS if args.quick else SCENARIOS)
        teams = args.teams or list(QUICK_TEAMS if args.quick else (3, *(n for n, _ in BIG_TEAMS)))
        if "action_level" in overrides:
            raise ValueError("--set action_level: each policy runs at its own action level")
        for suffix in (".json", ".md", ".png"):
            check_writable(args.out.with_suffix(suffix), "--out")
        report = transfer(args.policies, presets, teams, episodes, overrides, not args.quiet)
    except (ValueError, KeyError, TypeError) as err:
        parser.error(str(err))
    command = command_line("python -m benchmarks.transfer", argv)
    write_report(args.out, report, format_markdown(report), plot_transfer, command)
    if not args.quiet:
        print(format_matrix(report))
        print()
        print(format_precision(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
