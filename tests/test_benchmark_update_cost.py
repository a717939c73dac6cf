"""The update-cost benchmark's arithmetic floor describes the update it is compared with."""

import gymnasium as gym
import pytest
from torch.utils.flop_counter import FlopCounterMode

from benchmarks.studies import update_cost
from sb3_denfac import DENFAC


@pytest.fixture(scope="module")
def acrobot_model():
    settings = update_cost.yaml_settings(update_cost.ENVS["acrobot"])
    model = DENFAC("MlpPolicy", gym.make(update_cost.ENVS["acrobot"]), seed=0, learning_starts=10**9, **settings)
    model.n_fitted_iterations = 1
    model.learn(300)  # 300 real transitions in D
    return model


def test_floor_counts_the_fast_updates_matrix_products(acrobot_model):
    """The floor's FLOPs are those of the products the fast updater runs, within the rank-1 ones it broadcasts."""
    assert type(acrobot_model.make_updater()).__name__ == "FastUpdater"  # what "auto" picks here
    with FlopCounterMode(display=False) as counter:
        acrobot_model._update()
    counted = update_cost.matmul_flops(update_cost.update_matmuls(acrobot_model))
    # rel 0.06: FLOP counts, not float results: the rank-1 products the fast updater broadcasts are not in the floor
    assert counter.get_total_flops() == pytest.approx(counted, rel=0.06)


def test_gemm_replay_runs_exactly_the_counted_products(acrobot_model):
    shapes = update_cost.update_matmuls(acrobot_model)
    with FlopCounterMode(display=False) as counter:
        update_cost.matmul_replay(shapes)()
    assert counter.get_total_flops() == update_cost.matmul_flops(shapes)
