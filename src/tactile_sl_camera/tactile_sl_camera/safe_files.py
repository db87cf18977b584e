"""Output files that never destroy their input: same-file checks, writability, atomic rename.

Every command that writes a file (``tactile-sl replay -o``, ``train -o``, ``evaluate --json``,
``pattern generate/render``) goes through these helpers:

* :func:`check_output` decides "same file" by the file system (device and inode, so hard
  links, symlinks and ``..`` paths are caught), refuses an output inside an input bag
  directory, and checks that the target directory can take a new file *before* any long
  work starts;
* :func:`atomic_path` yields a temporary file in the target directory and renames it over
  the target only when the block ends without an exception, so an interrupted or failed run
  leaves an existing output untouched and never leaves a stub.
"""
from __future__ import annotations

import contextlib
import os
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
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
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
