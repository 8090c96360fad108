"""cdr_bench.weights: torch's weights-only checkpoints read without torch, bit for bit."""

from __future__ import annotations

import pickle
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cdr_bench.weights import UnsupportedCheckpoint, load_weights, read_checkpoint

torch = pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[1]


def _numpy(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _numpy(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_numpy(v) for v in obj)
    if isinstance(obj, torch.Tensor):
        return obj.numpy()
    return obj


def _same(a: Any, b: Any, where: str = "") -> None:
    if isinstance(b, dict):
        assert isinstance(a, dict) and list(a) == list(b), where
        for k in b:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(b, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(b, np.ndarray):
        assert isinstance(a, np.ndarray), where
        assert (a.dtype, a.shape) == (b.dtype, b.shape), where
        assert a.tobytes() == np.ascontiguousarray(b).tobytes(), where
        assert a.flags.c_contiguous and a.flags.writeable, where
    else:
        assert type(a) is type(b) and a == b, where


def test_every_shipped_checkpoint_reads_as_torch_reads_it() -> None:
    files = sorted(ROOT.glob("agents/**/*.pt"))
    assert len(files) >= 20
    for f in files:
        _same(read_checkpoint(f), _numpy(torch.load(f, map_location="cpu", weights_only=True)))


def test_views_dtypes_and_shapes(tmp_path: Path) -> None:
    obj = {
        "columns": torch.arange(24, dtype=torch.float64).reshape(4, 6)[:, 1::2],
        "offset": torch.arange(10)[3:7],
        "transposed": torch.randn(3, 4, generator=torch.Generator().manual_seed(0)).t(),
        "bool": torch.tensor([True, False]),
        "empty": torch.zeros(0, 3),
        "scalar": torch.tensor(3.5),
        "half": torch.linspace(-2, 2, 5).half(),
        "nested": [torch.ones(2, dtype=torch.int8), (1, "x", None, 2.5)],
        "config": {"width": 64, "kind": "ppo", "flag": True},
    }
    torch.save(obj, tmp_path / "w.pt")
    _same(read_checkpoint(tmp_path / "w.pt"), _numpy(obj))


def test_what_it_does_not_read_is_refused_and_torch_reads_it_instead(tmp_path: Path) -> None:
    torch.save({"x": torch.zeros(1).expand(5)}, tmp_path / "repeat.pt")  # stride 0
    with pytest.raises(UnsupportedCheckpoint, match="repeats its values"):
        read_checkpoint(tmp_path / "repeat.pt")
    assert load_weights(tmp_path / "repeat.pt")["x"].tolist() == [0.0] * 5
    torch.save({"x": torch.zeros(2, dtype=torch.bfloat16)}, tmp_path / "bf16.pt")
    with pytest.raises(UnsupportedCheckpoint, match="BFloat16Storage"):
        read_checkpoint(tmp_path / "bf16.pt")
    torch.save(torch.nn.Linear(2, 2), tmp_path / "module.pt")
    with pytest.raises(UnsupportedCheckpoint, match="torch.nn.modules.linear.Linear"):
        read_checkpoint(tmp_path / "module.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a zip")
    with pytest.raises(UnsupportedCheckpoint, match="not a zip"):
        read_checkpoint(tmp_path / "junk.pt")
    with pytest.raises(FileNotFoundError, match="no checkpoint at"):
        load_weights(tmp_path / "missing.pt")


class _Boom:
    def __reduce__(self) -> Any:
        return (subprocess.call, (["touch", "/tmp/cdr-bench-weights-pwned"],))


def test_a_pickle_that_would_run_code_is_refused_unrun(tmp_path: Path) -> None:
    target = Path("/tmp/cdr-bench-weights-pwned")
    target.unlink(missing_ok=True)
    torch.save({"w": torch.ones(2)}, tmp_path / "ok.pt")
    with zipfile.ZipFile(tmp_path / "ok.pt") as z:
        members = {n: z.read(n) for n in z.namelist()}
    pkl = next(n for n in members if n.endswith("/data.pkl"))
    members[pkl] = pickle.dumps({"w": _Boom()}, protocol=2)
    with zipfile.ZipFile(tmp_path / "evil.pt", "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    with pytest.raises(UnsupportedCheckpoint, match=r"\.call in the pickle"):
        read_checkpoint(tmp_path / "evil.pt")
    assert not target.exists()


def test_checkpoint_agents_do_not_import_torch() -> None:
    code = (
        "import sys\n"
        "from cdr_bench.inference import CheckpointActorAgent\n"
        "class A(CheckpointActorAgent):\n"
        "    algorithm = 'ippo'\n"
        "a = A(checkpoint='agents/ippo/checkpoint.pt')\n"
        "print(type(a.net).__name__, 'torch' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.split() == ["MLP", "False"], out.stderr
