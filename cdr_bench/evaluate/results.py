"""Result files: a JSON of provenance per run and a per-episode log of facts beside it (xz
JSONL), both written atomically (temporary file + ``os.replace``), and the partial checkpoint
used by ``--resume``.

Facts in files, metrics at read time: the files hold what happened (per episode and aircraft:
outcome, steps, events, distances, and every decision taken); every metric, interval and table
is computed when a result is read (:func:`read_result` adds ``metrics`` to each scenario from
the per-episode log with :func:`cdr_bench.evaluate.metrics.scenario_metrics`). A new metric over
facts already recorded needs no re-evaluation and no rewrite of a committed file.

Layout of ``<out>.json`` (``schema_version`` 4)::

    schema_version, kind, agent {name, path, entry, files {name: sha256}, sha256},
    suite, base_seed, batch_size, seed_derivation, versions {cdr_bench, python, numpy, ...},
    scenarios [{id, config_hash, config, episodes, seeds_sha256}],
    episodes_file, episodes_sha256, run_key,
    timing {wall_s, episodes_per_s, workers, resumed, decision_latency {per scenario}}

Everything outside ``timing`` is a function of the agent's files, the scenarios, the base seed,
the batch size and the package versions: an interrupted run finished with ``--resume`` (or a run
with any ``--workers``) gives the same per-episode log and a JSON identical outside ``timing``.

``<out>.jsonl.xz``: xz (:func:`compress_log`: one fixed filter chain, so the same text gives
the same bytes) of one JSON line per episode and scenario, sorted by scenario (in run order)
then episode: ``{"scenario", "episode", "seed", "steps", "aircraft": [per-aircraft record]}``;
each aircraft record ends with ``actions``, its decisions one character each
(:data:`cdr_bench.evaluate.runner.ACTION_CODE`), from which ``leaderboard build --check``
replays the episode exactly. Inside the xz the log is in its stored form
(:mod:`cdr_bench.evaluate.logcodec`): a header line, then each line without the fields that
follow from the others (the episode seeds, counters, flags and copies; lossless, checked when
written), a quarter smaller compressed; :func:`log_text` gives the full lines back and every
reader sees the full records. A schema-4 log written before xz (``<out>.jsonl.gz``, gzip, named
so by its JSON's ``episodes_file``) is still read. :func:`log_text` reads every form (xz, gzip,
plain), with a cap on the decompressed size (:data:`cdr_bench.checks.MAX_EPISODE_LOG_BYTES`).

Results of schema 3 (a plain ``.jsonl`` log without decisions; the archived runs under
``sweeps/landed/``) are still read, metrics computed the same way; they cannot be replayed, and
a leaderboard entry must be schema 4.

The two are one result: the JSON carries the SHA-256 of the uncompressed log as stored
(``episodes_sha256``, ``xz -dc <out>.jsonl.xz | sha256sum``; of the text, so that another
compressor's bytes do not matter; a log written before the stored form, plain lines, is its
own stored form) and every
reader (:func:`read_result`, hence ``report``, ``compare`` and the leaderboard) refuses a pair
that does not match, e.g. a new log beside an old JSON after a disk filled up between the two
renames.

``<out>.partial.jsonl`` (only while a run is unfinished): a header line with the ``run_key``,
then one line per finished batch (appended and fsync'ed); a torn last line is ignored. Every
batch line carries a MAC (HMAC-SHA256 over the run key and the batch's content) keyed by a
random per-run secret that is not in the file: :func:`resume_key_path`, a 0600 file in the
user's cache folder (``$XDG_CACHE_HOME/cdr-bench/resume-keys``, else
``~/.cache/cdr-bench/resume-keys``, a 0700 folder), named after the checkpoint's absolute path,
written when the run starts and removed when it finishes. ``--resume`` validates each line (MAC,
scenario, batch index, episode numbers and seeds): an edited, forged or foreign line is an
error, never merged. So only a process that can read the user's cache folder can forge a line:
a confined agent cannot (the sandbox shows no home folder); an agent run without
``--sandbox`` runs as the user and can. A checkpoint moved to another path, user or machine
cannot be resumed (its key is not there): run again without ``--resume``.
"""

from __future__ import annotations

import copy
import gzip
import hashlib
import hmac
import io
import json
import lzma
import os
import platform
import tempfile
import zlib
from collections.abc import Callable, Iterable
from importlib import metadata
from pathlib import Path
from typing import Any

from cdr_bench.checks import MAX_EPISODE_LOG_BYTES, MAX_RESULT_BYTES, file_kind, read_input
from cdr_bench.errors import UserError
from cdr_bench.evaluate import logcodec

SCHEMA_VERSION = 4
LOG_SUFFIX = ".jsonl.xz"
"""The compressed form of a JSON-lines log (:func:`compress_log`)."""
EPISODES_SUFFIX = LOG_SUFFIX
LEGACY_EPISODES_SUFFIX = ".jsonl.gz"
"""Per-episode logs of schema 4 written before xz (gzip): still read."""
XZ_FILTERS: list[dict[str, int]] = [{"id": lzma.FILTER_LZMA2, "preset": 9 | lzma.PRESET_EXTREME}]
RESULT_KIND = "cdr-bench evaluation"


def canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("cdr-bench", "numpy", "gymnasium", "pettingzoo", "pyyaml"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:  # pragma: no cover - optional
            out[dist] = "not installed"
    return out


def episodes_path(out: Path) -> Path:
    return out.with_suffix(EPISODES_SUFFIX)


def partial_path(out: Path) -> Path:
    return out.with_suffix(".partial.jsonl")


def check_output_path(path: str | os.PathLike[str], flag: str = "--out") -> Path:
    """``path`` as a file a command may write, checked before the command does its work: a
    regular file or nothing yet (a folder, a device such as ``/dev/full``, a named pipe or a
    socket is refused: the writer would replace it), and its nearest existing folder writable
    (a :class:`UserError` naming ``flag`` otherwise). Nothing is created; the writer makes the
    missing folders. Every command that writes a file calls this first."""
    p = Path(path)
    try:
        st = p.stat()
    except (FileNotFoundError, NotADirectoryError):
        st = None  # nothing there yet (a file in the way of a folder: below)
    except OSError as e:
        raise UserError(f"{flag} {path}: {e.strerror or e}") from None
    if st is not None:
        kind = file_kind(st.st_mode)
        if kind == "a folder":
            raise UserError(f"{flag} {path}: is a folder; expected a file path")
        if kind is not None:
            raise UserError(f"{flag} {path}: is {kind}, not a regular file; expected a file path")
    parent = p.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise UserError(f"{flag} {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UserError(f"{flag} {path}: {parent} is not writable")
    return p


def _refuse_non_regular(path: Path) -> None:
    """A :class:`UserError` if something other than a regular file is at ``path`` (following
    a symbolic link): :func:`atomic_write_text` never replaces a device, pipe or folder."""
    try:
        st = path.stat()
    except OSError:
        return  # nothing there (or unreadable: the write says so)
    kind = file_kind(st.st_mode)
    if kind is not None:
        raise UserError(f"{path}: is {kind}, not a regular file; refusing to replace it")


def compress_log(text: str) -> bytes:
    """``text`` (UTF-8) as xz with a fixed filter chain (:data:`XZ_FILTERS`, CRC-64 check): the
    same text gives the same bytes with the same liblzma. Every log the package writes
    compressed goes through here (per-episode logs, shipped training logs); :func:`log_text`
    reads them back."""
    return lzma.compress(
        text.encode("utf-8"), format=lzma.FORMAT_XZ, check=lzma.CHECK_CRC64, filters=XZ_FILTERS
    )


class _TooLarge(Exception):
    """Raised by the decompressors below past their limit."""


def _xz_decompress(data: bytes, limit: int) -> bytes:
    """The single xz stream ``data`` decompressed, stopped (``_TooLarge``) past ``limit`` bytes
    so that a small file cannot expand without bound."""
    dec = lzma.LZMADecompressor(format=lzma.FORMAT_XZ)
    out = bytearray(dec.decompress(data, max_length=limit + 1))
    while len(out) <= limit and not dec.eof and not dec.needs_input:
        out += dec.decompress(b"", max_length=limit + 1 - len(out))
    if len(out) > limit:
        raise _TooLarge
    if not dec.eof:
        raise EOFError("truncated xz stream")
    if dec.unused_data:
        raise lzma.LZMAError("data after the end of the xz stream")
    return bytes(out)


def _gzip_decompress(data: bytes, limit: int) -> bytes:
    with gzip.GzipFile(fileobj=io.BytesIO(data), mode="rb") as f:
        out = f.read(limit + 1)
    if len(out) > limit:
        raise _TooLarge
    return out


def log_text(
    path: str | os.PathLike[str], what: str = "per-episode log", limit: int = MAX_EPISODE_LOG_BYTES
) -> str:
    """The text of a JSON-lines log: xz (``X.jsonl.xz``, :func:`compress_log`), gzip
    (``X.jsonl.gz``, the per-episode logs written before xz) or plain (any other name), a
    per-episode log's stored form expanded (:func:`cdr_bench.evaluate.logcodec.decode`); at
    most ``limit`` bytes of text, compressed or not. ``ValueError`` naming the file otherwise
    (missing, not a regular file, damaged, too large, not UTF-8)."""
    p = Path(path)
    try:
        return logcodec.decode(stored_text(p, what, limit), limit)
    except ValueError as e:
        if str(e).startswith(str(p)):
            raise
        raise ValueError(f"{p}: {e}") from None


def stored_text(
    path: str | os.PathLike[str], what: str = "per-episode log", limit: int = MAX_EPISODE_LOG_BYTES
) -> str:
    """The text a log file holds, decompressed (a per-episode log in its stored form, whose
    SHA-256 its result names: ``xz -dc X.jsonl.xz | sha256sum``); as :func:`log_text`."""
    p = Path(path)
    try:
        raw = read_input(p, limit, what)
    except UserError as e:
        raise ValueError(str(e)) from None
    kind = "an xz" if p.name.endswith(".xz") else "a gzip" if p.name.endswith(".gz") else None
    try:
        if kind == "an xz":
            raw = _xz_decompress(raw, limit)
        elif kind == "a gzip":
            raw = _gzip_decompress(raw, limit)
    except _TooLarge:
        raise ValueError(f"{p}: larger than a {what} may be ({limit} bytes uncompressed)") from None
    except (OSError, EOFError, lzma.LZMAError, zlib.error) as e:
        raise ValueError(f"{p}: not {kind} {what} ({e})") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"{p}: not UTF-8 text ({e})") from None


def atomic_write_text(path: Path, text: str | bytes) -> None:
    """Write ``text`` (or bytes) to ``path`` so that readers see the old file or the new one,
    never a part: temporary file in the same folder, fsync, ``os.replace``. A path that cannot
    be written is a :class:`UserError` naming it, and so is a ``path`` that holds something
    other than a regular file (a device, a pipe, a folder): it is never replaced."""
    _refuse_non_regular(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as e:
        raise UserError(f"{path}: cannot write it ({e.strerror or e})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(text.encode("utf-8") if isinstance(text, str) else text)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; results are ordinary files
        _refuse_non_regular(path)  # again: something may have appeared there meanwhile
        os.replace(tmp, path)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise UserError(f"{path}: cannot write it ({e.strerror or e})") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def jsonl_text(rows: Iterable[dict[str, Any]]) -> str:
    return "".join(json.dumps(r, separators=(",", ":")) + "\n" for r in rows)


def user_cache_dir(name: str) -> Path:
    """The folder ``name`` of cdr-bench's cache in the user's cache folder:
    ``$XDG_CACHE_HOME/cdr-bench/<name>``, else ``~/.cache/cdr-bench/<name>`` (not created)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "cdr-bench" / name


def resume_key_path(partial: Path) -> Path:
    """Where the secret key of the checkpoint ``partial`` lives (module docstring)."""
    name = hashlib.sha256(str(partial.resolve()).encode()).hexdigest()[:40]
    return user_cache_dir("resume-keys") / f"{name}.key"


def batch_mac(key: bytes, run_key: str, batch: dict[str, Any]) -> str:
    """The MAC a partial-log line carries: HMAC-SHA256, keyed by the run's secret ``key``, of the
    run key and the batch's content."""
    body = {k: v for k, v in batch.items() if k not in ("kind", "mac", "digest")}
    return hmac.new(key, (run_key + "\n" + canonical(body)).encode(), hashlib.sha256).hexdigest()


class PartialLog:
    """The append-only checkpoint of an unfinished run (module docstring: the MAC and its key)."""

    def __init__(self, path: Path, run_key: str):
        self.path = path
        self.run_key = run_key
        self._key: bytes | None = None

    def _new_key(self) -> None:
        kp = resume_key_path(self.path)
        try:
            kp.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            os.chmod(kp.parent, 0o700)
            key = os.urandom(32)
            tmp = kp.with_name(f".{kp.name}.{os.getpid()}.tmp")
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
            with os.fdopen(fd, "wb") as f:
                f.write(key)
            os.replace(tmp, kp)
        except OSError as e:
            raise UserError(f"{kp}: cannot write the checkpoint's key ({e})") from None
        self._key = key

    def _load_key(self) -> bytes:
        kp = resume_key_path(self.path)
        try:
            key = kp.read_bytes()
        except OSError:
            key = b""
        if len(key) != 32:
            raise ValueError(
                f"{self.path}: its key {kp} is missing (the checkpoint was written by another "
                "user, on another machine or at another path, or forged); delete it or run "
                "without --resume"
            )
        return key

    def load(
        self, check: Callable[[dict[str, Any]], str | None] | None = None
    ) -> dict[tuple[str, int], dict[str, Any]]:
        """Finished batches keyed by (scenario id, batch index). Raises ``ValueError`` if the
        file belongs to another run, is not a partial log, has no key, or holds a line that
        is not a batch this run wrote (bad MAC, or ``check(batch)`` returns a reason)."""
        done: dict[tuple[str, int], dict[str, Any]] = {}
        if not self.path.exists():
            return done
        if not self.path.is_file():
            raise ValueError(
                f"{self.path}: the checkpoint is not a file; delete it or run without --resume"
            )
        try:
            with open(self.path, "rb") as f:
                lines = f.read().decode("utf-8").split("\n")
        except (OSError, UnicodeDecodeError) as e:
            raise ValueError(f"{self.path}: unreadable checkpoint ({e}); delete it") from None
        key = self._load_key()
        good_bytes = 0
        for i, line in enumerate(lines):
            if not line:
                continue
            try:
                row = json.loads(line)
            except (json.JSONDecodeError, RecursionError):
                if i == len(lines) - 1 or all(not x for x in lines[i + 1 :]):
                    break  # torn last line of a killed run
                raise ValueError(f"{self.path}:{i + 1}: not a JSON line; delete the file") from None
            if i == 0:
                if (
                    not isinstance(row, dict)
                    or row.get("kind") != "header"
                    or row.get("run_key") != self.run_key
                ):
                    raise ValueError(
                        f"{self.path} belongs to a different run (other agent files, scenarios, "
                        "seed, episodes or batch size); delete it or run without --resume"
                    )
            else:
                where = f"{self.path}:{i + 1}"
                if not isinstance(row, dict) or row.get("kind") != "batch":
                    raise ValueError(f"{where}: not a batch line of this run; delete the file")
                mac = row.get("mac")
                if not isinstance(mac, str) or not hmac.compare_digest(
                    mac, batch_mac(key, self.run_key, row)
                ):
                    raise ValueError(
                        f"{where}: the batch line was changed after it was written, or not "
                        "written by this run (its MAC does not match); delete the file and run "
                        "again"
                    )
                why = check(row) if check is not None else None
                if why:
                    raise ValueError(f"{where}: {why}; delete the file and run again")
                done[(row["scenario"], int(row["batch"]))] = row
            good_bytes += len(line.encode()) + 1
        with open(self.path, "r+b") as f:  # drop a torn tail so appends start on a new line
            f.truncate(good_bytes)
        self._key = key
        return done

    def start(self, header: dict[str, Any]) -> None:
        """Begin a new checkpoint, with a new key."""
        self._new_key()
        atomic_write_text(self.path, json.dumps({"kind": "header", **header}) + "\n")

    def append(self, batch: dict[str, Any]) -> None:
        if self._key is None:
            self._key = self._load_key()
        row = {"kind": "batch", **batch, "mac": batch_mac(self._key, self.run_key, batch)}
        line = json.dumps(row, separators=(",", ":")) + "\n"
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)
        resume_key_path(self.path).unlink(missing_ok=True)


COMPUTED_KEYS = ("metrics", "system_metrics")
"""What :func:`read_result` computes into each scenario from the per-episode log (never
written): the metrics per role and, where an episode has several controlled aircraft, the
system metrics."""


def strip_metrics(result: dict[str, Any]) -> dict[str, Any]:
    """``result`` without what :func:`read_result` computes (each scenario's ``metrics`` and
    ``system_metrics``)."""
    return {
        **result,
        "scenarios": [
            {k: v for k, v in s.items() if k not in COMPUTED_KEYS}
            for s in result.get("scenarios", [])
        ],
    }


def write_results(out: Path, result: dict[str, Any], episodes: list[dict[str, Any]]) -> None:
    """The per-episode log first (xz of its stored form, :func:`compress_log`), then the JSON
    that names it and carries the SHA-256 of that text (both atomic); readers refuse a pair
    whose hashes differ. Metrics are not written: they are computed when the result is read."""
    seeds = {
        str(s["id"]): (int(result["base_seed"]), str(s["config_hash"]))
        for s in result.get("scenarios", [])
        if isinstance(s, dict) and "id" in s and "config_hash" in s and "base_seed" in result
    }
    stored = logcodec.encode(jsonl_text(episodes), seeds)
    result = {**strip_metrics(result), "episodes_sha256": sha256_text(stored)}
    atomic_write_text(episodes_path(out), compress_log(stored))
    atomic_write_text(out, json.dumps(result, indent=1) + "\n")


_EPISODES_CACHE: dict[tuple[str, str], list[dict[str, Any]]] = {}


def _parse_episodes(path: Path, stored: str, digest: str) -> list[dict[str, Any]]:
    key = (str(path.resolve()), digest)
    eps = _EPISODES_CACHE.get(key)
    if eps is None:
        try:
            eps = logcodec.records(stored)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
        if len(_EPISODES_CACHE) >= 4:
            _EPISODES_CACHE.pop(next(iter(_EPISODES_CACHE)))
        _EPISODES_CACHE[key] = eps
    return eps


def add_metrics(
    result: dict[str, Any], episodes: list[dict[str, Any]], roles: bool = True
) -> dict[str, Any]:
    """``result`` with each scenario's ``metrics`` (and, where an episode has several
    controlled aircraft, ``system_metrics``) computed from its per-episode records;
    ``roles=False``: the system metrics only (what the leaderboard's multi-agent track shows;
    the per-role means of thousands of flights are the costly part)."""
    from cdr_bench.evaluate.metrics import scenario_metrics, system_metrics

    by_id: dict[str, list[dict[str, Any]]] = {}
    for e in episodes:
        by_id.setdefault(e.get("scenario"), []).append(e)  # type: ignore[arg-type]
    for s in result.get("scenarios", []):
        eps = by_id.get(s.get("id"), [])
        if roles:
            s["metrics"] = scenario_metrics(eps)
        system = system_metrics(eps)
        if system is not None:
            s["system_metrics"] = system
        else:
            s.pop("system_metrics", None)
    return result


def read_result(
    path: str | os.PathLike[str], metrics: bool = True, roles: bool = True
) -> dict[str, Any]:
    """A result JSON, checked for kind and schema version, and against its per-episode log
    (present, same SHA-256), with each scenario's ``metrics`` computed from the log (unless
    ``metrics`` is false; ``roles=False``: the system metrics only, :func:`add_metrics`);
    ``ValueError`` naming the file otherwise."""
    p = Path(path)
    try:
        data = json.loads(read_input(p, MAX_RESULT_BYTES, "result file").decode("utf-8"))
    except UserError as e:  # missing, a folder, a device or pipe, too large, unreadable
        raise ValueError(str(e)) from None
    except UnicodeDecodeError as e:
        raise ValueError(f"{p}: unreadable ({e})") from None
    except (json.JSONDecodeError, RecursionError) as e:
        raise ValueError(f"{p}: not a JSON result file ({str(e)[:80]})") from None
    if not isinstance(data, dict) or data.get("kind") != RESULT_KIND:
        raise ValueError(f"{p}: not a cdr-bench evaluation result")
    legacy = data.get("schema_version") == 3  # archived runs: read, never replayable
    if data.get("schema_version") != SCHEMA_VERSION and not legacy:
        raise ValueError(
            f"{p}: schema_version {str(data.get('schema_version'))[:20]!r}, this cdr-bench reads "
            f"{SCHEMA_VERSION} (re-run the evaluation)"
        )
    name = data.get("episodes_file")
    if (
        not isinstance(name, str)
        or "/" in name
        or "\\" in name
        or not name.endswith((".jsonl",) if legacy else (EPISODES_SUFFIX, LEGACY_EPISODES_SUFFIX))
    ):
        raise ValueError(
            f"{p}: episodes_file: expected a {'.jsonl' if legacy else EPISODES_SUFFIX} file name "
            "beside the result"
        )
    ep = p.parent / name
    if not ep.is_file():
        raise ValueError(f"{p}: its per-episode file {ep} is missing")
    log = stored_text(ep)
    digest = sha256_text(log)
    if digest != data.get("episodes_sha256"):
        raise ValueError(
            f"{p}: its per-episode file {ep.name} does not match it (episodes_sha256 differs: "
            "an interrupted write or an edit); re-run the evaluation"
        )
    if not isinstance(data.get("scenarios"), list):
        raise ValueError(f"{p}: scenarios: expected a list")
    stored = [
        s.get("id")
        for s in data["scenarios"]
        if isinstance(s, dict) and any(k in s for k in COMPUTED_KEYS)
    ]
    if stored and not legacy:  # schema 3 stored them; they are recomputed below all the same
        raise ValueError(
            f"{p}: scenario {str(stored[0])[:60]} carries stored metrics, which a result of "
            f"schema {SCHEMA_VERSION} never holds (they are computed from the per-episode log "
            "when read): an edited file; re-run the evaluation"
        )
    if not metrics:
        return data
    from cdr_bench.evaluate.metrics import registry_generation

    key = (digest, roles, registry_generation(), tuple(str(s.get("id")) for s in data["scenarios"]))
    computed = _METRICS_CACHE.get(key)
    if computed is None:
        add_metrics(data, _parse_episodes(ep, log, digest), roles)
        computed = [
            {k: s[k] for k in ("metrics", "system_metrics") if k in s} for s in data["scenarios"]
        ]
        if len(_METRICS_CACHE) >= 1024:
            _METRICS_CACHE.pop(next(iter(_METRICS_CACHE)))
        _METRICS_CACHE[key] = copy.deepcopy(computed)
        return data
    for s, c in zip(data["scenarios"], computed, strict=True):
        s.pop("system_metrics", None)  # as add_metrics: only where computed
        s.update(copy.deepcopy(c))
    return data


_METRICS_CACHE: dict[tuple[str, bool, int, tuple[str, ...]], list[dict[str, Any]]] = {}
"""Metrics computed by :func:`read_result`, by the SHA-256 of the per-episode log they come from
(the scenarios they are grouped by, the metric registry's generation): a function of the
log's text and the metric definitions, so a process that reads
the same result twice (the leaderboard's pages, then its docs blocks) computes them once."""


def read_episodes(result_path: str | os.PathLike[str], result: dict[str, Any]) -> list[dict]:
    """The per-episode records beside a result JSON (checked by :func:`read_result`)."""
    p = Path(result_path).parent / result["episodes_file"]
    if not p.exists():
        raise ValueError(f"{p}: per-episode file of {result_path} is missing")
    digest = str(result.get("episodes_sha256"))
    cached = _EPISODES_CACHE.get((str(p.resolve()), digest))
    if cached is not None:
        return cached
    stored = stored_text(p)
    return _parse_episodes(p, stored, sha256_text(stored))
