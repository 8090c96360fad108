"""An entry's identity is the files it uses: its agent's code, the checkpoint its submission
names and the configuration beside that checkpoint; not its whole folder. Re-training one seed
changes the identity of that run and of no other."""

from __future__ import annotations

from pathlib import Path

from cdr_bench.evaluate.loader import WEIGHT_SUFFIXES, agent_files, agent_identity
from cdr_bench.leaderboard.build import with_seeds
from cdr_bench.leaderboard.published import load_published
from cdr_bench.leaderboard.submission import load_submissions

ROOT = Path(__file__).resolve().parents[2]


def _layout(root: Path) -> dict[str, str | None]:
    """A folder shaped like agents/diffusion_ac: one agent file, a default checkpoint, seeds
    and ablations with seeds, each with its own checkpoint, arguments and log. Returns the runs
    (name -> checkpoint path or None)."""
    (root / "helpers").mkdir(parents=True)
    (root / "agent.py").write_text("class Agent: ...\n")
    (root / "helpers" / "net.py").write_text("W = 1\n")
    runs: dict[str, str | None] = {"default": None}
    for rel in ("", "seeds/2/", "ablations/x/", "ablations/x/seeds/2/", "ablations/y/"):
        d = root / rel
        d.mkdir(parents=True, exist_ok=True)
        (d / "checkpoint.pt").write_bytes(f"weights of {rel or 'main'}".encode())
        (d / "train_args.json").write_text(f'{{"run": "{rel}"}}')
        (d / "training_log.jsonl").write_text("{}\n")
        runs[rel or "main"] = str(d / "checkpoint.pt")
    return runs


def _identities(root: Path, runs: dict[str, str | None]) -> dict[str, str]:
    return {
        name: agent_identity(root / "agent.py", checkpoint=ck)["sha256"]
        for name, ck in runs.items()
    }


def test_retraining_one_ablation_seed_changes_that_run_only(tmp_path: Path) -> None:
    root = tmp_path / "diffusion_ac"
    runs = _layout(root)
    before = _identities(root, runs)
    assert len(set(before.values())) == len(before)  # every run is told apart
    seed = root / "ablations" / "x" / "seeds" / "2"
    (seed / "checkpoint.pt").write_bytes(b"re-trained weights")
    (seed / "train_args.json").write_text('{"run": "again"}')
    (seed / "training_log.jsonl").write_text('{"step": 1}\n')
    after = _identities(root, runs)
    assert {k for k in runs if before[k] != after[k]} == {"ablations/x/seeds/2/"}
    # the code is shared: changing it changes every run
    (root / "helpers" / "net.py").write_text("W = 2\n")
    assert all(v != after[k] for k, v in _identities(root, runs).items())


def test_logs_docs_and_outputs_are_not_identity(tmp_path: Path) -> None:
    root = tmp_path / "a"
    runs = _layout(root)
    before = _identities(root, runs)
    (root / "README.md").write_text("notes")
    (root / "results").mkdir()
    (root / "results" / "x.json").write_text("{}")
    (root / "training_log.jsonl").write_text('{"step": 2}\n')
    assert _identities(root, runs) == before


def test_shipped_runs_hash_only_their_own_weights() -> None:
    """Every leaderboard run (every entry and seed) hashes exactly one weight file, the
    checkpoint its submission names, and no configuration of another run's folder."""
    lb = ROOT / "leaderboard"
    views = with_seeds(load_submissions(lb, load_published(lb).names))
    assert len(views) > 30
    for v in views:
        ck = ROOT / v.checkpoint if v.checkpoint else None
        files = agent_files(ROOT / v.agent, ck)
        weights = [f for f in files if f.name.endswith(WEIGHT_SUFFIXES)]
        assert weights == [], (v.name, weights)  # the named checkpoint is hashed on its own
        if ck is not None:
            configs = [f for f in files if f.suffix != ".py"]
            assert all(f.parent == ck.parent for f in configs), (v.name, configs)
