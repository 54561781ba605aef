"""Files that are either written whole or not at all.

Every file the project writes (reports, trajectories, figures, checkpoints,
configs) goes through ``atomic_path``: the content is written into a
temporary file in the destination's folder, flushed to disk, and then moved
over the destination with ``os.replace``, which is atomic on POSIX and
Windows. A process killed mid-write leaves the previous file (or none) and a
hidden ``.NAME.*.tmp`` file, never a truncated ``NAME``.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "TEMP_MARK",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_writable",
    "fsync_folder",
    "temporary_beside",
]

#: Part of every temporary file's name (``.NAME.<random>.tmp<suffix>``), for clean-ups.
TEMP_MARK = ".tmp"


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: The process's umask, read once: temporary files get the mode ``open()`` would give the final file.
_FILE_MODE = 0o666 & ~_umask()


def temporary_beside(path: str | os.PathLike[str]) -> Path:
    """A new, empty temporary file in ``path``'s folder, named ``.NAME.<random>.tmp<suffix>``.

    It has the permissions ``open()`` would give ``path`` (not mkstemp's 0600),
    so renaming it over ``path`` changes nothing but the content.
    """
    target = Path(path)
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f"{TEMP_MARK}{target.suffix}", dir=target.parent)
    try:
        with contextlib.suppress(AttributeError, OSError):  # no fchmod on Windows
            os.fchmod(fd, _FILE_MODE)
    finally:
        os.close(fd)
    return Path(name)


def fsync_folder(folder: str | os.PathLike[str]) -> None:
    """Make a rename in ``folder`` durable (a no-op where folders cannot be opened, e.g. Windows)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success move it over ``path``.

    The temporary name keeps ``path``'s suffix, so writers that choose the
    format by extension (matplotlib's ``savefig``) or append one when it is
    missing (``np.savez``, SB3's ``save``) write exactly that file. If the
    body raises (or the process is interrupted), the temporary file is
    removed and ``path`` is left as it was.

    Example::

        with atomic_path("results/paper.npz") as tmp:
            np.savez_compressed(tmp, **arrays)
    """
    target = Path(path)
    tmp = temporary_beside(target)
    try:
        yield tmp
        with open(tmp, "rb+") as handle:  # the content reaches the disk before the rename makes it visible
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_folder(target.parent)


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (``atomic_path``)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (``atomic_path``)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def check_writable(path: str | os.PathLike[str], what: str) -> Path:
    """Make sure ``path`` can be written later: create its folder and try a file there.

    Call it before a long computation whose result goes to ``path``, so a
    typo fails at once rather than after the work.

    Raises:
        ValueError: ``path`` is a folder, or its folder cannot be created or
            written; the message names ``what`` (e.g. ``--json``) and the path.
    """
    target = Path(path)
    if target.is_dir():
        raise ValueError(f"{what} {str(target)!r} is a folder; give a file name")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=target.parent, prefix=f".{target.name}.", suffix=TEMP_MARK):
            pass
    except OSError as err:
        raise ValueError(f"{what} {str(target)!r} cannot be written: {err.strerror or err}") from None
    return target
