"""The writer lock of a run store: one writing process per database file, whatever its name.

The lock is an exclusive, non-blocking ``flock`` on the store file itself, so it belongs to the
file (its inode), not to a name: a hard link or a symbolic link to the same store meets the same
lock. ``flock`` belongs to the open file description, so the kernel drops it when the process
exits or is killed: a stale lock of a crashed run cannot exist, and nothing is left beside the
store. On Linux ``flock`` and the POSIX record locks SQLite takes on the same file do not
interact (stores belong on a local disk; SQLite's write-ahead log needs one anyway).

One POSIX rule shapes the code: closing *any* descriptor of a file drops every POSIX record lock
the process holds on it, SQLite's included. So the lock's descriptor is opened before SQLite opens
the file and closed after SQLite closed it, and a second writer of the same file inside this
process is refused from a table of held files, without opening the file again.

On Windows (no ``fcntl``) the lock falls back to ``msvcrt.locking`` on a sibling ``<store>.lock``.
"""

from __future__ import annotations

import errno
import os
import socket
from pathlib import Path

from corl.store.records import StoreError

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None
    import msvcrt

__all__ = ["WriterLock"]

_HELD: set[tuple[int, int]] = set()  # (st_dev, st_ino) of every store file this process writes


def _key(st: os.stat_result) -> tuple[int, int]:
    return st.st_dev, st.st_ino


def _flock_holder(st: os.stat_result) -> str | None:
    """The pid holding an exclusive flock on the file ``st`` describes, from ``/proc/locks`` (Linux)."""
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        parts = line.split()
        if len(parts) < 6 or parts[1] != "FLOCK" or parts[3] != "WRITE":
            continue
        try:
            major, minor, inode = parts[5].split(":")
            same = (int(major, 16), int(minor, 16), int(inode)) == (os.major(st.st_dev), os.minor(st.st_dev),
                                                                    st.st_ino)
        except ValueError:
            continue
        if same:
            return parts[4]
    return None


class WriterLock:
    """The writer lock of one store file; :meth:`acquire` it, :meth:`release` it when done.

    Attributes
    ----------
    created : True when :meth:`acquire` created the (empty) store file, so a refused open can
        remove it again and leave nothing behind.
    """

    def __init__(self, store_path: Path) -> None:
        self.store_path = Path(store_path)
        self.created = False
        self._fd: int | None = None
        self._key: tuple[int, int] | None = None

    # -- acquiring -----------------------------------------------------------------------------
    def acquire(self, *, create: bool) -> None:
        """Take the lock, creating the store file first when ``create`` and it does not exist.

        Raises :class:`StoreError` when another process (or another RunStore of this process)
        writes the same file under any name, or when the file cannot be opened for writing.
        """
        if fcntl is None:  # pragma: no cover - Windows
            return self._acquire_sibling(create=create)
        for _ in range(5):  # the name can be re-pointed between open and lock: then try again
            try:
                before = os.stat(self.store_path)
            except FileNotFoundError:
                before = None
            except OSError as exc:
                raise self._cannot_open(exc) from None
            if before is not None and _key(before) in _HELD:
                raise self._busy(str(os.getpid()))
            flags = os.O_RDWR | getattr(os, "O_CLOEXEC", 0) | (os.O_CREAT | os.O_EXCL if before is None else 0)
            if before is None and not create:
                raise StoreError(f"no store at {self.store_path}; check the --store path")
            try:
                fd = os.open(self.store_path, flags, 0o644)
            except FileExistsError:
                continue  # created by someone else meanwhile
            except FileNotFoundError:
                continue  # removed meanwhile
            except OSError as exc:
                raise self._cannot_open(exc) from None
            created = before is None
            st = os.fstat(fd)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = _flock_holder(st)
                os.close(fd)  # this process writes nothing to the file (checked above)
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise StoreError(f"cannot lock store {self.store_path} for writing: {exc.strerror}; keep "
                                     "stores on a local disk") from None
                raise self._busy(holder) from None
            if not self._names_file(st):
                os.close(fd)  # replaced or removed while we locked it: start over
                continue
            self._fd, self._key, self.created = fd, _key(st), created
            _HELD.add(self._key)
            return
        raise StoreError(f"store {self.store_path} keeps being replaced while it is opened; stop the other "
                         "program that renames or deletes it")

    def _names_file(self, st: os.stat_result) -> bool:
        try:
            return _key(os.stat(self.store_path)) == _key(st)
        except OSError:
            return False

    def _busy(self, pid: str | None) -> StoreError:
        holder = "another process" if pid is None else f"process {pid} on {socket.gethostname()}"
        if pid == str(os.getpid()):
            holder += ", that is this very process: close the other RunStore first"
        return StoreError(
            f"store {self.store_path} is already open for writing by {holder}; one process writes a "
            "store at a time, under any of its names (links included). Wait for that run to finish "
            "(or stop it), or open the store read-only (`corl runs`, `corl status`, export) to look at it"
        )

    def _cannot_open(self, exc: OSError) -> StoreError:
        return StoreError(
            f"cannot open store {self.store_path} for writing: {exc.strerror}; open it read-only "
            "(`corl status`, `corl export`) to look at it, or copy it to a writable folder"
        )

    # -- releasing -----------------------------------------------------------------------------
    def release(self) -> None:
        """Drop the lock (after SQLite has closed the file); releasing twice is harmless."""
        if self._fd is not None:
            os.close(self._fd)  # closing drops the flock
            self._fd = None
        if self._key is not None:
            _HELD.discard(self._key)
            self._key = None

    # -- Windows -------------------------------------------------------------------------------
    def _acquire_sibling(self, *, create: bool) -> None:  # pragma: no cover - Windows
        if not self.store_path.exists():
            if not create:
                raise StoreError(f"no store at {self.store_path}; check the --store path")
            self.created = True
        lock_path = self.store_path.with_name(self.store_path.name + ".lock")
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise self._cannot_open(exc) from None
        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            os.close(fd)
            raise self._busy(None) from None
        self._fd = fd
