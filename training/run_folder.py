"""Run folders that never lose or corrupt work: atomic writes, checkpoints, resume bookkeeping.

Every file of a run folder is written **atomically**
(``atomic_write``, on top of ``marine_formation_env.atomic.atomic_path``):
the bytes go to a temporary file in the same folder
(``.<name>.<random>.tmp<suffix>``), which is flushed and ``fsync``-ed and then
renamed over the final name with ``os.replace`` (the folder is
``fsync``-ed too). A reader, or a process killed at any instant, sees either
the old file or the new one, never half of one; a kill leaves at most a stale
temporary file, which ``recover`` removes.

Files that belong together are replaced together: ``best_model.zip``,
``best_vecnormalize.pkl`` and ``best_model.json`` (the JSON records the score
of that model with those statistics), and the final ``model.zip`` with
``vecnormalize.pkl``. ``write_together`` stages all of them, then writes a
small journal (``.commit.json``, atomically: the commit point) naming the
renames, then performs them and removes the journal. ``recover`` finishes
a journal a kill interrupted, so such files always come from the same model.

Every run folder, whatever its trainer, holds the same four things
(``CONFIG_FILE``, ``PROGRESS_FILE``, ``EVALUATION_FILE`` and the
trainer's policy file):

* ``config.yaml``: one flat mapping, the resolved config with three more
  top-level fields: ``trainer`` (``sb3``, ``torchrl`` or ``rllib``: the kind of
  run folder, read by ``read_config``, never guessed from the files),
  ``env_id`` and ``seed`` (``config_record``);
* ``progress.csv``: one row per iteration (per rollout for SB3), the shared
  columns ``PROGRESS_COLUMNS`` first, then the trainer's own;
* ``evaluation.json``: the learned policy and the reference on
  ``baselines.seeds.evaluation_seeds(eval_episodes)``
  (``training.learned.evaluate_run``);
* the policy: ``model.zip`` and ``vecnormalize.pkl`` (SB3), ``policy.pt``
  (TorchRL), ``checkpoint/`` (RLlib).

Checkpoints keep SB3's names: ``checkpoints/model_<N>_steps.zip`` and
``checkpoints/model_vecnormalize_<N>_steps.pkl``; the statistics are written
first (after removing a zip of the same name), so a checkpoint zip exists only
once its own statistics are complete.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import pickle
import re
import shutil
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import yaml

from baselines.runs import CONFIG_FILE, RunFolderError, read_config
from marine_formation_env import ENV_ID
from marine_formation_env.atomic import TEMP_MARK, atomic_path, fsync_folder, temporary_beside

__all__ = [
    "ARTIFACTS",
    "CONFIG_FILE",
    "EVALUATION_FILE",
    "PROGRESS_COLUMNS",
    "PROGRESS_FILE",
    "TRAINERS",
    "Checkpoint",
    "RunFolderError",
    "atomic_write",
    "checkpoint_problem",
    "config_record",
    "list_checkpoints",
    "present_artifacts",
    "read_best",
    "read_config",
    "read_evaluations",
    "recover",
    "remove_artifacts",
    "save_checkpoint",
    "save_final",
    "save_model",
    "save_normalizer",
    "temporaries",
    "truncate_evaluations",
    "write_bytes",
    "write_config",
    "write_evaluations",
    "write_progress",
    "write_together",
]

#: The learning curve: ``PROGRESS_COLUMNS``, then the trainer's own columns.
PROGRESS_FILE = "progress.csv"
#: The closing evaluation on the evaluation seeds (``training.learned.evaluate_run``).
EVALUATION_FILE = "evaluation.json"
#: The values of ``config.yaml``'s ``trainer`` field.
TRAINERS = ("sb3", "torchrl", "rllib")
#: The first columns of every trainer's ``progress.csv``, in this order: vessel-steps trained so far, wall-clock
#: seconds since the start of training, the mean return per vessel of the training episodes that ended in the row
#: (the env's reward as the learner saw it; empty when none ended) and their number.
PROGRESS_COLUMNS = ("vessel_steps", "wall_time_s", "episode_return_mean", "episodes")

#: Names of the temporary files of ``atomic_write`` and ``write_together``: ``.NAME.<random>.tmp<suffix>``.
_TEMP_RE = re.compile(rf"\..+\.[A-Za-z0-9_]+{re.escape(TEMP_MARK)}(\.[A-Za-z0-9_]+)?")
#: The journal of ``write_together``.
JOURNAL = ".commit.json"
#: What a run leaves in its folder; a new run refuses a folder holding any of them (``--overwrite`` removes them).
ARTIFACTS = (
    CONFIG_FILE,
    "model.zip",
    "vecnormalize.pkl",
    "best_model.zip",
    "best_vecnormalize.pkl",
    "best_model.json",
    "evaluations.csv",
    PROGRESS_FILE,
    EVALUATION_FILE,
    "tb",
    "checkpoints",
    JOURNAL,
)
CHECKPOINTS = "checkpoints"
_CHECKPOINT_RE = re.compile(r"model_(\d+)_steps")


@contextlib.contextmanager
def _staged(path: Path) -> Iterator[tuple[IO[bytes], Path]]:
    """An open temporary file beside ``path``; flushed and fsync-ed on exit, removed on error."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_beside(path)
    try:
        with open(tmp, "wb") as handle:
            yield handle, tmp
            handle.flush()
            os.fsync(handle.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_write(path: str | Path) -> Iterator[IO[bytes]]:
    """Write ``path`` atomically: yield an open binary file whose bytes replace ``path`` on a clean exit.

    The file is a temporary one in the same folder; after the ``with`` body it
    is closed, ``fsync``-ed and renamed over ``path`` (``os.replace``, by
    ``marine_formation_env.atomic.atomic_path``). If the body raises, the
    temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        yield handle


def write_bytes(path: str | Path, data: bytes) -> None:
    """``path.write_bytes(data)``, atomically."""
    with atomic_write(path) as handle:
        handle.write(data)


def save_model(model: Any, path: str | Path) -> None:
    """``model.save(path)``, atomically (SB3's ``save`` accepts an open binary file)."""
    with atomic_write(path) as handle:
        model.save(handle)


def save_normalizer(normalizer: Any, path: str | Path) -> None:
    """``VecNormalize.save(path)``, atomically (which is ``pickle.dump(normalizer, file)``, as SB3 does)."""
    with atomic_write(path) as handle:
        pickle.dump(normalizer, handle)


def write_together(folder: Path, writers: dict[str, Callable[[IO[bytes]], Any]]) -> None:
    """Replace several files of ``folder`` so that, even after a kill, either all or none are new.

    Each ``writers[name](file)`` writes the new content of ``folder/name``. All
    are staged (written, fsync-ed) first; then the journal naming the renames is
    written atomically (the commit point); then the renames happen and the
    journal is removed. ``recover`` completes a committed journal.
    """
    folder.mkdir(parents=True, exist_ok=True)
    staged: list[tuple[str, str]] = []
    try:
        for name, write in writers.items():
            with _staged(folder / name) as (handle, tmp):
                write(handle)
            staged.append((tmp.name, name))
    except BaseException:
        for tmp_name, _ in staged:
            (folder / tmp_name).unlink(missing_ok=True)
        raise
    write_bytes(folder / JOURNAL, json.dumps(staged).encode())
    _apply_journal(folder)


def _apply_journal(folder: Path) -> list[str]:
    """Perform the renames the journal lists (those not done yet), then remove it; return the names."""
    journal = folder / JOURNAL
    renames = json.loads(journal.read_text())
    for tmp_name, name in renames:
        if (folder / tmp_name).exists():
            os.replace(folder / tmp_name, folder / name)
    fsync_folder(folder)
    journal.unlink()
    fsync_folder(folder)
    return [name for _, name in renames]


def temporaries(folder: Path) -> list[Path]:
    """Temporary files of interrupted atomic writes in ``folder`` and ``folder/checkpoints``."""
    found: list[Path] = []
    for sub in (folder, folder / CHECKPOINTS):
        if sub.is_dir():
            found.extend(p for p in sorted(sub.iterdir()) if _TEMP_RE.fullmatch(p.name) and p.is_file())
    return found


def recover(folder: Path) -> list[str]:
    """Finish an interrupted ``write_together`` and remove stale temporary files.

    Returns one line per action taken (for the log).
    """
    notes: list[str] = []
    if (folder / JOURNAL).is_file():
        names = _apply_journal(folder)
        notes.append(f"completed the interrupted update of {', '.join(names)} in {folder}")
    for tmp in temporaries(folder):
        tmp.unlink(missing_ok=True)
        notes.append(f"removed stale temporary file {tmp} (left by an interrupted write)")
    return notes


# --------------------------------------------------------------------------- checkpoints


@dataclass(frozen=True)
class Checkpoint:
    """One ``checkpoints/model_<steps>_steps.zip`` and its VecNormalize statistics' path."""

    steps: int
    model: Path
    stats: Path


def list_checkpoints(out: Path) -> list[Checkpoint]:
    """The checkpoint zips of run folder ``out``, newest first (whether readable or not)."""
    found = []
    for path in (out / CHECKPOINTS).glob("model_*_steps.zip"):
        match = _CHECKPOINT_RE.fullmatch(path.stem)
        if match:
            steps = int(match.group(1))
            found.append(Checkpoint(steps, path, path.with_name(f"model_vecnormalize_{steps}_steps.pkl")))
    return sorted(found, key=lambda c: c.steps, reverse=True)


def checkpoint_problem(checkpoint: Checkpoint, needs_stats: bool) -> str | None:
    """Why ``checkpoint`` cannot be resumed from (empty, truncated or corrupt files), or None."""
    path = checkpoint.model
    try:
        if path.stat().st_size == 0:
            return "empty file"
        if not zipfile.is_zipfile(path):
            return "truncated or not a zip archive"
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
            if bad is not None:
                return f"corrupt archive member {bad!r}"
            missing = {"data", "policy.pth"} - set(archive.namelist())
            if missing:
                return f"truncated or incomplete archive (no {', '.join(sorted(missing))})"
    except (OSError, zipfile.BadZipFile, EOFError) as err:
        return f"unreadable archive ({type(err).__name__}: {err})"
    if needs_stats:
        if not checkpoint.stats.is_file():
            return f"its VecNormalize statistics {checkpoint.stats.name} are missing"
        try:
            with checkpoint.stats.open("rb") as handle:
                pickle.load(handle)
        except Exception as err:
            return f"unreadable VecNormalize statistics {checkpoint.stats.name} ({type(err).__name__}: {err})"
    return None


def save_checkpoint(model: Any, out: Path, steps: int | None = None) -> Path:
    """Save ``model`` (and its VecNormalize statistics, first) as the checkpoint at ``steps``; return the zip.

    A zip already at that name (a run resumed from an earlier checkpoint
    reaches the same step again) is removed first, so a checkpoint zip is
    always newer than its statistics and from the same model.
    """
    steps = int(model.num_timesteps if steps is None else steps)
    folder = out / CHECKPOINTS
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"model_{steps}_steps.zip"
    normalizer = model.get_vec_normalize_env()
    if normalizer is not None:
        if path.exists():
            path.unlink()
            fsync_folder(folder)
        save_normalizer(normalizer, folder / f"model_vecnormalize_{steps}_steps.pkl")
    save_model(model, path)
    return path


def save_final(model: Any, out: Path, model_name: str = "model.zip", stats_name: str = "vecnormalize.pkl") -> None:
    """Save ``model`` and its VecNormalize statistics (if any) as a pair (``write_together``)."""
    writers: dict[str, Callable[[IO[bytes]], Any]] = {model_name: model.save}
    normalizer = model.get_vec_normalize_env()
    if normalizer is not None:
        writers[stats_name] = lambda handle: pickle.dump(normalizer, handle)
    write_together(out, writers)


# --------------------------------------------------------------------------- artifacts, evaluations, best


def present_artifacts(out: Path) -> list[str]:
    """The ``ARTIFACTS`` of another run present in ``out``."""
    return [name for name in ARTIFACTS if (out / name).exists()]


def remove_artifacts(out: Path) -> None:
    """Remove every ``ARTIFACT`` (and stale temporary file) from ``out``."""
    for name in ARTIFACTS:
        path = out / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
    for tmp in temporaries(out):
        tmp.unlink(missing_ok=True)


def write_evaluations(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write ``rows`` as ``evaluations.csv`` (header from the first row), atomically."""
    text = io.StringIO(newline="")
    if rows:
        writer = csv.DictWriter(text, fieldnames=list(rows[0]), lineterminator="\r\n")
        writer.writeheader()
        writer.writerows(rows)
    write_bytes(path, text.getvalue().encode())


def read_evaluations(path: Path) -> list[dict[str, Any]]:
    """The rows of ``evaluations.csv`` (empty if absent); rows without a whole ``timesteps`` are dropped."""
    if not path.is_file():
        return []
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    out = []
    for row in rows:
        try:
            int(row.get("timesteps") or "")
        except ValueError:
            continue
        if None in row or None in row.values():  # a short or long (damaged) line
            continue
        out.append(row)
    return out


def truncate_evaluations(path: Path, steps: int) -> int:
    """Drop the rows of ``evaluations.csv`` after ``steps`` timesteps (rewrite atomically); return how many."""
    if not path.is_file():
        return 0
    with path.open(newline="") as handle:
        total = sum(1 for _ in csv.DictReader(handle))
    kept = [row for row in read_evaluations(path) if int(row["timesteps"]) <= steps]
    if total != len(kept):
        write_evaluations(path, kept)
    return total - len(kept)


def read_best(out: Path) -> dict[str, Any] | None:
    """``best_model.json`` of run folder ``out`` (None if absent or unreadable)."""
    path = out / "best_model.json"
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and "return_learned" in record else None


# --------------------------------------------------------------------------- the run-folder contract


def config_record(trainer: str, resolved: dict[str, Any], seed: int) -> dict[str, Any]:
    """What ``config.yaml`` holds: ``trainer``, ``env_id`` and ``seed``, then the resolved config's keys."""
    if trainer not in TRAINERS:
        raise ValueError(f"trainer must be one of {list(TRAINERS)}, got {trainer!r}")
    rest = {k: v for k, v in resolved.items() if k not in ("trainer", "env_id", "seed")}
    return {"trainer": trainer, "env_id": ENV_ID, "seed": int(seed), **rest}


class _FullDumper(yaml.SafeDumper):
    """Writes a value that several keys share (an anchor in the config file) in full at each key."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def write_config(out: Path, trainer: str, resolved: dict[str, Any], seed: int) -> dict[str, Any]:
    """Write ``out/config.yaml`` (``config_record``) atomically; return the record."""
    record = config_record(trainer, resolved, seed)
    text = yaml.dump(record, Dumper=_FullDumper, sort_keys=False, allow_unicode=True)
    write_bytes(out / CONFIG_FILE, text.encode())
    return record


def write_progress(path: Path, rows: list[dict[str, Any]], own_columns: tuple[str, ...] = ()) -> None:
    """Write ``progress.csv`` atomically: ``PROGRESS_COLUMNS``, then ``own_columns`` (the trainer's)."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=[*PROGRESS_COLUMNS, *own_columns])
    writer.writeheader()
    writer.writerows(rows)
    write_bytes(path, text.getvalue().encode())
