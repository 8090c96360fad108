"""``python -m cdr_bench.leaderboard.safeload CHECKPOINT``: open a checkpoint with a loader
that cannot run code (run sandboxed before a submission is evaluated).

* ``.pt`` / ``.pth``: :func:`cdr_bench.weights.read_checkpoint` (plain tensors in dicts, lists
  and tuples, read without torch), else ``torch.load(weights_only=True)`` (tensors, containers
  and plain values only; anything else raises ``UnpicklingError``): what the first reads, the
  second reads too;
* ``.npz``: ``numpy.load(allow_pickle=False)`` of every array;
* ``.safetensors``: the JSON header is parsed and every tensor's byte range checked.

Exit code 0 and one line on success; exit code 2 and the reason otherwise.
"""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path


def check(path: Path) -> str:
    suffix = path.suffix
    if suffix in (".pt", ".pth"):
        from cdr_bench.weights import UnsupportedCheckpoint, read_checkpoint

        try:
            obj = read_checkpoint(path)
            return f"{path.name}: weights-only read ok without torch ({type(obj).__name__})"
        except UnsupportedCheckpoint:
            import torch

            obj = torch.load(path, map_location="cpu", weights_only=True)
            return f"{path.name}: torch weights-only load ok ({type(obj).__name__})"
    if suffix == ".npz":
        import numpy as np

        with np.load(path, allow_pickle=False) as z:
            n = sum(int(z[k].size) for k in z.files)
        return f"{path.name}: {n} values in {len(z.files)} arrays, no pickled objects"
    if suffix == ".safetensors":
        data = path.read_bytes()
        (n,) = struct.unpack("<Q", data[:8])
        header = json.loads(data[8 : 8 + n])
        body = len(data) - 8 - n
        for name, spec in header.items():
            if name == "__metadata__":
                continue
            lo, hi = spec["data_offsets"]
            if not 0 <= lo <= hi <= body:
                raise ValueError(f"tensor {name}: byte range {lo}..{hi} outside the file")
        return f"{path.name}: safetensors header ok ({len(header)} entries)"
    raise ValueError(f"unsupported checkpoint format {suffix!r}")


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m cdr_bench.leaderboard.safeload CHECKPOINT", file=sys.stderr)
        return 2
    path = Path(args[0])
    try:
        print(check(path))
    except Exception as e:  # noqa: BLE001 - every failure is reported as one line
        print(f"{path}: not loadable without unpickling: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
