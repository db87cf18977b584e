"""Reference inversions kept on disk: a restarted node is ready at its first frame (no rclpy).

A :class:`~tactile_sl_decoder.touch.traction.TractionSolver` depends only on the pad (its
elastomer, pitch and lattice), the reference's cells, the inversion's weights and the code
that builds it; preparing one takes ~1-2 s on one core (three dense products and two
Cholesky factorisations of 3N x 3N, N ~ 700-840 cells), during which a live node queues
frames.  The cells of an untouched pad decode the same way at every start, so the products
are stored, keyed by all of those inputs, and read back in ~0.1 s.

The key is a SHA-256 over the cell kernel's bytes (the pad, pitch and lattice shape through
the code that computes it), the cells, the weights, ``mirrored`` and the source of the
modules that build the inversion: an entry written by other code is never read.  What is
read back is the very arrays that were computed, so the outputs are the same bytes either
way (test); they are computed on one BLAS thread, since OpenBLAS's rounding depends on how
it splits the work, so an entry does not depend on what its writer's process had set (test).
Entries are written to a temporary file and renamed (a reader never sees half a file, two
writers never clash); at most ``max_entries`` are kept, the least recently used
removed.  A file that cannot be read or written gives a warning and the inversion is
computed as if there were no cache.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import pathlib
import tempfile
import warnings
import zipfile
from typing import Any

import numpy as np

SUFFIX = ".npz"
DEFAULT_ENTRIES = 8


def default_directory() -> pathlib.Path:
    """``$XDG_CACHE_HOME/tactile_sl/traction``, or ``~/.cache/tactile_sl/traction``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return pathlib.Path(base) / "tactile_sl" / "traction"


def source_digest(*modules: Any) -> str:
    """SHA-256 of the source files of ``modules``: code that builds an entry is in its key."""
    digest = hashlib.sha256()
    for module in modules:
        digest.update(pathlib.Path(module.__file__).read_bytes())
    return digest.hexdigest()


def entry_key(kernel: np.ndarray, cells: np.ndarray, settings: dict[str, Any],
              code: str) -> str:
    """The file name stem of one inversion: every input it depends on, hashed."""
    digest = hashlib.sha256()
    digest.update(code.encode())
    digest.update(json.dumps(settings, sort_keys=True).encode())
    for array in (kernel, cells):
        contiguous = np.ascontiguousarray(array)
        digest.update(f"{contiguous.dtype.str}{contiguous.shape}".encode())
        digest.update(contiguous.tobytes())
    return digest.hexdigest()[:40]


class SolverCache:
    """A directory of stored inversions (arrays by name), least recently used removed."""

    def __init__(self, directory: str | os.PathLike[str] | None = None,
                 max_entries: int = DEFAULT_ENTRIES) -> None:
        self.directory = pathlib.Path(directory) if directory else default_directory()
        self.max_entries = int(max_entries)
        self.hits = 0
        self.misses = 0

    def path(self, key: str) -> pathlib.Path:
        """Where the entry ``key`` is stored."""
        return self.directory / f"{key}{SUFFIX}"

    def load(self, key: str, names: tuple[str, ...]) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``key`` (all of ``names``), or None."""
        path = self.path(key)
        try:
            with open(path, "rb") as file, np.load(file, allow_pickle=False) as stored:
                arrays = {name: stored[name] for name in names}
        except (FileNotFoundError, NotADirectoryError):   # none, or another process's trim
            # removed it just now (a directory that cannot hold one warns when storing)
            self.misses += 1
            return None
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            warnings.warn(f"solver cache: {path} is unreadable ({exc}); computing the "
                          f"inversion instead", stacklevel=2)
            self.misses += 1
            return None
        with contextlib.suppress(OSError):  # recently used (unless trimmed meanwhile)
            os.utime(path)
        self.hits += 1
        return arrays

    def store(self, key: str, arrays: dict[str, np.ndarray]) -> bool:
        """Write an entry (temporary file, then rename); False with a warning on failure."""
        path = self.path(key)
        tmp_name = None
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=self.directory, prefix=".tmp-",
                                             suffix=SUFFIX, delete=False) as tmp:
                tmp_name = tmp.name
                np.savez(tmp, **arrays)  # type: ignore[arg-type]
            os.replace(tmp_name, path)
            tmp_name = None
            self._trim()
        except OSError as exc:
            warnings.warn(f"solver cache: cannot write {path} ({exc}); the inversion is "
                          f"computed again at the next start", stacklevel=2)
            return False
        finally:
            if tmp_name is not None:
                try:
                    os.unlink(tmp_name)
                except OSError:
                    pass
        return True

    def _trim(self) -> None:
        """Remove the least recently used entries beyond ``max_entries``."""
        entries = []
        for path in self.directory.glob(f"*{SUFFIX}"):
            if path.name.startswith(".tmp-"):
                continue
            try:
                entries.append((path.stat().st_mtime, path))
            except OSError:
                continue
        entries.sort(reverse=True)
        for _, path in entries[self.max_entries:]:
            try:
                path.unlink()
            except OSError:
                pass
