"""The stored form of a per-episode log (``cdr_bench.evaluate.logcodec``): lossless on every
committed log, a quarter smaller compressed, the fallback to plain lines for what the rules do
not fit, and hostile stored forms refused with a message naming the file."""

from __future__ import annotations

import hashlib
import json
import lzma
from pathlib import Path

import pytest

from cdr_bench.cli import main
from cdr_bench.evaluate import logcodec
from cdr_bench.evaluate import results as rf

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "leaderboard" / "results"


def _seeds(result: dict) -> dict[str, tuple[int, str]]:
    return {s["id"]: (result["base_seed"], s["config_hash"]) for s in result["scenarios"]}


@pytest.mark.parametrize("name", ["mvp", "mvp-reciprocal"])
def test_committed_logs_are_stored_compactly_and_give_their_lines_back(name: str) -> None:
    """A single-agent and a multi-agent entry: the stored text is what ``episodes_sha256``
    names (as ``xz -dc | sha256sum`` computes it) and its records are the full lines'; on the
    first 50 lines, encoding is deterministic and takes less room than the lines stored plain
    (the whole log is what the CHANGELOG measured: encoding is the costly direction)."""
    path = RESULTS / f"{name}.json"
    result = json.loads(path.read_text())
    log = path.with_suffix("").with_suffix(".jsonl.xz")
    raw = lzma.decompress(log.read_bytes()).decode()
    assert raw.startswith('{"cdr-bench log":1')
    assert hashlib.sha256(raw.encode()).hexdigest() == result["episodes_sha256"]
    text = rf.log_text(log)
    full = [json.loads(line) for line in text.splitlines()]
    assert logcodec.records(raw) == full
    assert [list(r) for r in logcodec.records(raw)] == [list(r) for r in full]  # key order
    assert full[0]["scenario"] == result["scenarios"][0]["id"] and full[0]["episode"] == 0
    assert full[0]["seed"] == logcodec.derive_seed(
        result["base_seed"], full[0]["scenario"], result["scenarios"][0]["config_hash"], 0
    )
    head = "".join(text.splitlines(keepends=True)[:50])
    stored = logcodec.encode(head, _seeds(result))
    assert stored == logcodec.encode(head, _seeds(result)) and stored != head
    assert logcodec.decode(stored, len(head)) == head
    assert len(rf.compress_log(stored)) < 0.9 * len(rf.compress_log(head))


def test_records_that_the_rules_do_not_fit_are_stored_as_they_are() -> None:
    ok = {"scenario": "s", "episode": 0, "seed": 5, "steps": 2, "aircraft": [
        {"id": "a", "outcome": "success", "steps": 2, "los": False, "los_events": 0,
         "actions": "dd"}]}  # fmt: skip
    text = json.dumps(ok, separators=(",", ":")) + "\n"
    stored = logcodec.encode(text)
    assert stored != text and logcodec.decode(stored, 10**6) == text
    # the seed is kept where no derivation was stated, dropped where it was
    assert '"seed":5' in stored
    odd = [
        {**ok, "steps": True},  # a bool where the rule derives an int
        {**ok, "aircraft": [{**ok["aircraft"][0], "los": 1}]},  # an int for a flag
        {"episode": 0, "scenario": "s", "aircraft": []},  # another key order
        {**ok, "episode": 3},  # an episode number that does not follow
    ]
    for rec in odd:
        t = json.dumps(rec, separators=(",", ":")) + "\n"
        assert logcodec.decode(logcodec.encode(t), 10**6) == t
    assert logcodec.encode("not json\n") == "not json\n"
    assert logcodec.encode('{"a":1}') == '{"a":1}'  # no final newline: as it is


@pytest.mark.parametrize(
    "stored, message",
    [
        ('{"cdr-bench log":2}\n{}\n', "another version"),
        ('{"cdr-bench log":1,"ids":{},"seeds":{}}\n', "without ids, seeds or aircraft_keys"),
        ('{"cdr-bench log":1,"ids":{"s":["' + "x" * 65 + '"]},"seeds":{},"aircraft_keys":[]}\n',
         "malformed aircraft identifier"),
        ('{"cdr-bench log":1,"ids":{},"seeds":{"s":[1.5,"h"]},"aircraft_keys":[]}\n',
         "malformed seed"),
        ('{"cdr-bench log":1,"ids":{},"seeds":{},"aircraft_keys":[]}\n[1]\n', "not a JSON object"),
        ('{"cdr-bench log":1,"ids":{},"seeds":{},"aircraft_keys":[]}\n{"scenario":"s",'
         '"aircraft":' + json.dumps([{}] * 4097) + "}\n", "more than 4096 aircraft"),
        ('{"cdr-bench log":1,"ids":{},"seeds":{},"aircraft_keys":[]}\n{"aircraft":1}\n',
         "damaged"),
        ('{"cdr-bench log":1,"ids":{},"seeds":{},"aircraft_keys":[]}\n{"scenario":"s"', "damaged"),
    ],
)  # fmt: skip
def test_a_damaged_stored_form_is_an_error_naming_the_file(
    tmp_path: Path, stored: str, message: str
) -> None:
    p = tmp_path / "r.jsonl.xz"
    p.write_bytes(rf.compress_log(stored))
    with pytest.raises(ValueError, match=message) as e:
        rf.log_text(p)
    assert str(e.value).startswith(str(p))


def test_expansion_is_capped() -> None:
    head = '{"cdr-bench log":1,"ids":{"s":["' + "i" * 64 + '"]},"seeds":{},"aircraft_keys":["id"]}'
    line = '{"scenario":"s","episode":0,"aircraft":[{}]}'
    stored = head + "\n" + line + "\n"
    assert len(logcodec.decode(stored, 10**6)) > len(stored) - len(head)
    with pytest.raises(ValueError, match="expands past 50 characters"):
        logcodec.decode(stored, 50)


def test_a_new_result_is_written_in_the_stored_form(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    agent = str(ROOT / "agents" / "mvp" / "agent.py")
    assert main(["evaluate", agent, "--scenario", "low", "--episodes", "4", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    raw = lzma.decompress(out.with_suffix(".jsonl.xz").read_bytes()).decode()
    assert raw.startswith('{"cdr-bench log":1') and '"seed"' not in raw.split("\n", 1)[1]
    assert hashlib.sha256(raw.encode()).hexdigest() == result["episodes_sha256"]
    eps = rf.read_episodes(out, rf.read_result(out))
    assert [e["episode"] for e in eps] == [0, 1, 2, 3] and all("seed" in e for e in eps)


def test_restore_rewrites_a_plain_log_and_its_hash_and_nothing_else(tmp_path: Path) -> None:
    """``python -m cdr_bench.evaluate.logcodec RESULT.json``: what turned the committed logs
    into the stored form; a log that does not match its JSON is refused, untouched."""
    out = tmp_path / "r.json"
    agent = str(ROOT / "agents" / "direct" / "agent.py")
    assert main(["evaluate", agent, "--scenario", "low", "--episodes", "3", "--out", str(out)]) == 0
    log = out.with_suffix(".jsonl.xz")
    text = rf.log_text(log)
    doc = json.loads(out.read_text())
    log.write_bytes(rf.compress_log(text))  # the plain form, as written before the codec
    out.write_text(json.dumps({**doc, "episodes_sha256": rf.sha256_text(text)}, indent=1) + "\n")
    before = rf.read_episodes(out, rf.read_result(out))
    logcodec.restore_files([str(out)])  # bytes saved: negative for 3 episodes (the header)
    assert lzma.decompress(log.read_bytes()).startswith(b'{"cdr-bench log":1')
    assert json.loads(out.read_text()) == doc
    assert rf.read_episodes(out, rf.read_result(out)) == before
    log.write_bytes(rf.compress_log(text + text.split("\n")[0] + "\n"))  # one more line
    with pytest.raises(ValueError, match="its log does not match it"):
        logcodec.restore_files([str(out)])
