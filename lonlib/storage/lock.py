"""One writer at a time: OS-level file locks that the kernel releases when the holder dies.

A lock is an exclusive ``flock`` on a lock file. The kernel releases it when the holder
closes the file or dies (SIGKILL, a lost Dask worker, a crash), so a lock never outlives
its process and there is nothing stale to clean up. A run lock records its holder (pid,
host, since) in the file so that a process finding it taken can name who holds it. Lock
files are never deleted: deleting one while another process waits on it would let a third
process lock a new file of the same name, and two writers would each hold "the" lock.

Limits: the lock is advisory (only lonlib honours it). On NFS, Linux implements ``flock``
with POSIX byte-range locks, which exclude other clients' processes but not two threads of
one process: run Dask workers with one thread each (lonlib's ``dask-local`` does).
"""

from __future__ import annotations

import fcntl
import json
import os
import platform
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from lonlib.storage.atomic import write_error


class LockHeld(RuntimeError):
    """Another process holds the lock; the message (and ``holder``) names it."""

    def __init__(self, path: Path, holder: str) -> None:
        super().__init__(f"{path} is held by {holder}")
        self.path = path
        self.holder = holder


@contextmanager
def exclusive_lock(path: Path, wait: bool = True, record_holder: bool = True) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (created, with its folder, if missing) for the
    ``with`` block. If another process holds it: block until it is released (``wait``) or
    raise :class:`LockHeld` naming the holder. ``record_holder`` writes this process's pid,
    host and start time into the file while it holds the lock.

    A lock file that cannot be created raises :class:`lonlib.storage.atomic.DataWriteError`.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as error:
        raise write_error(path, error) from error
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not wait:
                raise LockHeld(path, lock_holder(path)) from None
            fcntl.flock(handle, fcntl.LOCK_EX)
        if record_holder:
            _record_holder(path, handle)
        yield
    finally:
        os.close(handle)  # releases the lock


class SamplingLock:
    """An experiment folder's sampling lock (:data:`lonlib.storage.layout.SAMPLING_LOCK`).
    Every sampling session holds it shared for as long as it samples; a session that changes
    the stored settings (``lonlib run --allow-change``) first takes it exclusively, without
    waiting, so that no session sampling under the old settings is running. Take it while
    holding the manifest lock: the exclusive hold then lasts only until :meth:`share`, and
    a shared request never waits for it."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._handle: int | None = None

    def acquire(self, exclusive: bool) -> None:
        """Hold it shared, or exclusively (:class:`LockHeld` if another session holds it)."""
        try:
            self._handle = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as error:
            raise write_error(self.path, error) from error
        try:
            if exclusive:
                fcntl.flock(self._handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            else:
                fcntl.flock(self._handle, fcntl.LOCK_SH)
        except BlockingIOError:
            self.release()
            raise LockHeld(self.path, "another sampling session") from None

    def share(self) -> None:
        """Turn an exclusive hold into a shared one (the change is stored)."""
        if self._handle is not None:
            fcntl.flock(self._handle, fcntl.LOCK_SH)

    def release(self) -> None:
        """Let go (idempotent)."""
        if self._handle is not None:
            os.close(self._handle)
            self._handle = None


@contextmanager
def sampling_lock_or_refuse(folder: Path, command: str) -> Iterator[None]:
    """Hold the experiment folder's sampling lock (:class:`SamplingLock`) exclusively for the
    ``with`` block, for a command that rewrites what sampling sessions append to (``lonlib
    thin``, ``lonlib verify --seal``): a session that starts meanwhile waits for it. If a
    session is sampling, refuse without waiting: ValueError "<folder>: a sampling session is
    running; <command> it once it ends" (``command``: ``"thin"``, ``"seal"``)."""
    from lonlib.storage.layout import SAMPLING_LOCK

    sampling = SamplingLock(Path(folder) / SAMPLING_LOCK)
    try:
        sampling.acquire(exclusive=True)
    except LockHeld:
        raise ValueError(
            f"{folder}: a sampling session is running; {command} it once it ends"
        ) from None
    try:
        yield
    finally:
        sampling.release()


def lock_holder(path: Path) -> str:
    """Who holds (or last held) the lock at ``path``, in words."""
    try:
        holder = json.loads(Path(path).read_text())
        return f"pid {holder['pid']} on {holder['host']} (since {holder['since']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process (it has not recorded itself yet)"


def _record_holder(path: Path, handle: int) -> None:
    holder = {
        "pid": os.getpid(),
        "host": platform.node(),
        "since": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    try:
        os.ftruncate(handle, 0)
        os.pwrite(handle, json.dumps(holder).encode(), 0)
    except OSError as error:
        raise write_error(path, error) from error
