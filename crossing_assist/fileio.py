"""Atomic file writes, shared by every subpackage (stdlib only).

Whatever matters (labels, manifests, checkpoints, plots, WAVs, run state) is written to a
temporary file in the destination folder and moved into place with ``os.replace``, so a kill
or a crash leaves either the old file or the new one, never half of one.

Temporary names carry the writer's process id (:func:`tmp_tag`, ``.tmp<pid>``): what a killed
process left behind (SIGKILL runs no clean-up) is removed by :func:`sweep_orphans` the next
time a command writes into that folder, and never while the writer still runs.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


def tmp_tag() -> str:
    """``tmp<pid>``: the mark of this process's temporary files and folders."""
    return f"tmp{os.getpid()}"


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (on this machine)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


_ORPHAN = re.compile(r"\.(?:tmp|old)(\d+)(?:[-.][^/]*)?$")


def sweep_orphans(folder: str | os.PathLike, *, prefix: str = ".") -> list[Path]:
    """Remove temporary files/folders in ``folder`` whose name starts with ``prefix`` and carries
    the tag (``.tmp<pid>`` / ``.old<pid>``) of a process that no longer runs; returns them.
    Nothing else is touched, and a missing folder is fine."""
    removed: list[Path] = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for entry in entries:
        m = _ORPHAN.search(entry.name)
        if not entry.name.startswith(prefix) or m is None or pid_alive(int(m.group(1))):
            continue
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
            removed.append(entry)
        except OSError:
            pass
    return removed


@contextmanager
def atomic_path(path: str | os.PathLike, *, mode: int = 0o644, fsync: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix, so writers that infer the format
    from the extension work); on success it replaces ``path``, on any error it is removed.

    ``mode``: permissions of the result (mkstemp creates 0600). ``fsync``: flush the data to
    disk before the rename (for checkpoints that must survive a power cut).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".{tmp_tag()}{path.suffix}", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        if fsync:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def link_or_copy(src: str | os.PathLike, dst: str | os.PathLike) -> Path:
    """Place ``src`` at ``dst`` as a hard link (no extra space), or a byte copy where links are
    impossible (another file system); an existing ``dst`` is replaced. Returns ``dst``."""
    dst = Path(dst)
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.unlink(missing_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)
    return dst
