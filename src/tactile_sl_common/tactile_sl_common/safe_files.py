"""Output files that never destroy their input: same-file checks, writability, atomic rename.

Every command that writes a file (``tactile-sl replay -o``, ``train -o``, ``evaluate --json``,
``pattern generate/render``) goes through these helpers:

* :func:`check_output` decides "same file" by the file system (device and inode, so hard
  links, symlinks and ``..`` paths are caught), refuses an output inside an input bag
  directory, and checks that the target directory can take a new file *before* any long
  work starts;
* :func:`atomic_path` yields a temporary file in the target directory and renames it over
  the target only when the block ends without an exception, so an interrupted or failed run
  leaves an existing output untouched and never leaves a stub;
* :func:`write_files` writes a set of files that belong together (``calibrate``'s
  ``left.yaml``, ``right.yaml``, ``coverage.png``; ``sensor.yaml``) all or none, after
  :func:`check_outputs` has refused, before any work, targets that cannot be written.

Outputs get the mode a plain ``open()`` gives (0666 less the umask), not the 0600 of the
temporary file they are written as.
"""
from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import tempfile
from pathlib import Path
from typing import Iterable, Iterator


class OutputError(OSError):
    """An output path that cannot or must not be written; the message says why."""


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when both paths name one existing file (same device and inode)."""
    try:
        sa, sb = os.stat(a), os.stat(b)
    except OSError:
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def _input_files(path: Path) -> list[Path]:
    """The file itself, or for a directory (a rosbag2 bag) every file directly in it."""
    if path.is_dir():
        return [p for p in path.iterdir() if p.is_file()]
    return [path]


def check_output(output: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """Refuse an output that is an input or cannot be created; returns it as a Path.

    Raises :class:`OutputError` (one line, naming the paths) when ``output`` is one of the
    ``inputs`` (or a file of an input directory, or would go into an input directory), is a
    directory, or its directory does not exist / is not writable.
    """
    out = Path(output)
    for raw in inputs:
        inp = Path(raw)
        for f in _input_files(inp):
            if same_file(f, out):
                raise OutputError(f"{out} is the input file {f}: choose another output path")
        if inp.is_dir() and same_file(out.parent if str(out.parent) else ".", inp):
            raise OutputError(f"{out} is inside the input bag directory {inp}: "
                              "choose another output path")
    if out.is_dir():
        raise OutputError(f"{out} is a directory, not a file path")
    if out.exists() and not out.is_file():
        raise OutputError(f"{out} exists and is not a regular file")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.exists():
        raise OutputError(f"cannot write {out}: directory {parent} does not exist")
    if not parent.is_dir():
        raise OutputError(f"cannot write {out}: {parent} is not a directory")
    try:   # the real test (root ignores permission bits, read-only mounts do not)
        fd, probe = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".probe", dir=parent)
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)
    return out


def _file_mode() -> int:
    """The mode a new file gets from ``open()``: 0666 less the process umask."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def check_outputs(directory: str | os.PathLike, names: Iterable[str]) -> Path:
    """Refuse, before any work, a set of outputs in ``directory`` that cannot be written.

    ``directory`` may not exist yet (it is created when writing); its nearest existing
    ancestor must then be a writable directory.  Each ``directory / name`` that exists must
    be a regular file (it is replaced).  Raises :class:`OutputError` naming the path.
    """
    d = Path(directory)
    if d.exists() and not d.is_dir():
        raise OutputError(f"cannot write into {d}: it is not a directory")
    for name in names:
        target = d / name
        if target.exists() and not target.is_file():
            raise OutputError(f"cannot write {target}: it exists and is not a regular file")
    existing = d
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"cannot create {d}: {existing} is not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=".probe.", suffix=".probe", dir=existing)
    except OSError as exc:
        raise OutputError(f"cannot write into {existing}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)
    return d


def write_files(directory: str | os.PathLike, files: dict[str, bytes]) -> list[Path]:
    """Write every file into ``directory``, all or none; returns the paths written.

    Each file is written to a temporary name beside its target first; only when all are
    written are they renamed onto their targets.  Should a rename still fail (the target
    turned into a directory meanwhile, a full or read-only file system), the targets
    already renamed are put back as they were (an earlier file restored from a hard-linked
    copy, a new one removed) and :class:`OutputError` is raised.
    """
    d = check_outputs(directory, files)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {d}: {exc.strerror or exc}") from None
    mode = _file_mode()
    temps: dict[str, Path] = {}
    backups: dict[str, Path] = {}
    done: list[str] = []
    try:
        for name, data in files.items():
            fd, tmp_name = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=d)
            temps[name] = Path(tmp_name)
            with os.fdopen(fd, "wb") as fh:
                os.fchmod(fh.fileno(), mode)
                fh.write(data)
        for name in files:                 # earlier versions, to put back on a failure
            if (d / name).is_file():
                backups[name] = d / f".{name}.{secrets.token_hex(4)}.bak"
                try:
                    os.link(d / name, backups[name])
                except OSError:            # no hard links here: a copy does
                    shutil.copy2(d / name, backups[name])
        for name in files:
            os.replace(temps[name], d / name)
            del temps[name]
            done.append(name)
        return [d / name for name in files]
    except BaseException as exc:          # Ctrl-C included: the set stays as it was
        for name in reversed(done):
            with contextlib.suppress(OSError):
                if name in backups:
                    os.replace(backups.pop(name), d / name)
                else:
                    (d / name).unlink()
        if not isinstance(exc, OSError):
            raise
        target = getattr(exc, "filename2", None) or getattr(exc, "filename", None) or d
        raise OutputError(f"cannot write {target}: {exc.strerror or exc}; nothing written "
                          f"to {d}") from None
    finally:
        for leftover in list(temps.values()) + list(backups.values()):
            with contextlib.suppress(OSError):
                leftover.unlink()


@contextlib.contextmanager
def atomic_path(output: str | os.PathLike) -> Iterator[Path]:
    """A temporary path next to ``output``, renamed onto it if the block succeeds.

    On an exception (KeyboardInterrupt included) the temporary file is removed and
    ``output`` is left as it was.
    """
    out = Path(output)
    parent = out.parent if str(out.parent) else Path(".")
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=parent)
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, _file_mode())
        os.replace(tmp, out)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_text(output: str | os.PathLike, text: str) -> None:
    """Write a text file atomically (temporary file + rename)."""
    with atomic_path(output) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_bytes(output: str | os.PathLike, data: bytes) -> None:
    """Write a binary file atomically (temporary file + rename)."""
    with atomic_path(output) as tmp:
        tmp.write_bytes(data)
