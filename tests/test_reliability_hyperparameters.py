"""Invalid hyperparameters of the package's algorithms are refused at construction with a message naming them."""

from __future__ import annotations

import pytest

INVALID = {
    "denfac": [
        (dict(n_fitted_iterations=0), "n_fitted_iterations"),
        (dict(critic_steps=0), "critic_steps"),
        (dict(weighting="importance"), "weighting"),
        (dict(sigma=0.0), "sigma"),
        (dict(buffer_size=10), "buffer_size"),  # half an episode of the tiny env (20 steps)
        (dict(batch_size=1), "batch_size"),
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(actor_learning_rate=0.0), "actor_learning_rate"),
        (dict(gamma=1.5), "gamma"),
        (dict(prioritized="td"), "prioritized"),
        (dict(prioritized="critic", batch_size=None), "prioritized"),
        (dict(prioritized=dict(on="critic", alpha=-1.0)), "prioritized alpha"),
        (dict(prioritized=dict(on="critic", beta=2.0)), "prioritized beta"),
        (dict(prioritized=dict(on="critic", eps=0.0)), "prioritized eps"),
        (dict(actor_proximal=-0.1), "actor_proximal"),
    ],
    "ddpg": [
        (dict(tau=0.0), "tau"),
        (dict(actor_learning_rate=-1.0), "actor_learning_rate"),
        (dict(batch_size=1), "batch_size"),
        (dict(sigma=-0.1), "sigma"),
        (dict(gradient_steps=-2), "gradient_steps"),  # 0 (collect only) and -1 (one per env step) are valid
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(gamma=1.5), "gamma"),
    ],
    "nfac": [
        (dict(n_episodes=0), "n_episodes"),
        (dict(n_fitted_iterations=0), "n_fitted_iterations"),
        (dict(critic_steps=0), "critic_steps"),
        (dict(actor_steps=0), "actor_steps"),
        (dict(sigma=0.0), "sigma"),
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(critic_learning_rate=0.0), "critic_learning_rate"),
        (dict(gamma=1.5), "gamma"),
    ],
    "cacla": [
        (dict(n_steps=0), "n_steps"),
        (dict(bn_window=1), "bn_window"),
        (dict(sigma=0.0), "sigma"),
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(gamma=1.5), "gamma"),
    ],
    "cmaes": [
        (dict(population_size=1), "population_size"),
        (dict(sigma0=0.0), "sigma0"),
        (dict(n_eval_episodes=0), "n_eval_episodes"),
        (dict(sigma=-0.1), "sigma"),
        (dict(incumbent="last"), "incumbent"),
    ],
}
INVALID_CASES = [(name, kwargs, match) for name, cases in INVALID.items() for kwargs, match in cases]


@pytest.mark.parametrize(("name", "kwargs", "match"), INVALID_CASES, ids=[f"{n}-{next(iter(k))}" for n, k, _ in INVALID_CASES])
def test_invalid_hyperparameters(name: str, kwargs: dict, match: str, make_model) -> None:
    with pytest.raises(ValueError, match=match):
        make_model(name, **kwargs)


@pytest.mark.algorithms("all")
def test_invalid_policy_kwargs(name: str, make_model) -> None:
    with pytest.raises(ValueError, match="init"):
        make_model(name, policy_kwargs=dict(init="xavier"))
    with pytest.raises(ValueError, match="hidden layer sizes"):
        make_model(name, policy_kwargs=dict(net_arch=[0]))
