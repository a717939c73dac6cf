"""The paper's data-efficiency measure (Section 4, Figure 3): the best performance registered since the first episode."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def best_so_far(values: Sequence[float] | np.ndarray, lower_is_better: bool) -> np.ndarray:
    """Per episode, the best of ``values`` up to it: the running min if ``lower_is_better`` (Acrobot's steps to the goal,
    see :attr:`sb3_denfac.envs.facts.EnvFacts.lower_is_better`), else the running max. NaN values (episodes without
    the measure) are skipped; the result is NaN only until the first number."""
    values = np.asarray(values, dtype=np.float64)
    return np.fmin.accumulate(values) if lower_is_better else np.fmax.accumulate(values)
