"""cdr_bench.jsonl: JSON-lines files read plain, gzip or xz under any of their names; gzip and
xz (``cdr_bench.evaluate.results.compress_log``) written deterministically; decompressed sizes
capped (``results.log_text``)."""

from __future__ import annotations

import gzip
import lzma
from pathlib import Path

import pytest

from cdr_bench.evaluate.results import compress_log, log_text
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


def test_xz_logs_are_deterministic_standard_and_read_under_any_name(tmp_path: Path) -> None:
    """``results.compress_log`` (the leaderboard's per-episode logs and shipped training logs)
    gives the same bytes for the same text, a standard xz stream; every reader takes it."""
    text = ROWS.decode()
    a = compress_log(text)
    assert a == compress_log(text) and a[:6] == b"\xfd7zXZ\x00"
    assert lzma.decompress(a) == ROWS
    packed = tmp_path / "log.jsonl.xz"
    packed.write_bytes(a)
    assert log_text(packed) == text
    want = [{"step": 1}, {"step": 2, "final": {"step": 2}}]
    assert read_jsonl(packed) == read_jsonl(tmp_path / "log.jsonl") == want
    assert existing(tmp_path / "log.jsonl") == packed
    assert existing(tmp_path / "log.jsonl.gz") == packed


def test_log_text_caps_the_decompressed_size_and_names_a_damaged_file(tmp_path: Path) -> None:
    """A small compressed file that expands past the cap is refused without being decompressed
    whole (xz and gzip alike); a truncated or trailing-garbage stream is a ValueError naming
    the file; a legacy gzip log is read."""
    text = '{"x": 0}\n' * 100_000  # 900 kB of text, a few kB compressed
    xz, gz = tmp_path / "big.jsonl.xz", tmp_path / "big.jsonl.gz"
    xz.write_bytes(compress_log(text))
    gz.write_bytes(gzip_bytes(text.encode()))
    assert xz.stat().st_size < 10_000
    assert log_text(xz, limit=len(text)) == log_text(gz, limit=len(text)) == text
    for p in (xz, gz):
        with pytest.raises(ValueError, match=f"{p.name}: larger than a per-episode log may be"):
            log_text(p, limit=len(text) - 1)
    bad = tmp_path / "bad.jsonl.xz"
    bad.write_bytes(compress_log(text)[:-20])
    with pytest.raises(ValueError, match="bad.jsonl.xz: not an xz per-episode log"):
        log_text(bad)
    bad.write_bytes(compress_log(text) + b"more")
    with pytest.raises(ValueError, match="data after the end of the xz stream"):
        log_text(bad)
    with pytest.raises(OSError, match="bad.jsonl.xz: not an xz JSON-lines file"):
        read_jsonl(bad)
