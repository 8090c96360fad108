"""Weights-only PyTorch checkpoints read without PyTorch: the shipped learned agents' loader.

A ``.pt`` file written by ``torch.save`` is a zip archive: ``<name>/data.pkl`` (a pickle of
the saved object, whose tensors refer to storages by key) and ``<name>/data/<key>`` (each
storage's raw bytes). :func:`read_checkpoint` unpickles ``data.pkl`` with a loader that knows
exactly the few names a weights-only file of plain tensors uses (``collections.OrderedDict``,
``torch._utils._rebuild_tensor_v2`` and the typed storage classes) and nothing else, and builds
each tensor as a numpy array straight from its storage's bytes (offset, shape and strides as
recorded): the same values, bit for bit, as ``torch.load(..., weights_only=True)`` followed by
``.numpy()``. Like torch's weights-only loader it cannot run code from the file; unlike it, it
needs no ``import torch`` (1.5 CPU s per process: the agent processes of the leaderboard's
checks and evaluations start many).

Anything else in a file (another global, a storage on a device other than the CPU, a dtype
numpy lacks) raises :class:`UnsupportedCheckpoint`; :func:`load_weights` then falls back to
``torch.load(weights_only=True)`` where torch is installed, so a checkpoint torch reads is
never refused.
"""

from __future__ import annotations

import collections
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

_STORAGES = {
    "DoubleStorage": np.float64,
    "FloatStorage": np.float32,
    "HalfStorage": np.float16,
    "LongStorage": np.int64,
    "IntStorage": np.int32,
    "ShortStorage": np.int16,
    "CharStorage": np.int8,
    "ByteStorage": np.uint8,
    "BoolStorage": np.bool_,
}
"""The typed storage classes of torch's pickles and the numpy dtype of their elements."""


class UnsupportedCheckpoint(ValueError):
    """The file holds something :func:`read_checkpoint` does not read (it may still be a valid
    checkpoint for ``torch.load``)."""


class _StorageType:
    __slots__ = ("dtype",)  # no __dict__: a BUILD in the pickle cannot change it

    def __init__(self, name: str) -> None:
        self.dtype = np.dtype(_STORAGES[name]).newbyteorder("<")


def _rebuild_tensor_v2(
    storage: np.ndarray,
    offset: int,
    size: tuple[int, ...],
    stride: tuple[int, ...],
    requires_grad: bool = False,
    hooks: Any = None,
    metadata: Any = None,
) -> np.ndarray:
    n = int(np.prod(size, dtype=np.int64)) if size else 1
    if n == 0:
        return np.zeros(size, storage.dtype)
    last = offset + sum((s - 1) * st for s, st in zip(size, stride, strict=True))
    if offset < 0 or min(stride, default=0) < 0 or last >= len(storage) or n > len(storage):
        raise UnsupportedCheckpoint("a tensor lies outside its storage or repeats its values")
    view = np.lib.stride_tricks.as_strided(
        storage[offset:], shape=size, strides=[s * storage.itemsize for s in stride]
    )
    return np.array(view, dtype=storage.dtype.newbyteorder("="), copy=True, order="C")


class _Unpickler(pickle.Unpickler):
    def __init__(self, data: bytes, archive: zipfile.ZipFile, prefix: str) -> None:
        import io

        super().__init__(io.BytesIO(data))
        self.archive, self.prefix = archive, prefix
        self.storages: dict[str, np.ndarray] = {}

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) == ("collections", "OrderedDict"):
            return collections.OrderedDict
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            return _rebuild_tensor_v2
        if module == "torch" and name in _STORAGES:
            return _StorageType(name)
        raise UnsupportedCheckpoint(f"{module}.{name} in the pickle")

    def persistent_load(self, pid: Any) -> Any:
        if not (isinstance(pid, tuple) and len(pid) == 5 and pid[0] == "storage"):
            raise UnsupportedCheckpoint(f"persistent id {pid!r:.60}")
        _, kind, key, location, numel = pid
        if not isinstance(kind, _StorageType) or str(location) != "cpu":
            raise UnsupportedCheckpoint(f"a storage of {kind!r:.40} on {location!r:.20}")
        key = str(key)
        if key not in self.storages:
            try:
                raw = self.archive.read(f"{self.prefix}data/{key}")
            except KeyError:
                raise UnsupportedCheckpoint(f"storage {key} missing from the archive") from None
            if len(raw) != int(numel) * kind.dtype.itemsize:
                raise UnsupportedCheckpoint(f"storage {key}: {len(raw)} bytes for {numel} values")
            self.storages[key] = np.frombuffer(raw, kind.dtype)
        return self.storages[key]


def read_checkpoint(path: str | Path) -> Any:
    """The object saved in ``path`` by ``torch.save``, its tensors as numpy arrays (see the
    module docstring); :class:`UnsupportedCheckpoint` where it holds anything else."""
    try:
        with zipfile.ZipFile(path) as z:
            pkl = [n for n in z.namelist() if n.endswith("data.pkl") and n.count("/") == 1]
            if len(pkl) != 1:
                raise UnsupportedCheckpoint("not a torch zip archive (no single data.pkl)")
            prefix = pkl[0][: -len("data.pkl")]
            order = z.read(f"{prefix}byteorder") if f"{prefix}byteorder" in z.namelist() else b""
            if order not in (b"", b"little"):
                raise UnsupportedCheckpoint(f"byte order {order!r}")
            return _Unpickler(z.read(pkl[0]), z, prefix).load()
    except zipfile.BadZipFile as e:
        raise UnsupportedCheckpoint(f"not a zip archive ({e})") from None
    except (pickle.UnpicklingError, EOFError, TypeError, AttributeError) as e:
        raise UnsupportedCheckpoint(f"{type(e).__name__}: {e}") from None


def _numpy(obj: Any) -> Any:
    """torch tensors in nested dicts, lists and tuples as numpy arrays."""
    if isinstance(obj, dict):
        return type(obj)((k, _numpy(v)) for k, v in obj.items())
    if isinstance(obj, (list, tuple)):
        return type(obj)(_numpy(v) for v in obj)
    if hasattr(obj, "detach") and hasattr(obj, "numpy"):
        return obj.detach().cpu().numpy()
    return obj


def load_weights(path: str | Path) -> Any:
    """The object in a weights-only checkpoint with its tensors as numpy arrays: read by
    :func:`read_checkpoint` (no torch), or, for what that does not read, by
    ``torch.load(weights_only=True)`` (torch's own errors then: a missing file is
    ``FileNotFoundError``)."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    try:
        return read_checkpoint(path)
    except UnsupportedCheckpoint as e:
        try:
            import torch
        except ImportError:
            raise UnsupportedCheckpoint(f"{path}: {e}, and torch is not installed") from None
        return _numpy(torch.load(path, map_location="cpu", weights_only=True))
