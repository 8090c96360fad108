"""What the wheel and the sdist ship, checked without building them (.ci/wheel_smoke.sh builds
and installs them): no symbolic link in the package, every scenario of ``scenarios/`` and every
built-in agent in setup.py's list, and where the package finds them."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from types import ModuleType

import pytest

import cdr_bench._data as data
from cdr_bench.evaluate.loader import AgentError, agent_identity, resolve_agent_path
from cdr_bench.scenarios import list_scenarios, registry_root

ROOT = Path(__file__).resolve().parent.parent


def _setup_py() -> ModuleType:
    spec = importlib.util.spec_from_file_location("cdr_bench_setup_py", ROOT / "setup.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # not __main__: defines, does not call setup()
    return module


def test_no_symbolic_link_in_the_package() -> None:
    links = []
    for root, dirs, names in os.walk(ROOT / "cdr_bench"):
        links += [
            os.path.relpath(os.path.join(root, n), ROOT)
            for n in dirs + names
            if os.path.islink(os.path.join(root, n))
        ]
    assert links == []


def test_every_scenario_and_builtin_agent_is_shipped() -> None:
    shipped = set(_setup_py().shipped_files(ROOT))
    scenarios = {p.relative_to(ROOT).as_posix() for p in (ROOT / "scenarios").rglob("*.yaml")}
    assert len(scenarios) > 20 and scenarios <= shipped
    agents = {f"agents/{name}/agent.py" for name in data.BUILTIN_AGENTS}
    assert {"agents/mvp/agent.py", "agents/direct/agent.py"} <= agents <= shipped
    assert shipped == scenarios | agents  # nothing else (no tests, no weights)


def test_setup_py_refuses_a_pattern_that_matches_nothing(tmp_path: Path) -> None:
    (tmp_path / "cdr_bench" / "_data").mkdir(parents=True)
    (tmp_path / "cdr_bench" / "_data" / "__init__.py").write_text('SHIPPED = ("nothing/*.yaml",)')
    with pytest.raises(FileNotFoundError, match="matches no file"):
        _setup_py().shipped_files(tmp_path)


def test_a_checkout_reads_the_repository_folders(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CDR_BENCH_SCENARIOS", raising=False)
    assert registry_root() == ROOT / "scenarios"
    assert "high" in list_scenarios() and "tactical/head-on" in list_scenarios()
    assert data.data_dir("agents") == ROOT / "agents"


def test_an_installed_copy_is_preferred(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "scenarios").mkdir()
    monkeypatch.setattr(data, "files", lambda _package: tmp_path)  # as in a wheel
    assert data.data_dir("scenarios") == tmp_path / "scenarios"
    assert data.data_dir("agents") == ROOT / "agents"  # no copy: the checkout's


def test_builtin_agent_names(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    for name in data.BUILTIN_AGENTS:
        assert resolve_agent_path(name) == ROOT / "agents" / name / "agent.py"
    ident = agent_identity("mvp", checkpoint=None)
    assert ident["name"] == "mvp"
    assert ident["sha256"] == agent_identity(ROOT / "agents" / "mvp", checkpoint=None)["sha256"]
    (tmp_path / "mvp").mkdir()  # a folder of that name here wins
    with pytest.raises(AgentError, match="has no agent.py"):
        resolve_agent_path("mvp")
    with pytest.raises(AgentError, match="built-in agents: direct, mvp, random"):
        resolve_agent_path("mvpp")
