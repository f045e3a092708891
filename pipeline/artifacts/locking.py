"""Locks of the artifact store: one run per stage version at a time, across processes.

A run holds ``<stage_dir>/.lock-<version>`` (``fcntl.flock``) while it works; a forked worker
dies with its parent (``PR_SET_PDEATHSIG``), so a killed run's workers cannot keep writing into
a folder that the next run takes over. Stale temporary folders of other versions are removed
when no run holds their lock. ``pipeline.artifacts.store`` (its module docstring: "Crash
safety") uses these.
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
import shutil
import sys
import time
from pathlib import Path

from pipeline.artifacts.errors import ArtifactError

TMP_PREFIX = ".tmp-"
LOCK_PREFIX = ".lock-"
STALE_TMP_S = 3600.0  # random-named .tmp-* entries older than this are removed
RESUME_KEEP_S = 7 * 24 * 3600.0  # unlocked work folders of other versions older than this too
LOCK_GRACE_S = 10.0  # how long to wait for the workers of a killed run to exit
_RANDOM_TMP = re.compile(r"^\.tmp-.+-[0-9a-f]{8}$")  # .tmp-<version>-<random>, old-, latest-


_HELD_LOCKS: set[int] = set()  # lock file descriptors this process holds
_FORK_PARENT = 0


def _before_fork() -> None:
    global _FORK_PARENT
    _FORK_PARENT = os.getpid()


def _prctl():
    """libc's ``prctl`` (Linux), looked up in the parent so that a forked child only calls it."""
    global _PRCTL
    if _PRCTL is None and sys.platform.startswith("linux"):
        try:
            import ctypes

            _PRCTL = ctypes.CDLL(None, use_errno=True).prctl
        except (OSError, AttributeError):  # pragma: no cover
            _PRCTL = False
    return _PRCTL


_PRCTL = None


def _after_fork_in_child() -> None:
    """A process forked while a stage lock is held (a worker of the stage) dies with its
    parent: after ``kill -9`` of the stage, no orphan keeps writing into the work folder."""
    if not _HELD_LOCKS or not _PRCTL:
        return
    _PRCTL(1, 9)  # PR_SET_PDEATHSIG, SIGKILL
    if os.getppid() != _FORK_PARENT:  # the parent died before prctl took effect
        os._exit(1)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_before_fork, after_in_child=_after_fork_in_child)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class VersionLock:
    """Exclusive, non-blocking ``flock`` on ``<stage_dir>/.lock-<version>`` (module docstring)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd: int | None = None

    def try_acquire(self) -> bool:
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as e:
                os.close(fd)
                if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    return False
                raise
            try:
                st = os.stat(self.path)
            except FileNotFoundError:
                st = None
            mine = os.fstat(fd)
            if st is not None and (st.st_ino, st.st_dev) == (mine.st_ino, mine.st_dev):
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                self.fd = fd
                _prctl()
                _HELD_LOCKS.add(fd)
                return True
            os.close(fd)  # its holder removed the file after we opened it: lock the new one

    def holder(self) -> int | None:
        try:
            return int(self.path.read_text().strip())
        except (OSError, ValueError):
            return None

    def release(self) -> None:
        if self.fd is None:
            return
        fd, self.fd = self.fd, None
        _HELD_LOCKS.discard(fd)
        try:
            self.path.unlink(missing_ok=True)
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)


def lock_version(stage_dir: Path, stage: str, version: str, work_dir: Path) -> VersionLock:
    """The version's lock, or ArtifactError when another live run of it holds the lock."""
    lock = VersionLock(stage_dir / f"{LOCK_PREFIX}{version}")
    deadline = time.monotonic() + LOCK_GRACE_S
    while not lock.try_acquire():
        pid = lock.holder()
        if pid is not None and not _pid_alive(pid) and time.monotonic() < deadline:
            time.sleep(0.1)  # a killed run's forked workers are still exiting
            continue
        if pid is None or _pid_alive(pid):
            who = f"pid {pid}" if pid is not None else "another process"
            fix = (
                f"wait for it to finish, or stop it (`kill {pid}`) and run the stage again"
                if pid is not None
                else "wait for it to finish"
            )
        else:
            who = (
                f"pid {pid} has exited, but processes it started still hold the lock `{lock.path}`"
            )
            fix = f"stop them (`fuser -k {lock.path}`) and run the stage again"
        raise ArtifactError(
            f"[{stage}] another run of {stage} {version} is writing {work_dir} ({who}); {fix}."
            " A run killed part-way resumes where it stopped."
        )
    return lock


def remove_path(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def remove_stale_tmp(stage_dir: Path, current: str) -> None:
    """Remove what interrupted runs left, except what a live run or a rerun may still use
    (module docstring): called with the lock of version ``current`` held."""
    now = time.time()
    for path in stage_dir.glob(f"{TMP_PREFIX}*"):
        try:
            age = now - path.lstat().st_mtime
            if path.name.startswith(f"{TMP_PREFIX}old-{current}-"):
                remove_path(path)  # ours: left by a run of this version killed while swapping
            elif _RANDOM_TMP.match(path.name) or not path.is_dir() or path.is_symlink():
                if age >= STALE_TMP_S:  # a concurrent run of older code may still write there
                    remove_path(path)
            elif path.name != f"{TMP_PREFIX}{current}" and age >= RESUME_KEEP_S:
                other = path.name[len(TMP_PREFIX) :]
                lock = VersionLock(stage_dir / f"{LOCK_PREFIX}{other}")
                if lock.try_acquire():  # nobody is writing there
                    try:
                        remove_path(path)
                    finally:
                        lock.release()
        except FileNotFoundError:
            pass
