"""TD3's hybrid adaptation (paper §5.2): its continuous output rounded to an action index.

Pure numpy; imported by the TD3 trainer (:mod:`cdr_bench.rl.train_sb3`) and agents/td3/agent.py.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def continuous_to_index(action: NDArray[np.floating]) -> NDArray[np.int64]:
    """TD3's continuous output (N, 3) in [-1, 1]^3, ordered (a_psi, a_v, a_h), rounded to the
    nearest value of {-1, 0, +1} per component (below -0.5 -> -1, above +0.5 -> +1, else 0;
    +-0.5 itself -> 0), then encoded as the action index 9 (a_psi + 1) + 3 (a_v + 1) + (a_h + 1).

    No mask is applied (the paper's TD3 is unmasked): a climb rounded at the top level (or a
    descent at level 0) is executed without its level change and counted as an invalid action.
    """
    a = np.asarray(action, np.float64).reshape(-1, 3)
    triple = (a > 0.5).astype(np.int64) - (a < -0.5).astype(np.int64)
    return 9 * (triple[:, 0] + 1) + 3 * (triple[:, 1] + 1) + (triple[:, 2] + 1)
