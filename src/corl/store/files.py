"""Files written whole or not at all: through a temporary file beside the target, then renamed.

A full disk, a read-only folder or an error midway leaves the old file (or none), never half a file
and never the temporary file (only a SIGKILL can leave one: a hidden ``.<name>.<random><suffix>``).
Used by every command that writes a result file (``corl export``, ``corl sweep``, ``corl report``,
the ``summary.json`` of ``corl run``).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable

from corl.errors import InputError

__all__ = ["write_atomically", "write_text_atomically"]

_MODE = 0o644  # mkstemp creates 0o600; a result file is readable like any other


def write_atomically(path: str | os.PathLike, write: Callable[[Path], object], *,
                     hint: str = "choose another --out") -> Path:
    """Call ``write(tmp)`` on a temporary path beside ``path`` (same suffix), then rename it to ``path``.

    On any failure the temporary file is removed; an :class:`OSError` (a full disk, a read-only
    folder) becomes an :class:`InputError` naming the file, the reason and ``hint``. Returns ``path``.
    """
    path = Path(path)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
        os.close(fd)
    except OSError as exc:
        raise _cannot_write(path, exc, hint) from None
    tmp = Path(name)
    try:
        write(tmp)
        os.chmod(tmp, _MODE)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise _cannot_write(path, exc, hint) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text_atomically(path: str | os.PathLike, text: str, *, hint: str = "choose another --out") -> Path:
    """:func:`write_atomically` of UTF-8 ``text``."""
    return write_atomically(path, lambda tmp: tmp.write_text(text, encoding="utf-8"), hint=hint)


def _cannot_write(path: Path, exc: OSError, hint: str) -> InputError:
    reason = exc.strerror or str(exc) or type(exc).__name__
    return InputError(f"cannot write {path}: {reason}; nothing was written there, {hint}")
