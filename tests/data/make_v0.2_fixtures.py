"""Write the v0.2 fixtures of tests/test_saved_models.py: one small model per algorithm, saved by the code of the
checkout this runs in, plus its state-dict keys and deterministic actions on fixed observations.

Run on the 0.2 code (commit dedb04a) as ``PYTHONPATH=<checkout of dedb04a> python tests/data/make_v0.2_fixtures.py DIR``.
"""

import json
import sys

import numpy as np
import torch as th

from sb3_denfac import CACLA, CMAES, DDPG, DENFAC, NFAC

th.set_num_threads(1)
out = sys.argv[1]
rng = np.random.default_rng(0)
obs = rng.uniform(-1, 1, size=(8, 3)).astype(np.float32)
obs = np.stack([np.cos(obs[:, 0] * 3), np.sin(obs[:, 0] * 3), obs[:, 2] * 8], axis=1).astype(np.float32)
kw = dict(policy_kwargs=dict(net_arch=[8]))
fit = dict(n_fitted_iterations=1, critic_steps=2, actor_steps=2)
models = {
    "denfac": DENFAC(
        "MlpPolicy",
        "Pendulum-v1",
        seed=0,
        buffer_size=1000,
        batch_size=64,
        **fit,
        policy_kwargs={**kw["policy_kwargs"], "batch_norm": True},
    ),
    "ddpg": DDPG("MlpPolicy", "Pendulum-v1", seed=0, learning_starts=50, batch_size=32, actor_learning_rate=2e-3, **kw),
    "nfac": NFAC("MlpPolicy", "Pendulum-v1", seed=0, **fit, critic_learning_rate=2e-3, **kw),
    "cacla": CACLA("MlpPolicy", "Pendulum-v1", seed=0, n_steps=50, critic_learning_rate=2e-3, **kw),
    "cmaes": CMAES("MlpPolicy", "Pendulum-v1", seed=0, population_size=4, **kw),
}
meta = {}
for name, model in models.items():
    model.learn(400)
    model.save(f"{out}/{name}_v0.2_pendulum.zip")
    actions, _ = model.predict(obs, deterministic=True)
    meta[name] = dict(keys=sorted(model.policy.state_dict().keys()), actions=actions.tolist())
meta["obs"] = obs.tolist()
with open(f"{out}/v0.2_pendulum_expected.json", "w") as file:
    json.dump(meta, file, indent=1)
