"""Output paths checked before anything is written: a file or a folder cartctl can write, else one
line naming the option, the path and why (for the commands' ``--out`` and the API's ``save``)."""

from __future__ import annotations

import contextlib
import errno
import itertools
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from cartctl.errors import InputError, OutputError

__all__ = ["check_output_file", "check_output_folder", "writing"]


def check_output_folder(folder: str | Path, option: str) -> Path:
    """``folder`` when cartctl can create it and write files into it, else one line naming
    ``option``, the folder and why. It really writes (and removes again): permissions, read-only
    and virtual file systems alike."""
    folder = Path(folder)
    why = _unwritable(folder)
    if why is not None:
        raise InputError(f"{option} {folder}: {why}")
    return folder


@contextlib.contextmanager
def writing(path: str | Path) -> Iterator[None]:
    """A block writing ``path`` (its folder made first): an OSError in it (a full disk) is an
    :class:`OutputError` naming the file, exit 1 as a run's trace, not the bare reason (exit 2)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)  # (its failure: the bare reason)
    try:
        yield
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(path, exc.strerror or str(exc)) from None


def check_output_file(path: str | Path, option: str) -> Path:
    """``path`` when cartctl can write (or replace) it; else as :func:`check_output_folder`."""
    path = Path(path)
    base = next((folder for folder in path.absolute().parents if folder.is_dir()), Path("/"))
    long = len(os.fsencode(path.name)) > os.pathconf(base, "PC_NAME_MAX")  # is_dir would raise
    if not long and path.is_dir():
        raise InputError(f"{option} {path}: is a folder, not a file")
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise InputError(f"{option} {path}: cannot create: {parent} is a file")
    why = _unwritable(parent, there="cannot create")
    if why is None and long:
        why = "cannot create: file name too long"  # the folder is fine, the file is not
    if why is None and path.exists() and not os.access(path, os.W_OK):
        why = "cannot write: permission denied"
    if why is not None:
        raise InputError(f"{option} {path}: {why}")
    return path


_REASONS = {
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.EROFS: "read-only file system",
    errno.ENOSPC: "no space left on device",
    errno.EDQUOT: "disk quota exceeded",
    errno.ENAMETOOLONG: "file name too long",
}


def _unwritable(folder: Path, there: str = "cannot write there") -> str | None:
    """None when a file can be written in ``folder`` (made for the test and removed), else why;
    ``there`` begins the answer when ``folder`` exists but takes no file."""
    missing = list(itertools.takewhile(lambda p: not p.exists(), [folder, *folder.parents]))
    broken = next((p for p in missing if p.is_symlink()), None)
    if broken is not None:  # a dangling link: mkdir would fail on it
        return f"cannot create: {broken} is a broken link"
    existing = missing[-1].parent if missing else folder
    if not existing.is_dir():
        if existing == folder:
            return "is a file, not a folder"
        return f"cannot create: {existing} is a file"
    made: list[Path] = []
    step = "cannot create"
    try:
        for path in reversed(missing):
            path.mkdir()
            made.append(path)
        step = there if not made else step
        probe = folder / f".cartctl-write-test-{os.getpid()}"
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as exc:
        if exc.errno == errno.ENOENT:  # its parent is there, yet it cannot be made: /proc
            return f"{step}: {existing} takes no new files or folders"
        return f"{step}: {_REASONS.get(exc.errno or 0, (exc.strerror or str(exc)).lower())}"
    finally:
        for path in reversed(made):
            with contextlib.suppress(OSError):
                path.rmdir()
    return None


def remove_stale_recording(trace: str | Path, keep: str | Path | None = None) -> None:
    """Remove the ``.rrd`` beside a new ``trace``: an earlier run's of that name would pass for
    this trace's recording. Not when it is ``trace`` itself or ``keep``; a failure is ignored."""
    stale = Path(trace).with_suffix(".rrd").resolve()
    if stale == Path(trace).resolve() or (keep is not None and stale == Path(keep).resolve()):
        return
    with contextlib.suppress(OSError):
        stale.unlink(missing_ok=True)


def call_each(
    calls: Iterable[Callable[..., object]],
    *args: object,
    failed: Callable[[OutputError], object] = lambda exc: None,
) -> None:
    """Call each with ``args``; a failed file write (an OutputError, given to ``failed``) does not
    stop the others, and the first is raised once all have run."""
    first: OutputError | None = None
    for call in calls:
        try:
            call(*args)
        except OutputError as exc:
            failed(exc)
            first = first or exc
    if first is not None:
        raise first
