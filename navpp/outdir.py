"""Safety of an output directory: one run at a time, only navpp's own files removed, no leftovers.

An output directory (``--out``) may hold the user's own files, the results of an earlier run
and, by mistake, the very inputs of this run (``navpp process x/trajectory.mcap --out x``).
The rules, used by :func:`navpp.api.process` and :func:`navpp.comparison.compare`:

- **Lock** (:class:`OutDirLock`): a run holds an advisory lock (``fcntl.flock``) on
  ``<out>/.navpp.lock`` from before it reads its inputs until its files are written.  A second
  run into the same directory fails at once with one line naming the directory and the pid of
  the run that holds it.  The kernel drops the lock when its process dies (even by SIGKILL),
  so a dead run never blocks a later one.  The lock file is removed when the run ends.
- **Manifest** (``<out>/.navpp-manifest.json``): the names of the files navpp wrote there.
  A run removes an earlier result it did not write again (e.g. ``metrics.json`` of a run with a
  reference, or a figure, :data:`FIGURE_SUFFIXES`, of a run with ``--plot`` or other filters)
  only if the manifest lists it, so a file the user put there under a navpp name is never
  deleted; in a directory without a manifest no such file is removed.
- **Inputs** (:func:`input_files`): a file that is an input of the current run (same device
  and inode) is never removed or replaced; a run whose output would replace one of its inputs
  is refused before it starts (:func:`refuse_overwriting_inputs`).
- **Leftovers**: staging directories (``.navpp-run-*``) and temporary files of a
  run that was killed (SIGKILL, power loss) are removed by the next run that takes the lock:
  while the lock is held no other live navpp run can own them.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import shutil
from collections.abc import Iterable
from pathlib import Path

from .errors import InputError

LOCK_NAME = ".navpp.lock"
#: Endings of the figure files navpp writes (``<log>_<kind>`` of ``process --plot`` and of a
#: ``compare`` report, :mod:`navpp.plots`, :mod:`navpp.comparison.figures`): a run that did not
#: write such a file again removes it when the manifest lists it (:func:`stale_figures`).
FIGURE_SUFFIXES = ("_trajectory.png", "_error_time.png", "_error_cdf.png", "_adaptive.png", "_errors.png",
                   "_innovations.png", "_map.html")
MANIFEST_NAME = ".navpp-manifest.json"
STAGING_PREFIX = ".navpp-run-"


def _reason(exc: OSError) -> str:
    return (exc.strerror or str(exc) or type(exc).__name__).lower()


class OutDirLock:
    """Context manager: hold the advisory lock of ``out`` (a directory that exists).

    Raises :class:`InputError` ``"<label> <out>: another navpp run (pid N) is writing there; ..."``
    when another live process holds it, or ``"<label> <out>: cannot lock it (<reason>)"``.
    On entry, leftovers of dead runs are removed (:func:`remove_leftovers`).
    """

    def __init__(self, out: Path, label: str = "--out", *, extra_leftovers: Iterable[str] = ()) -> None:
        self.out = Path(out)
        self.label = label
        self.path = self.out / LOCK_NAME
        self.extra_leftovers = tuple(extra_leftovers)
        self.fd: int | None = None

    def __enter__(self) -> OutDirLock:
        self.acquire()
        return self

    def acquire(self) -> None:
        """Take the lock (see the class); then remove the leftovers of dead runs."""
        import fcntl

        for _ in range(20):          # the file may be unlinked by its holder between open and flock
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            except OSError as exc:
                raise InputError(f"{self.label} {self.out}: cannot lock it ({_reason(exc)})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = _read_pid(fd)
                os.close(fd)
                if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                    who = f"another navpp run (pid {holder})" if holder else "another navpp run"
                    raise InputError(f"{self.label} {self.out}: {who} is writing there; wait for it to end "
                                     f"or choose another {self.label}") from None
                if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
                    _unlink_quietly(self.path)      # a file system without flock: run unguarded
                    return
                raise InputError(f"{self.label} {self.out}: cannot lock it ({_reason(exc)})") from None
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)             # we locked a file its holder had just removed: take the new one
        else:
            raise InputError(f"{self.label} {self.out}: cannot lock it (the lock file keeps changing)")
        self.fd = fd
        from .interrupts import guard

        guard(self.out)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        remove_leftovers(self.out, self.extra_leftovers)

    def __exit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        """Remove the lock file, then drop the lock (in this order: see the retry in :meth:`acquire`)."""
        if self.fd is None:
            return
        _unlink_quietly(self.path)
        os.close(self.fd)
        self.fd = None


def _unlink_quietly(path: Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        return int(text) if text.isdigit() else None
    except OSError:
        return None


def remove_leftovers(out: Path, names: Iterable[str] = ()) -> None:
    """Remove what a killed navpp run left in ``out``: ``.navpp-run-*`` staging directories and
    the temporary files of :func:`navpp.io.writers.atomic_write`
    (``.<name>.<8 characters>.tmp``) for a navpp file name: one of ``names``, or ending in one
    of them when it starts with ``*`` (``"*_trajectory.png"``).  Only call it while holding
    ``out``'s lock: a live run makes these only while it holds the lock.  (Not the write
    probes of :func:`navpp.outfiles.prepare_out_dir`: a run makes one before it takes the lock.)
    Best effort."""
    exact = {n for n in names if not n.startswith("*")} | {MANIFEST_NAME}
    endings = tuple(n[1:] for n in names if n.startswith("*"))
    try:
        entries = list(os.scandir(out))
    except OSError:
        return
    for e in entries:
        try:
            if e.name.startswith(STAGING_PREFIX) and e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path, ignore_errors=True)
            elif e.is_file(follow_symlinks=False):
                m = _TMP.match(e.name)
                if m is not None and (m.group(1) in exact or m.group(1).endswith(endings or ("\0",))):
                    os.unlink(e.path)
        except OSError:
            pass


_TMP = re.compile(r"^\.(.+)\.[A-Za-z0-9_]{8}\.tmp$")


# ----------------------------------------------------------------------------------- manifest


def read_manifest(out: Path) -> set[str]:
    """The file names the manifest of ``out`` lists (plain names only); empty if none or unreadable."""
    try:
        data = json.loads((Path(out) / MANIFEST_NAME).read_text(encoding="utf-8"))
        files = data.get("files", []) if isinstance(data, dict) else []
    except (OSError, ValueError):
        return set()
    return {f for f in files if isinstance(f, str) and f and "/" not in f and f not in (".", "..")}


def stale_figures(out: Path, written: Iterable[str], ours: Iterable[str]) -> list[Path]:
    """The figures of an earlier run in ``out`` that this run did not write: files named in
    the manifest (``ours``, :func:`read_manifest`) ending in :data:`FIGURE_SUFFIXES`, not among
    ``written`` (names), regular files (not symbolic links), in name order."""
    done = set(written)
    return [Path(out) / n for n in sorted(ours) if n.endswith(FIGURE_SUFFIXES) and n not in done
            and (Path(out) / n).is_file() and not (Path(out) / n).is_symlink()]


def write_manifest(out: Path, names: Iterable[str]) -> None:
    """Write the manifest of ``out`` (atomically) listing ``names``."""
    from .io.writers import atomic_write

    data = {"written_by": "navpp", "note": "files navpp wrote here; a later run may replace or remove only these",
            "files": sorted(set(names))}
    atomic_write(Path(out) / MANIFEST_NAME, lambda f: f.write(json.dumps(data, indent=1) + "\n"))


# ----------------------------------------------------------------------------------- inputs


def input_files(*paths: str | os.PathLike[str] | None, not_in_dirs: Iterable[str] = ()) -> set[tuple[int, int]]:
    """(device, inode) of every input file: each path given, and for a directory (a CSV log, a
    ROS 2 bag) the files directly inside it except those named in ``not_in_dirs`` (navpp's own
    output names: a log directory may also be the output directory).  Missing paths are skipped."""
    skip = set(not_in_dirs)
    ids: set[tuple[int, int]] = set()
    for p in paths:
        if p is None:
            continue
        try:
            st = os.stat(p)
        except OSError:
            continue
        ids.add((st.st_dev, st.st_ino))
        if os.path.isdir(p):
            try:
                for e in os.scandir(p):
                    if e.name not in skip and e.is_file():
                        s = e.stat()
                        ids.add((s.st_dev, s.st_ino))
            except OSError:
                pass
    return ids


def is_input(path: Path, inputs: set[tuple[int, int]]) -> bool:
    """Whether ``path`` exists and is one of the ``inputs`` (:func:`input_files`)."""
    try:
        st = os.stat(path)
    except OSError:
        return False
    return (st.st_dev, st.st_ino) in inputs


def refuse_overwriting_inputs(out: Path, names: Iterable[str], inputs: set[tuple[int, int]],
                              label: str = "--out") -> None:
    """:class:`InputError` if writing any of ``names`` into ``out`` would replace an input file."""
    for name in names:
        if is_input(Path(out) / name, inputs):
            raise InputError(f"{label} {out}: {name} there is an input of this run and would be replaced by "
                             f"its output; choose another {label}")
