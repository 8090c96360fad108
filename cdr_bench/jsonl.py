"""JSON-lines files kept plain (``X.jsonl``), gzip-compressed (``X.jsonl.gz``) or
xz-compressed (``X.jsonl.xz``).

The repository keeps the logs and per-episode files of finished runs (``sweeps/landed/``, the
``analysis/``, ``tuning/`` and ``ablations/`` folders of ``agents/``) gzip-compressed; the readers
of those files (``cdr_bench.leaderboard.tables``, ``sweeps/*.py``) read them through
:func:`read_jsonl`, which takes any of the names: ``X.jsonl`` is read as ``X.jsonl.xz`` or
``X.jsonl.gz`` when only that exists, and the other way round. Compressed files are written by
:func:`gzip_file` deterministically (no file name, ``mtime=0`` in the header), so compressing
the same bytes twice gives the same file.

The training logs named by ``leaderboard/submissions/*.yaml`` and the leaderboard's per-episode
logs are xz (``X.jsonl.xz``), written and read by
:func:`cdr_bench.evaluate.results.compress_log` and :func:`cdr_bench.evaluate.results.log_text`;
:func:`read_bytes` reads an xz file through the latter.
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
XZ = ".xz"


def existing(path: str | os.PathLike[str]) -> Path:
    """``path`` if it exists, else another form of it (``X.jsonl``, ``X.jsonl.xz``,
    ``X.jsonl.gz``, in this order) if one exists, else ``path`` unchanged (so that the caller's
    error names the file it was given)."""
    p = Path(path)
    if p.exists():
        return p
    plain = p.name.removesuffix(GZ).removesuffix(XZ) if p.name.endswith((GZ, XZ)) else p.name
    for name in (plain, plain + XZ, plain + GZ):
        if name != p.name and p.with_name(name).exists():
            return p.with_name(name)
    return p


def read_bytes(path: str | os.PathLike[str]) -> bytes:
    """The content of ``path`` (or of another form of it, :func:`existing`), decompressed when
    the file is gzip or xz (``X.xz``). A damaged compressed file is an ``OSError`` naming it."""
    p = existing(path)
    if p.name.endswith(XZ):
        from cdr_bench.evaluate.results import log_text

        try:
            return log_text(p, "JSON-lines file").encode("utf-8")
        except ValueError as e:
            raise OSError(str(e)) from None
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
    """One JSON value per non-blank line of ``path`` (plain, gzip or xz, any name)."""
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
    """Write the content of ``src`` (plain, gzip or xz, any name) to ``dst``, plain (atomically).
    Returns ``dst``."""
    d = Path(dst)
    _atomic_write(d, read_bytes(src))
    return d
