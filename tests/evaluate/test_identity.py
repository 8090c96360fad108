"""An agent's identity covers its code, weights and configuration, not its docs or outputs."""

from __future__ import annotations

import pytest

from cdr_bench.evaluate.loader import AgentError, agent_identity

AGENT = (
    "class Agent:\n"
    "    def __init__(self, o, a):\n"
    "        pass\n"
    "    def act(self, o):\n"
    "        return 13\n"
)


def make_agent(tmp_path):
    d = tmp_path / "my_agent"
    d.mkdir()
    (d / "agent.py").write_text(AGENT)
    (d / "weights.pt").write_bytes(b"\x00\x01")
    return d


def test_outputs_and_docs_do_not_change_identity(tmp_path):
    d = make_agent(tmp_path)
    before = agent_identity(d)
    assert sorted(before["files"]) == ["agent.py", "weights.pt"]
    (d / "README.md").write_text("notes")
    (d / "curve.png").write_bytes(b"png")
    (d / "eval").mkdir()
    (d / "eval" / "paper.json").write_text("{}")
    assert agent_identity(d)["sha256"] == before["sha256"]


def test_code_weights_and_checkpoint_override_change_identity(tmp_path, monkeypatch):
    d = make_agent(tmp_path)
    base = agent_identity(d)["sha256"]
    (d / "weights.pt").write_bytes(b"\x00\x02")
    changed = agent_identity(d)["sha256"]
    assert changed != base
    other = tmp_path / "other.pt"
    other.write_bytes(b"other")
    monkeypatch.setenv("CDR_BENCH_CHECKPOINT", str(other))
    ident = agent_identity(d)
    assert ident["sha256"] != changed
    assert ident["checkpoint_override"]["path"] == str(other)
    monkeypatch.setenv("CDR_BENCH_CHECKPOINT", str(tmp_path / "missing.pt"))
    with pytest.raises(AgentError, match="no such checkpoint"):
        agent_identity(d)
