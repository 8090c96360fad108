"""``--device auto|cpu|cuda`` of every trainer: where the networks, their random generators and
the updates live. Collection (the batched simulator, the replay) stays on the host; the learner
copies each observation batch and replay batch to the device.

On the CPU the networks use the compiled kernels of :mod:`cdr_bench.rl.kernels` (the tested,
deterministic default); on any other device the same functions in tensor operations
(:func:`cdr_bench.rl.networks.compiled` picks; tests/rl/test_device.py runs both on the CPU and
compares them).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cdr_bench.errors import UserError

if TYPE_CHECKING:
    import torch

DEVICES = ("auto", "cpu", "cuda")
"""What ``--device`` accepts (``auto``: cuda if torch sees a CUDA device, else cpu)."""


def available() -> list[str]:
    """The devices this process can train on, e.g. ``["cpu", "cuda (NVIDIA H100, 1 device)"]``."""
    import torch

    found = ["cpu"]
    if torch.cuda.is_available():
        n = torch.cuda.device_count()
        found.append(f"cuda ({torch.cuda.get_device_name(0)}, {n} device{'s' * (n > 1)})")
    return found


def resolve_device(name: str) -> torch.device:
    """The ``torch.device`` of ``--device NAME``; a :class:`UserError` naming what was asked
    and what is available when it is not a choice or CUDA is asked for and absent."""
    import torch

    if name not in DEVICES:
        raise UserError(f"--device {name!r}: must be one of {', '.join(DEVICES)}")
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        build = f"CUDA {torch.version.cuda}" if torch.version.cuda else "without CUDA"
        raise UserError(
            f"--device cuda: no CUDA device is available (torch {torch.__version__}, built "
            f"{build}); available: {', '.join(available())}. Use --device cpu or auto"
        )
    return torch.device(name)
