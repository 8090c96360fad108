"""cdr_bench.jsonl: JSON-lines files read plain or gzip under either name; gzip written
deterministically."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest

from cdr_bench.jsonl import existing, gunzip_file, gzip_bytes, gzip_file, read_jsonl

ROWS = b'{"step": 1}\n\n{"step": 2, "final": {"step": 2}}\n'


def test_either_name_reads_either_form(tmp_path: Path) -> None:
    plain = tmp_path / "log.jsonl"
    plain.write_bytes(ROWS)
    want = [{"step": 1}, {"step": 2, "final": {"step": 2}}]
    assert read_jsonl(plain) == want
    assert read_jsonl(tmp_path / "log.jsonl.gz") == want  # only the plain file exists
    packed = gzip_file(plain)
    assert packed == tmp_path / "log.jsonl.gz" and not plain.exists()
    assert read_jsonl(packed) == want
    assert read_jsonl(plain) == want  # only the compressed file exists
    assert existing(plain) == packed and existing(packed) == packed
    assert existing(tmp_path / "none.jsonl") == tmp_path / "none.jsonl"
    assert gunzip_file(packed, tmp_path / "back.jsonl").read_bytes() == ROWS
    with pytest.raises(FileNotFoundError):
        read_jsonl(tmp_path / "none.jsonl")


def test_gzip_is_deterministic_and_standard(tmp_path: Path) -> None:
    a = gzip_bytes(ROWS)
    assert a == gzip_bytes(ROWS)
    assert a[4:8] == b"\0\0\0\0"  # mtime 0
    assert not a[3] & 0x08  # no file name in the header
    assert gzip.decompress(a) == ROWS
    (tmp_path / "x.jsonl").write_bytes(ROWS)
    (tmp_path / "y.jsonl").write_bytes(ROWS)
    assert (
        gzip_file(tmp_path / "x.jsonl").read_bytes() == gzip_file(tmp_path / "y.jsonl").read_bytes()
    )


def test_a_damaged_gzip_file_is_an_oserror_naming_it(tmp_path: Path) -> None:
    bad = tmp_path / "log.jsonl.gz"
    bad.write_bytes(gzip_bytes(ROWS)[:-12])
    with pytest.raises(OSError, match="log.jsonl.gz: damaged gzip file"):
        read_jsonl(bad)
