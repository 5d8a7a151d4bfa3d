"""Writing into an output directory: create it, prove it writable, write a file atomically.

Shared by ``navpp process`` (:mod:`navpp.api`) and ``navpp compare`` (:mod:`navpp.comparison`).
Every failure is an :class:`~navpp.errors.InputError` with a one-line message naming the path
and a short reason (:func:`os_reason`).  The rules of what may be replaced or removed there
(lock, manifest, inputs) are in :mod:`navpp.outdir`.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import InputError
from .outdir import OutDirLock


def os_reason(exc: OSError) -> str:
    """An OSError as a short lower-case reason ("permission denied"), without the path."""
    return (exc.strerror or str(exc) or type(exc).__name__).lower()


def first_non_directory(path: Path) -> Path | None:
    """``path`` or its nearest ancestor that exists but is not a directory, if any."""
    for p in (path, *path.parents):
        if p.exists() or p.is_symlink():
            return None if p.is_dir() else p
    return None


def prepare_out_dir(out: Path, label: str) -> list[Path]:
    """Create ``out`` (with parents) and prove it is writable by creating and removing a file.

    Returns the directories this call created (outermost first), so that a run that fails
    later can remove them again.  Raises :class:`InputError` ``"<label> <out>: cannot write
    there (<reason>)"``.
    """
    missing = [p for p in (out, *out.parents) if not (p.exists() or p.is_symlink())][::-1]
    try:
        blocker = first_non_directory(out)
        if blocker is not None:
            what = "it is" if blocker == out else f"{blocker} is"
            kind = "a broken symbolic link" if not blocker.exists() else "a file, not a directory"
            raise InputError(f"{label} {out}: cannot write there ({what} {kind})")
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=out, prefix=".navpp-write-test-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        remove_created_dirs(missing)
        raise InputError(f"{label} {out}: cannot write there ({os_reason(exc)})") from None
    return missing


def remove_created_dirs(created: list[Path]) -> None:
    """Remove the (still empty) directories :func:`prepare_out_dir` created, innermost first."""
    for d in reversed(created):
        try:
            d.rmdir()
        except OSError:
            break


@contextmanager
def claimed_out_dir(out: Path, label: str, leftovers: Iterable[str], lock_label: str | None = None) -> Iterator[None]:
    """The block runs with ``out`` created (:func:`prepare_out_dir`, messages naming ``label``)
    and locked (:class:`~navpp.outdir.OutDirLock`, naming ``lock_label``, default ``label``;
    ``leftovers``: the file names of dead runs it removes).  On leaving, the lock is released;
    on an exception (an interrupt too) the directories this created are removed again."""
    created = prepare_out_dir(out, label)
    lock = OutDirLock(out, label if lock_label is None else lock_label, extra_leftovers=leftovers)
    try:
        lock.acquire()       # held until the files are written: a second run into out fails at once
        yield
    except BaseException:
        lock.release()
        remove_created_dirs(created)
        raise
    lock.release()


def write_text_file(path: Path, data: str | bytes) -> None:
    """``data`` to ``path`` atomically (text as UTF-8, bytes as they are);
    :class:`~navpp.errors.InputError` naming the file."""
    from .io.writers import atomic_write

    try:
        atomic_write(path, lambda f: f.write(data), mode="wb" if isinstance(data, bytes) else "w")
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({os_reason(exc)})") from None
