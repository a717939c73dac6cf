"""The paper's data-efficiency measure (Section 4, Figure 3), the best performance registered since the first episode, and
the stability measure beside it: how often a run falls back after its first success."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def best_so_far(values: Sequence[float] | np.ndarray, lower_is_better: bool) -> np.ndarray:
    """Per episode, the best of ``values`` up to it: the running min if ``lower_is_better`` (Acrobot's steps to the goal,
    see :attr:`sb3_denfac.envs.facts.EnvFacts.lower_is_better`), else the running max. NaN values (episodes without
    the measure) are skipped; the result is NaN only until the first number."""
    values = np.asarray(values, dtype=np.float64)
    return np.fmin.accumulate(values) if lower_is_better else np.fmax.accumulate(values)


def fall_back_fraction(
    values: Sequence[float] | np.ndarray,
    lower_is_better: bool,
    reached: Sequence[bool] | np.ndarray,
    worst: float | None = None,
) -> float:
    """Stability: the fraction of the episodes after the first one that ``reached`` the env's threshold whose
    performance falls back below half of the best so far, halfway measured from ``worst`` (the env's worst value of
    the measure; None: the run's worst episode), so that "half" means the same for negative returns and for steps to
    a goal. NaN if the threshold was never reached or only at the last episode."""
    score = np.asarray(values, dtype=np.float64) * (-1.0 if lower_is_better else 1.0)  # higher is better from here
    hits = np.flatnonzero(np.asarray(reached, dtype=bool))
    if not len(hits) or hits[0] + 1 >= len(score):
        return float("nan")
    low = np.nanmin(score) if worst is None else (-worst if lower_is_better else worst)
    best = np.fmax.accumulate(score)
    after = slice(hits[0] + 1, None)
    return float(np.mean(score[after] - low < 0.5 * (best[after] - low)))
