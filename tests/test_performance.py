"""The paper's data-efficiency measure, best-so-far (sb3_denfac.common.performance), computed in one place."""

import numpy as np

from sb3_denfac.common.performance import best_so_far


def test_best_so_far_follows_the_direction_of_the_measure():
    values = np.array([500.0, 320.0, 410.0, 150.0])
    # exact: a running minimum or maximum selects given values, it computes none
    np.testing.assert_array_equal(best_so_far(values, lower_is_better=True), [500, 320, 320, 150])
    np.testing.assert_array_equal(best_so_far(-values, lower_is_better=False), [-500, -320, -320, -150])


def test_best_so_far_skips_episodes_without_the_measure():
    values = [np.nan, 3.0, np.nan, 1.0, 5.0]
    # exact: a running minimum or maximum selects given values, it computes none
    np.testing.assert_array_equal(best_so_far(values, lower_is_better=False), [np.nan, 3, 3, 3, 5])
    np.testing.assert_array_equal(best_so_far(values, lower_is_better=True), [np.nan, 3, 3, 1, 1])


def test_fall_back_fraction_counts_relapses_after_the_first_success():
    from sb3_denfac.common.performance import fall_back_fraction

    # returns, higher is better, worst -1000: success (>= -500) first at episode 2; after it, -900 is below half of
    # the best so far measured from -1000 (-300: halfway is -650), -400 and -200 are not
    returns = np.array([-1000.0, -800.0, -300.0, -900.0, -400.0, -200.0])
    reached = returns >= -500
    assert fall_back_fraction(returns, False, reached, worst=-1000.0) == 1 / 3
    # steps to a goal, lower is better, worst 500: first success at episode 1 (120 steps); 480 falls back, 200 does not
    steps = np.array([500.0, 120.0, 480.0, 200.0])
    assert fall_back_fraction(steps, True, steps < 500, worst=500.0) == 0.5
    assert np.isnan(fall_back_fraction(steps, True, np.zeros(4, bool)))  # never reached
    assert np.isnan(fall_back_fraction(steps, True, [False, False, False, True]))  # reached at the last episode only
