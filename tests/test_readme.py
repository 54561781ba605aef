"""What the README's first screen (and the site's home page, which mirrors it) promises.

The learned-baselines table of each agrees with ``docs/learned_baselines.json``
(which holds the published table of ``docs/results.md``, with each row's provenance);
the code example runs and prints the return it claims; the citation files parse.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.backend_independent

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
FIRST_SCREENS = [README, ROOT / "docs" / "index.md"]
RESULTS = ROOT / "docs" / "learned_baselines.json"
PAPER_TITLE = "Formation Control of Underactuated Marine Vehicles with Communication Constraints"


def published_rows() -> list[dict]:
    return json.loads(RESULTS.read_text())["rows"]


def markdown_table(text: str, header_start: str) -> list[dict[str, str]]:
    """The rows of the first table whose header line starts with ``header_start``, as {column: cell}."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header_start))
    header = [cell.strip() for cell in lines[start].strip().strip("|").split("|")]
    rows = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        rows.append(dict(zip(header, (cell.strip() for cell in line.strip().strip("|").split("|")), strict=True)))
    return rows


def learned_table(page: Path) -> dict[str, dict[str, str]]:
    rows = markdown_table(page.read_text(), "| row | level | learner |")
    return {row["row"].strip("`"): row for row in rows}


def leading_value(cell: str) -> str:
    """The cell's first ``mean ± spread`` (a note may follow it in parentheses)."""
    match = re.match(r"-?[\d.]+%? ± [\d.]+%?", cell)
    assert match, f"no 'mean ± spread' at the start of {cell!r}"
    return match.group(0)


def page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


@pytest.mark.parametrize("page", FIRST_SCREENS, ids=page_id)
def test_learned_table_has_every_published_row_and_no_other(page):
    assert set(learned_table(page)) == {row["row"] for row in published_rows()}


@pytest.mark.parametrize("page", FIRST_SCREENS, ids=page_id)
@pytest.mark.parametrize("row", published_rows(), ids=lambda row: row["row"])
def test_learned_numbers_are_the_published_ones(row, page):
    cells = learned_table(page)[row["row"]]
    assert leading_value(cells["R_ref / R_learned"]) == row["performance"]["text"]
    assert leading_value(cells["success"]) == row["success_learned"]["text"]
    assert cells["level"] == row["level"]
    assert cells["learner"].startswith(row["learner"]), (cells["learner"], row["learner"])


@pytest.mark.parametrize("row", published_rows(), ids=lambda row: row["row"])
def test_every_published_row_says_where_it_comes_from(row):
    provenance = row["provenance"]
    assert re.fullmatch(r"[0-9a-f]{7,40}", provenance["commit"])
    trained_on = provenance["trained_on"]
    for commit in trained_on.values() if isinstance(trained_on, dict) else [trained_on]:
        assert re.fullmatch(r"[0-9a-f]{7,40}", commit)
    assert provenance["command"].startswith("python -m benchmarks.learned_baselines --rows " + row["row"])
    assert provenance["machine"].strip()


@pytest.mark.parametrize("row", published_rows(), ids=lambda row: row["row"])
def test_json_rows_are_the_ones_docs_results_publishes(row):
    """Each record's numbers are on its row of the table between the markers of docs/results.md."""
    text = (ROOT / "docs" / "results.md").read_text()
    block = text[text.index("<!-- learned-baselines:start -->") : text.index("<!-- learned-baselines:end -->")]
    line = next(line for line in block.splitlines() if line.startswith(f"| `{row['row']}` |"))
    cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
    assert cells[1] == row["pipeline"] and float(cells[2]) == row["budget_minutes"] and int(cells[3]) == row["seeds"]
    assert cells[4] == row["learned_return"]["text"] and cells[5] == row["reference_return"]["text"]
    assert cells[6] == row["performance"]["text"]
    assert cells[7] == f"{row['success_learned']['text']} / {row['success_reference']['text']}"
    source = next(line for line in block.splitlines() if line.startswith(f"- `{row['row']}`: "))
    assert row["provenance"]["commit"] in source and f"`{row['provenance']['command']}`" in source


@pytest.mark.parametrize("page", FIRST_SCREENS, ids=page_id)
def test_example_runs_and_prints_the_return_it_claims(page):
    code = re.search(r"```python\n(.+?)\n```", page.read_text(), re.S).group(1)
    claimed = re.search(r"#\s*(return -?[\d.]+)\s*$", code.splitlines()[-1]).group(1)
    env = {**os.environ, "MARINE_FORMATION_BACKEND": "numpy", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == claimed


def test_citation_file_names_the_software_and_the_paper():
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["cff-version"] == "1.2.0"
    assert citation["type"] == "software" and citation["license"] == "MIT"
    assert citation["title"] and citation["authors"] and citation["message"]
    (paper,) = citation["references"]
    assert paper["title"] == PAPER_TITLE and paper["authors"] and paper["type"]
    assert PAPER_TITLE in README.read_text()
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")


@pytest.mark.parametrize("path", sorted((ROOT / "docs").glob("*.json")), ids=lambda p: p.name)
def test_shipped_result_files_cite_nothing_users_do_not_have(path):
    text = path.read_text()
    assert "../shared" not in text
    assert not re.search(r"\bSPEC\b", text), "cite the paper's equations or docs/model.md instead"
