"""Read the classifier's weights file (written by ``torch.save``) without importing torch.

Importing torch costs a decoder process about 3.5 s of CPU at start (measured on the 2-core
development VM: ``python -c "import torch"`` 3.6 s, the whole decoder node module 1.8 s
without it), and inference needs no torch (:mod:`.classifier` runs on numpy).  ``torch.save``
writes a zip archive (PyTorch's serialization format since 1.6): ``<name>/data.pkl``, a
pickle of the saved object whose tensors are persistent references to raw little- or
big-endian storages ``<name>/data/<key>``, plus ``<name>/byteorder``.

The pickle is read with an unpickler that knows exactly the globals a dict of plain tensors
needs (the tensor rebuild function, the storage types, ``collections.OrderedDict``) and
refuses every other one, so, like ``torch.load(weights_only=True)``, a file that would run
code when unpickled is refused without running it.  Tensors come back as numpy arrays.
"""
from __future__ import annotations

import collections
import io
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

_STORAGE_DTYPES = {
    "FloatStorage": np.float32, "DoubleStorage": np.float64, "HalfStorage": np.float16,
    "LongStorage": np.int64, "IntStorage": np.int32, "ShortStorage": np.int16,
    "CharStorage": np.int8, "ByteStorage": np.uint8, "BoolStorage": np.bool_,
}


class WeightsFileError(ValueError):
    """Not a zip archive written by ``torch.save``, or one holding more than plain tensors."""


class _Storage:
    """A storage type named in the pickle (its numpy dtype)."""

    def __init__(self, name: str) -> None:
        self.dtype = np.dtype(_STORAGE_DTYPES[name])


def read_torch_zip(path: str | Path) -> Any:
    """The object ``torch.save`` wrote to ``path``; its tensors as numpy arrays."""
    try:
        archive = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as exc:
        raise WeightsFileError(f"not a zip archive written by torch.save ({exc})") from None
    with archive:
        names = archive.namelist()
        pickles = [n for n in names if n.endswith("/data.pkl") and n.count("/") == 1]
        if len(pickles) != 1:
            raise WeightsFileError("no <name>/data.pkl record: not written by torch.save")
        prefix = pickles[0][:-len("data.pkl")]
        order = "little"
        if prefix + "byteorder" in names:
            order = archive.read(prefix + "byteorder").decode("ascii", "replace").strip()
        if order not in ("little", "big"):
            raise WeightsFileError(f"unknown byte order {order!r}")

        def storage(key: str, dtype: np.dtype) -> np.ndarray:
            try:
                raw = archive.read(f"{prefix}data/{key}")
            except KeyError:
                raise WeightsFileError(f"storage {key} is missing") from None
            return np.frombuffer(raw, dtype.newbyteorder("<" if order == "little" else ">"))

        try:
            return _Unpickler(io.BytesIO(archive.read(pickles[0])), storage).load()
        except WeightsFileError:
            raise
        except Exception as exc:   # a corrupt archive entry or a malformed pickle: say so
            raise WeightsFileError(f"unreadable pickle ({type(exc).__name__}: {exc})") from None


class _Unpickler(pickle.Unpickler):
    """Plain tensors, dicts, lists and scalars only (see the module docstring)."""

    def __init__(self, data: io.BytesIO, storage: Any) -> None:
        super().__init__(data)
        self._storage = storage
        self._loaded: dict[str, np.ndarray] = {}

    def find_class(self, module: str, name: str) -> Any:
        if module == "torch._utils" and name == "_rebuild_tensor_v2":
            return _rebuild_tensor
        if module == "torch" and name in _STORAGE_DTYPES:
            return _Storage(name)
        if module == "collections" and name == "OrderedDict":
            return collections.OrderedDict
        raise WeightsFileError(f"refusing to unpickle {module}.{name} (plain tensors only)")

    def persistent_load(self, pid: Any) -> np.ndarray:
        if not (isinstance(pid, tuple) and len(pid) == 5 and pid[0] == "storage"
                and isinstance(pid[1], _Storage)):
            raise WeightsFileError(f"unknown persistent record {pid!r:.80}")
        _, kind, key, _location, _numel = pid
        if key not in self._loaded:
            self._loaded[key] = self._storage(str(key), kind.dtype)
        return self._loaded[key]


def _rebuild_tensor(storage: np.ndarray, offset: int, size: tuple[int, ...],
                    stride: tuple[int, ...], *_: Any) -> np.ndarray:
    """A tensor of ``size`` with ``stride`` (elements) at ``offset`` into ``storage``."""
    size, stride = tuple(int(s) for s in size), tuple(int(s) for s in stride)
    extent = 1 + sum((n - 1) * s for n, s in zip(size, stride)) if all(size) else 0
    if offset < 0 or offset + extent > len(storage) or any(s < 0 for s in stride):
        raise WeightsFileError(f"tensor of size {size} does not fit its storage")
    view = np.lib.stride_tricks.as_strided(storage[offset:], size,
                                           tuple(s * storage.itemsize for s in stride))
    return np.array(view, dtype=storage.dtype.newbyteorder("="))
