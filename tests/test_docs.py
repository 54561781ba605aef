"""The documentation a user has: what it promises about itself.

CI runs ``.ci/run``, which must be the README's test command; the README stays
short; no user-facing file points at material users do not have; every page
of ``docs/`` is on the site.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.backend_independent

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("marine_formation_env", "baselines", "training")
CODE = sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))
USER_FACING = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *CODE]


def readme_command(heading: str) -> str:
    text = (ROOT / "README.md").read_text()
    after = text[text.index(heading) :]
    return re.search(r"```bash\n(.+?)\n```", after, re.S).group(1).strip()


def test_ci_runs_exactly_the_readme_test_command():
    command = readme_command("Run the tests")
    assert "\n" not in command  # one line
    script = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line and not line.startswith("#")]
    assert script[-1] == command


def test_readme_is_short():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200


@pytest.mark.parametrize("path", USER_FACING, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_reference_to_files_users_do_not_have(path):
    text = path.read_text()
    assert "../shared" not in text
    assert not re.search(r"\bSPEC\b", text), "cite the paper's equations or docs/model.md instead"


def test_every_docs_page_is_on_the_site():
    """Every page is in the navigation, except the tables the sweep script writes (excluded from the site)."""
    config = (ROOT / "mkdocs.yml").read_text()
    for page in (ROOT / "docs").rglob("*.md"):
        generated = page.name.startswith("sweep_") and "sweep_*.md" in config
        name = page.relative_to(ROOT / "docs").as_posix()
        assert generated or f": {name}" in config, name


@pytest.mark.parametrize("path", sorted((ROOT / "docs").rglob("*.json")), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_result_file_says_which_commit_command_and_machine_it_comes_from(path):
    report = json.loads(path.read_text())
    if "rows" in report:  # the learned-baselines table: a row each
        sources = [row["provenance"] for row in report["rows"]]
    elif "tasks" in report:  # the benchmark's results: each task's baselines and each cell
        sources = [entry["provenance"] for part in ("tasks", "cells") for entry in report[part].values()]
    else:
        sources = [report["provenance"]]
    for source in sources:
        assert re.fullmatch(r"[0-9a-f]{7,40}", source["commit"]), source
        assert source["command"].startswith("python -m "), source
        assert "cores" in source["machine"] or "2-core" in source["machine"], source


HISTORY = re.compile(r"\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,12}\b|\bissues? #?\d+", re.IGNORECASE)
SOURCES = sorted(
    p
    for package in (*PACKAGES, "benchmarks", "hydra_plugins")
    for pattern in ("*.py", "*.yaml")
    for p in (ROOT / package).rglob(pattern)
)


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_code_and_configs_say_what_a_thing_is_not_its_history(path):
    """No commit hashes or issue numbers: history lives in the changelog and the experiment log."""
    found = HISTORY.findall(path.read_text())
    assert not found, f"{path.relative_to(ROOT)}: {found}"
