"""The 27 discrete actions: index <-> triple (a_psi, a_v, a_h) in {-1, 0, +1}^3.

The index is ``9 * (a_psi + 1) + 3 * (a_v + 1) + (a_h + 1)``, factors in that order:

* ``a_psi``: heading change in units of ``ownship.heading_step_deg`` (+1 = turn right, clockwise),
* ``a_v``: speed change in units of ``ownship.speed_step_kt``,
* ``a_h``: flight-level change (+1 = climb one level).

So index 0 is (-1, -1, -1) (turn left, slow down, descend), :data:`HOLD` = 13 is (0, 0, 0) and
26 is (+1, +1, +1). Climbing at the top level and descending at level 0 are infeasible and are
masked; see :func:`action_mask`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

N_ACTIONS = 27
"""Number of discrete actions."""

Triple = tuple[int, int, int]

TRIPLES: NDArray[np.int64] = np.array(
    [(p, v, h) for p in (-1, 0, 1) for v in (-1, 0, 1) for h in (-1, 0, 1)], dtype=np.int64
)
"""Row i is the triple (a_psi, a_v, a_h) of action i, shape (27, 3)."""


def encode(triple: Triple) -> int:
    """Index of the triple (a_psi, a_v, a_h), each in {-1, 0, +1}."""
    if len(triple) != 3 or any(int(x) != x or x not in (-1, 0, 1) for x in triple):
        raise ValueError(f"expected a triple of values in {{-1, 0, 1}}, got {triple!r}")
    p, v, h = (int(x) for x in triple)
    return 9 * (p + 1) + 3 * (v + 1) + (h + 1)


def decode(index: int) -> Triple:
    """Triple (a_psi, a_v, a_h) of an action index in 0..26."""
    if isinstance(index, bool) or int(index) != index or not 0 <= int(index) < N_ACTIONS:
        raise ValueError(f"expected an action index in 0..26, got {index!r}")
    p, v, h = TRIPLES[int(index)]
    return int(p), int(v), int(h)


HOLD: int = encode((0, 0, 0))
"""Keep heading, speed and level (index 13)."""

CLIMB = TRIPLES[:, 2] == 1
"""Boolean (27,): actions that climb one level."""
DESCEND = TRIPLES[:, 2] == -1
"""Boolean (27,): actions that descend one level."""


def action_mask(level: NDArray[np.integer] | int, n_levels: int = 3) -> NDArray[np.int8]:
    """Feasibility flags, shape ``level.shape + (27,)``, int8 (1 = feasible).

    Only the level bounds are masked: no climb at the top level, no descent at level 0. The mask
    never depends on separation.
    """
    lv = np.asarray(level)
    if n_levels == 3:  # the common case: a table lookup
        return _MASK_3_LEVELS[lv]
    infeasible = (CLIMB & (lv[..., None] >= n_levels - 1)) | (DESCEND & (lv[..., None] <= 0))
    return (~infeasible).astype(np.int8)


_MASK_3_LEVELS = np.stack(
    [(~((CLIMB & (lv >= 2)) | (DESCEND & (lv <= 0)))).astype(np.int8) for lv in range(3)]
)


def describe(index: int) -> str:
    """Human-readable name, e.g. ``'left/slower/climb'`` or ``'hold'``."""
    p, v, h = decode(index)
    words = [
        {-1: "left", 0: "", 1: "right"}[p],
        {-1: "slower", 0: "", 1: "faster"}[v],
        {-1: "descend", 0: "", 1: "climb"}[h],
    ]
    return "/".join(w for w in words if w) or "hold"
