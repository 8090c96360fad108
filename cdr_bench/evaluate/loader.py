"""Load an agent file (or a folder with ``agent.py``) by path; see :mod:`.protocol`.

Every failure is an :class:`AgentError` (a ``UserError``: one line, exit code 2) naming the file
and, where the agent's own code raised, the agent's own line.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
import sys
import traceback
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench._data import BUILTIN_AGENTS, data_dir
from cdr_bench.checks import file_kind
from cdr_bench.errors import UserError

_SKIP_DIRS = {"__pycache__", ".git", ".ipynb_checkpoints"}


class AgentError(UserError):
    """The agent could not be loaded or misbehaved; the message says where and how."""


def resolve_agent_path(path: str | os.PathLike[str]) -> Path:
    """The agent's Python file: ``path`` itself, or ``path/agent.py`` for a folder. A built-in
    name (:data:`~cdr_bench._data.BUILTIN_AGENTS`: ``direct``, ``mvp``, ``random``) that is no
    file or folder here is the reference agent shipped in the package (in a source checkout,
    the repository's ``agents/<name>/agent.py``)."""
    p = Path(path)
    if os.fspath(path) in BUILTIN_AGENTS and not p.exists():
        p = data_dir("agents") / os.fspath(path)
    if p.is_dir():
        if not (p / "agent.py").is_file():
            raise AgentError(f"agent folder {path} has no agent.py")
        return (p / "agent.py").resolve()
    if not p.exists():
        raise AgentError(
            f"agent file {path} not found (built-in agents: {', '.join(BUILTIN_AGENTS)})"
        )
    kind = file_kind(p.stat().st_mode)
    if kind is not None:  # a named pipe would block the hash, a device never ends
        raise AgentError(f"agent file {path}: is {kind}, not a Python file")
    if p.suffix != ".py":
        raise AgentError(f"agent file {path}: expected a .py file or a folder with agent.py")
    return p.resolve()


def agent_name(path: str | os.PathLike[str]) -> str:
    """``mvp`` for ``agents/mvp/agent.py`` or ``agents/mvp``; the file stem otherwise."""
    f = resolve_agent_path(path)
    return f.parent.name if f.name == "agent.py" else f.stem


CODE_SUFFIXES = (".py",)
CONFIG_SUFFIXES = (".json", ".yaml", ".yml", ".toml", ".txt")
WEIGHT_SUFFIXES = (".pt", ".pth", ".safetensors", ".npz", ".npy", ".onnx", ".ckpt", ".bin", ".pkl")
AGENT_FILE_SUFFIXES = CODE_SUFFIXES + CONFIG_SUFFIXES + WEIGHT_SUFFIXES
"""Files that can change what an agent does: code, configuration and weights. Documentation,
logs, plots and result files are never part of its identity."""

_SKIP_AGENT_DIRS = _SKIP_DIRS | {"eval", "results", "analysis", "runs", "tuning"}

CHECKPOINT_ENV = "CDR_BENCH_CHECKPOINT"
"""Environment variable an agent may read to load another checkpoint (the Diffusion-AC agent
scores its ablations this way); when set, the file it names is part of the identity."""


MAX_AGENT_FILES = 1000
"""Most files an agent's identity hashes (the largest shipped agent has fewer than 10)."""
MAX_AGENT_ENTRIES = 20_000
"""Most folder entries looked at while listing an agent's files."""
MAX_AGENT_BYTES = 8 << 30
"""Most bytes an agent's identity hashes (code, configuration and weights together)."""


def _too_many(folder: Path, what: str) -> AgentError:
    return AgentError(
        f"agent folder {folder}: {what}; an agent.py is hashed with every file of its folder "
        "(docs/agents.md, Identity): put it in a folder of its own"
    )


def _listing(folder: Path, suffixes: tuple[str, ...], recursive: bool) -> list[Path]:
    out: list[Path] = []
    seen = 0
    for root, dirs, names in os.walk(folder):
        dirs[:] = (
            sorted(d for d in dirs if d not in _SKIP_AGENT_DIRS and not d.startswith("."))
            if recursive
            else []
        )
        seen += len(dirs) + len(names)
        if seen > MAX_AGENT_ENTRIES:
            raise _too_many(folder, f"more than {MAX_AGENT_ENTRIES} files and folders")
        out += [Path(root) / n for n in names if n.endswith(suffixes) and not n.startswith(".")]
        if len(out) > MAX_AGENT_FILES:
            raise _too_many(folder, f"more than {MAX_AGENT_FILES} files to hash")
    return out


def agent_files(
    path: str | os.PathLike[str], checkpoint: str | os.PathLike[str] | None = None
) -> list[Path]:
    """The files an agent uses, which make up its identity (docs/agents.md, "Identity").

    A single file that is not ``agent.py``: that file. An ``agent.py``: the code of its folder
    (every ``.py`` below it, outside the output folders ``eval``, ``results``, ``analysis``,
    ``runs`` and ``tuning``), and then, with no ``checkpoint`` named, the configuration and
    weight files directly in its folder; with a ``checkpoint`` named, the configuration files
    beside that checkpoint (the checkpoint itself is hashed by :func:`agent_identity`). So
    re-training one seed, whose checkpoint lives in its own folder, changes the identity of the
    runs that name that checkpoint and of no other."""
    f = resolve_agent_path(path)
    if f.name != "agent.py":
        return [f]
    out = _listing(f.parent, CODE_SUFFIXES, recursive=True)
    if checkpoint is None:
        out += _listing(f.parent, CONFIG_SUFFIXES + WEIGHT_SUFFIXES, recursive=False)
    else:
        ck = Path(checkpoint).resolve()
        out += [
            p for p in _listing(ck.parent, CONFIG_SUFFIXES, recursive=False) if p.resolve() != ck
        ]
    return sorted(set(out))


@functools.cache
def reserved_module_names() -> frozenset[str]:
    """Top-level module names an agent's file may not take: the standard library's, the
    interpreter's built-in modules, every installed distribution's top-level packages, and
    ``cdr_bench``. A file ``json.py`` or ``numpy.py`` in a folder on some process's import path
    would replace the real module for whatever imports it there. An installed distribution's
    top-level names are those its ``top_level.txt`` declares and every module or folder name
    in the folder it is installed in (``site-packages``): a superset of what
    ``importlib.metadata.packages_distributions`` infers from every distribution's file list,
    which took 0.4-0.9 s at each start of a build. Computed once per process (the installed
    set does not change while a build runs)."""
    from importlib import metadata

    names = set(sys.stdlib_module_names) | set(sys.builtin_module_names) | {"cdr_bench"}
    folders = set()
    try:
        for dist in metadata.distributions():
            names.update((dist.read_text("top_level.txt") or "").split())
            folders.add(str(dist.locate_file("")))
    except Exception:  # noqa: BLE001 - a broken distribution's metadata: the rest still holds
        pass
    for folder in folders:
        try:
            entries = os.listdir(folder)
        except OSError:
            continue
        names.update(e.split(".", 1)[0] for e in entries)
    return frozenset(n for n in names if n.isidentifier())


def check_module_names(agent: Path, files: list[Path], what: str) -> None:
    """:class:`AgentError` naming the first code file among ``files`` (the files of the agent
    ``agent``) whose top-level module name, as the agent's folder on the import path makes it,
    would shadow a standard or installed module (:func:`reserved_module_names`): ``json.py``,
    ``numpy.py``, ``cdr_bench.py``, or a folder ``numpy/`` holding code."""
    reserved = reserved_module_names()
    top = resolve_agent_path(agent).parent
    for f in files:
        f = f.resolve()
        if f.suffix != ".py" or not f.is_relative_to(top):
            continue
        first = f.relative_to(top).parts[0]
        name = first.removesuffix(".py")
        if name in reserved:
            raise AgentError(
                f"{what}: agent file {f.relative_to(top)} would shadow the module `{name}` (a "
                "standard or installed module); rename it"
            )


def file_sha256(p: Path) -> str:
    """SHA-256 of a regular file's bytes (hex), read in 1 MiB chunks; anything else (a named
    pipe, a device, a folder) is an :class:`AgentError`, never a read that blocks."""
    kind = file_kind(p.stat().st_mode)
    if kind is not None:
        raise AgentError(f"{p}: is {kind}, not a file an agent may be made of")
    h = hashlib.sha256()
    with open(p, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


_FROM_ENV = object()


def _name(p: Path, base: Path) -> str:
    """``p`` relative to the agent's folder (``../`` for a file outside it)."""
    return Path(os.path.relpath(p.resolve(), base.resolve())).as_posix()


def agent_identity(path: str | os.PathLike[str], checkpoint: Any = _FROM_ENV) -> dict[str, Any]:
    """Path, name and SHA-256 of every file of the agent (relative names), plus one combined
    hash over them (and over the checkpoint override, when there is one): identifies exactly
    what was scored. The override is ``checkpoint`` when given (a path, or ``None`` for none),
    else the one named by ``CDR_BENCH_CHECKPOINT``. Given ``checkpoint`` (and an absolute
    ``path``), the hash depends on no environment variable or working directory, so threads may
    compute it for different agents at once (the leaderboard build's check does)."""
    f = resolve_agent_path(path)
    base = f.parent
    override = os.environ.get(CHECKPOINT_ENV) if checkpoint is _FROM_ENV else checkpoint
    if override:
        override = os.fspath(override)
        if not Path(override).is_file():
            raise AgentError(f"{CHECKPOINT_ENV}={override}: no such checkpoint file")
    listed = agent_files(path, override if override else None)
    total = sum(p.stat().st_size for p in listed)
    if total > MAX_AGENT_BYTES:
        raise _too_many(base, f"{total} bytes to hash, more than {MAX_AGENT_BYTES}")
    files = {_name(p, base): file_sha256(p) for p in listed}
    lines = [f"{k} {v}" for k, v in sorted(files.items())]
    identity: dict[str, Any] = {
        "name": agent_name(path),
        "path": os.path.relpath(f) if not os.path.relpath(f).startswith("..") else str(f),
        "entry": f.name,
        "files": files,
    }
    if override:
        ck = Path(override)
        digest = file_sha256(ck)
        identity["checkpoint_override"] = {"path": override, "sha256": digest}
        lines.append(f"{CHECKPOINT_ENV} {digest}")
    identity["sha256"] = hashlib.sha256("\n".join(lines).encode()).hexdigest()
    return identity


def agent_error_line(exc: BaseException, agent_file: Path) -> str:
    """``agent.py:12: <the line>: ValueError: message`` for the innermost frame inside the
    agent's folder (or the innermost frame at all), then the exception itself."""
    frames = traceback.extract_tb(exc.__traceback__)
    root = agent_file.parent if agent_file.name == "agent.py" else None
    mine = [
        fr
        for fr in frames
        if Path(fr.filename).resolve() == agent_file
        or (root is not None and Path(fr.filename).resolve().is_relative_to(root))
    ]
    what = "".join(traceback.format_exception_only(type(exc), exc)).strip().splitlines()
    what_line = what[-1] if what else type(exc).__name__
    if isinstance(exc, SyntaxError):
        return f"{Path(exc.filename or agent_file).name}:{exc.lineno}: {what_line}"
    chosen = mine or list(frames)
    if not chosen:
        return what_line
    fr = chosen[-1]
    code = f" `{fr.line.strip()}`" if fr.line else ""
    return f"{Path(fr.filename).name}:{fr.lineno}:{code}: {what_line}"


def _import_file(f: Path) -> ModuleType:
    digest = hashlib.sha256(str(f).encode()).hexdigest()[:12]
    mod_name = f"cdr_bench_agent_{f.stem}_{digest}"
    spec = importlib.util.spec_from_file_location(mod_name, f)
    if spec is None or spec.loader is None:  # pragma: no cover - .py files always have one
        raise AgentError(f"agent file {f}: cannot be imported")
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    sys.path.insert(0, str(f.parent))  # an agent folder may hold helper modules
    try:
        spec.loader.exec_module(module)
    except SyntaxError as e:
        sys.modules.pop(mod_name, None)
        raise AgentError(f"agent file {f}: syntax error: {agent_error_line(e, f)}") from None
    except Exception as e:
        sys.modules.pop(mod_name, None)
        raise AgentError(f"agent file {f}: import failed: {agent_error_line(e, f)}") from None
    finally:
        try:
            sys.path.remove(str(f.parent))
        except ValueError:  # pragma: no cover - the agent removed it itself
            pass
    return module


class LoadedAgent:
    """An agent instance behind the full protocol: ``act``, ``act_batch`` (native or row by row)
    and ``reset`` (a no-op when the agent has none)."""

    def __init__(self, instance: Any, path: Path):
        self.instance = instance
        self.path = path
        self.name = path.parent.name if path.name == "agent.py" else path.stem
        self.has_act_batch = callable(getattr(instance, "act_batch", None))
        self.joint = callable(getattr(instance, "act_joint", None))
        """the agent acts jointly: ``act_joint`` sees every aircraft of an episode at once"""
        self._reset = getattr(instance, "reset", None)

    def act(self, observation: dict[str, NDArray[Any]]) -> Any:
        return self.instance.act(observation)

    def act_batch(self, observations: NDArray[np.float32], masks: NDArray[np.int8]) -> Any:
        if self.has_act_batch:
            return self.instance.act_batch(observations, masks)
        return [
            self.instance.act({"observation": o, "action_mask": m})
            for o, m in zip(observations, masks, strict=True)
        ]

    def act_joint(self, *rows: NDArray[Any]) -> Any:
        """``act_joint(observations, masks, episodes, aircraft)`` of the agent."""
        return self.instance.act_joint(*rows)

    def reset(self, seed: int) -> None:
        if callable(self._reset):
            self._reset(seed)


def load_module(path: str | os.PathLike[str]) -> ModuleType:
    """Import the agent file at ``path`` (a ``.py`` file or a folder holding ``agent.py``) and
    check that it defines a class ``Agent`` with ``act``; :class:`AgentError` otherwise."""
    f = resolve_agent_path(path)
    module = _import_file(f)
    cls = getattr(module, "Agent", None)
    if cls is None:
        raise AgentError(
            f"agent file {f} defines no `Agent` (see agents/template/agent.py for the protocol)"
        )
    if not callable(cls):
        raise AgentError(f"agent file {f}: `Agent` is not a class but {type(cls).__name__}")
    if not callable(getattr(cls, "act", None)):
        raise AgentError(f"agent file {f}: `Agent` has no act(observation) method")
    module.__dict__.setdefault("__cdr_bench_agent_file__", f)
    return module


def construct(module: ModuleType, observation_space: Any, action_space: Any) -> LoadedAgent:
    """``Agent(observation_space, action_space)`` of a module from :func:`load_module`."""
    f = Path(module.__dict__["__cdr_bench_agent_file__"])
    try:
        instance = module.Agent(observation_space, action_space)
    except Exception as e:
        raise AgentError(
            f"agent file {f}: Agent(observation_space, action_space) raised: "
            f"{agent_error_line(e, f)}"
        ) from None
    return LoadedAgent(instance, f)


def load_agent(
    path: str | os.PathLike[str], observation_space: Any, action_space: Any
) -> LoadedAgent:
    """Import the agent file at ``path`` and construct ``Agent(observation_space, action_space)``
    in THIS process (the evaluator never does this: it runs the agent in its own process,
    :mod:`cdr_bench.evaluate.remote`; this is for the agent process and for tests).

    Raises :class:`AgentError` for a missing file, a syntax or import error, a file without a
    class ``Agent``, an ``Agent`` without ``act`` and a constructor that raises.
    """
    return construct(load_module(path), observation_space, action_space)
