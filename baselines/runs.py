"""Load a trained policy from a run folder, whichever trainer wrote it.

Every trainer writes a run folder with a ``config.yaml`` whose top-level
``trainer`` field names it (``sb3``, ``torchrl``, ``rllib``). The loader of
each trainer is registered as a Python entry point in the group
``TRAINER_GROUP`` (the ``training`` package registers its three in
``pyproject.toml``), so this module finds a run's loader by that field
without importing any trainer: ``baselines`` stays free of torch, and a
third-party trainer can register its own.

A loader is called as ``loader(path, deterministic=True)`` with the path the
user named (the run folder, or a policy or checkpoint file in it) and returns
``(policy, config)``: a ``BatchPolicy`` and the run's
resolved configuration (``scenario`` and ``env_kwargs`` say what it trained on).
"""

from __future__ import annotations

from collections.abc import Callable
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

__all__ = [
    "CONFIG_FILE",
    "TRAINER_GROUP",
    "RunFolderError",
    "load_run",
    "read_config",
    "run_folder_of",
    "trainer_of",
    "trainers",
]

#: The entry-point group of the run-folder loaders, one per ``trainer`` name.
TRAINER_GROUP = "marine_formation_env.trainers"
#: A run folder's configuration file, with its ``trainer`` field.
CONFIG_FILE = "config.yaml"

Loader = Callable[..., tuple[Any, dict[str, Any]]]


class RunFolderError(ValueError):
    """A run folder that cannot be loaded (no ``config.yaml``, no ``trainer`` field, an unknown trainer)."""


def run_folder_of(path: str | Path) -> Path:
    """The run folder of ``path``: the nearest of ``path`` (a folder) or its folder (a file) and their parent and
    grandparent that holds a ``config.yaml``.

    ``runs/NAME``, ``runs/NAME/model.zip``, ``runs/NAME/checkpoints/step_1000.zip`` and RLlib's
    ``runs/NAME/checkpoint/learner_group`` all give ``runs/NAME``.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        RunFolderError: none of those folders holds a ``config.yaml``.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no run folder or policy file at {str(path)!r}")
    folder = path if path.is_dir() else path.parent
    for candidate in (folder, folder.parent, folder.parent.parent):
        if (candidate / CONFIG_FILE).is_file():
            return candidate
    raise RunFolderError(f"{str(path)!r} is not a run folder: neither it nor its parents have a {CONFIG_FILE}")


def read_config(folder: str | Path) -> dict[str, Any]:
    """The ``config.yaml`` of a run folder: a mapping with a ``trainer`` field that names its trainer.

    Raises:
        RunFolderError: no ``config.yaml``, not YAML, not a mapping, or no ``trainer`` field (the message
            names the folder and the field).
        ImportError: PyYAML is not installed (it comes with every trainer's extra).
    """
    try:
        import yaml  # the trainers' dependency: a run folder exists only where one is installed
    except ImportError as err:
        raise ImportError(f"config.yaml needs PyYAML: pip install 'marine-formation-env[train]' ({err})") from err
    folder = Path(folder)
    path = folder / CONFIG_FILE
    if not path.is_file():
        raise RunFolderError(f"{str(folder)!r} is not a run folder: it has no {CONFIG_FILE}")
    try:
        record = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise RunFolderError(f"{str(path)!r} is not readable YAML ({type(err).__name__}: {err})") from None
    if not isinstance(record, dict):
        raise RunFolderError(f"{str(path)!r} is not a mapping")
    if not isinstance(record.get("trainer"), str):
        raise RunFolderError(
            f"run folder {str(folder)!r}: {CONFIG_FILE} has no 'trainer' field (one of {sorted(trainers())}); "
            "it was written before run folders recorded their trainer"
        )
    return record


def trainer_of(folder: str | Path) -> str:
    """The ``trainer`` field of a run folder's ``config.yaml`` (:func:`read_config`)."""
    return str(read_config(folder)["trainer"])


def trainers() -> dict[str, Any]:
    """The registered run-folder loaders: ``{trainer name: entry point}`` (not yet imported)."""
    return {ep.name: ep for ep in entry_points(group=TRAINER_GROUP)}


def load_run(path: str | Path, deterministic: bool = True) -> tuple[Any, dict[str, Any]]:
    """Load the policy of a run folder (or of a policy file in one) and the run's resolved config.

    Args:
        path: the run folder, or its policy or a checkpoint file.
        deterministic: act with the policy's mode (mean action) rather than sampling.

    Returns:
        ``(policy, config)`` as the trainer's loader gives them.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        RunFolderError: no run folder, no ``trainer`` field, or a trainer with no registered loader.
        ImportError: the trainer's extra is not installed (the message names it).
    """
    folder = run_folder_of(path)
    trainer = trainer_of(folder)
    registered = trainers()
    if trainer not in registered:
        raise RunFolderError(
            f"run folder {str(folder)!r}: {CONFIG_FILE}'s trainer must be one of {sorted(registered)}, got "
            f"{trainer!r} (a trainer is registered when its package is installed: pip install -e .)"
        )
    try:
        loader: Loader = registered[trainer].load()
    except ImportError as err:
        raise ImportError(
            f"loading a {trainer!r} run needs its extra: pip install 'marine-formation-env[train]' "
            f"(sb3), '[torchrl]' or '[rllib]' ({err})"
        ) from err
    return loader(Path(path), deterministic=deterministic)
