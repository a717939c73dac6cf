"""The paper's data-efficiency measure, best-so-far (sb3_denfac.common.performance), computed in one place."""

import numpy as np

from sb3_denfac.common.performance import best_so_far


def test_best_so_far_follows_the_direction_of_the_measure():
    values = np.array([500.0, 320.0, 410.0, 150.0])
    np.testing.assert_array_equal(best_so_far(values, lower_is_better=True), [500, 320, 320, 150])
    np.testing.assert_array_equal(best_so_far(-values, lower_is_better=False), [-500, -320, -320, -150])


def test_best_so_far_skips_episodes_without_the_measure():
    values = [np.nan, 3.0, np.nan, 1.0, 5.0]
    np.testing.assert_array_equal(best_so_far(values, lower_is_better=False), [np.nan, 3, 3, 3, 5])
    np.testing.assert_array_equal(best_so_far(values, lower_is_better=True), [np.nan, 3, 3, 1, 1])
