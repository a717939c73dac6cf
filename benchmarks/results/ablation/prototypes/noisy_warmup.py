"""Prototype, not in the library (ablation README, section 18): sections 13 and 14 together, SAC's two exploration-side
ingredients in the 0.5 default DENFAC.

- the noise-robust actor of ``noisy_actor.py``: each actor step ascends E_eps Q(s, pi(s) + eps), eps ~ N(0, AN_SIGMA^2),
  as SAC's actor maximises E_{a ~ pi} Q(s, a);
- the uniform first episode of ``warmup_episode.py``: the first ``WARMUP_EPISODES`` episodes play uniform actions, as
  SB3's ``learning_starts``, counted in episodes.

Both patches are imported from their own files (one place each). Runs ``benchmarks.run`` in this process (use
``--workers 0``); ``noisy_warmup/`` holds its runs.

Usage: ``python noisy_warmup.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/noisy_warmup``
"""

import importlib.util
import sys
from pathlib import Path

from benchmarks import run
from sb3_denfac.common.exploration import TruncatedGaussianExplorationMixin
from sb3_denfac.denfac.eager_steps import EvalCritic


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


if __name__ == "__main__":
    EvalCritic.action_gradient = _load("noisy_actor").action_gradient
    TruncatedGaussianExplorationMixin._sample_action = _load("warmup_episode").sample_action
    sys.exit(run.main(sys.argv[1:]))
