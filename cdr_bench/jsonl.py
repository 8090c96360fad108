"""JSON-lines files kept either plain (``X.jsonl``) or gzip-compressed (``X.jsonl.gz``).

The repository keeps the logs and per-episode files of finished runs (``sweeps/landed/``, the
``analysis/``, ``tuning/`` and ``ablations/`` folders of ``agents/``) compressed; the readers of
those files (``cdr_bench.leaderboard.tables``, ``sweeps/*.py``) read them through
:func:`read_jsonl`, which takes either name: ``X.jsonl`` is read as ``X.jsonl.gz`` when only
that exists, and the other way round. Compressed files are written by :func:`gzip_file`
deterministically (no file name, ``mtime=0`` in the header), so compressing the same bytes
twice gives the same file.

Training logs named by ``leaderboard/submissions/*.yaml`` and the leaderboard's result files
stay plain: their readers (``cdr_bench.leaderboard.data``, ``cdr_bench.evaluate.results``) read
``.jsonl`` only.
"""

from __future__ import annotations

import gzip
import io
import json
import os
import zlib
from pathlib import Path
from typing import Any

GZ = ".gz"


def existing(path: str | os.PathLike[str]) -> Path:
    """``path`` if it exists, else its other form (``X.jsonl`` <-> ``X.jsonl.gz``) if that
    exists, else ``path`` unchanged (so that the caller's error names the file it was given)."""
    p = Path(path)
    if p.exists():
        return p
    other = p.with_name(p.name[: -len(GZ)]) if p.name.endswith(GZ) else p.with_name(p.name + GZ)
    return other if other.exists() else p


def read_bytes(path: str | os.PathLike[str]) -> bytes:
    """The content of ``path`` (or of its other form, :func:`existing`), decompressed when the
    file is gzip. A damaged gzip file is an ``OSError`` naming it."""
    p = existing(path)
    data = p.read_bytes()
    if data[:2] != b"\x1f\x8b":
        return data
    try:
        return gzip.decompress(data)
    except (EOFError, zlib.error, gzip.BadGzipFile) as e:
        raise OSError(f"{p}: damaged gzip file ({e})") from None


def read_text(path: str | os.PathLike[str]) -> str:
    """:func:`read_bytes` as UTF-8 text."""
    return read_bytes(path).decode("utf-8")


def read_jsonl(path: str | os.PathLike[str]) -> list[Any]:
    """One JSON value per non-blank line of ``path`` (plain or gzip, either name)."""
    return [json.loads(x) for x in read_text(path).splitlines() if x.strip()]


def gzip_bytes(data: bytes) -> bytes:
    """``data`` gzip-compressed (level 9), with no file name and ``mtime=0`` in the header:
    the same bytes always give the same file."""
    buf = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", compresslevel=9, fileobj=buf, mtime=0) as g:
        g.write(data)
    return buf.getvalue()


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def gzip_file(
    src: str | os.PathLike[str], dst: str | os.PathLike[str] | None = None, remove: bool = True
) -> Path:
    """Write ``src`` compressed to ``dst`` (default ``src`` + ``.gz``; atomically) and, with
    ``remove``, delete ``src``. Returns ``dst``."""
    s = Path(src)
    d = Path(dst) if dst is not None else s.with_name(s.name + GZ)
    _atomic_write(d, gzip_bytes(s.read_bytes()))
    if remove and s != d:
        s.unlink()
    return d


def gunzip_file(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> Path:
    """Write the content of ``src`` (plain or gzip, either name) to ``dst``, plain (atomically).
    Returns ``dst``."""
    d = Path(dst)
    _atomic_write(d, read_bytes(src))
    return d
