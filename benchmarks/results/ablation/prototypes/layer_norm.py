"""Prototype, not in the library (ablation README, section 16): layer normalisation in the Q networks.

DENFAC fits its critics with 500 gradient steps at every episode end, whatever the episode's length: on the short
early episodes that is an update-to-data ratio of tens to hundreds. At such ratios Q-learning's values drift away from
the returns off the data (Hussing et al. 2024, "Dissecting deep RL with high update ratios": feature normalisation
removes the divergence), and the DroQ, BRO and SimBa critics normalise every hidden layer (sbx's SAC
``layer_norm=True``). Here each hidden layer of every Q network is Linear -> LayerNorm -> activation (``LN_WHERE=critic``;
``LN_WHERE=both`` adds it to the actor); nothing else changes. The fast updater does not parse LayerNorm, so
``update_path="auto"`` takes the autograd updater (the CPU seconds of these runs are not comparable with the sweep's).
Runs ``benchmarks.run`` in this process with the patch (use ``--workers 0``); ``layer_norm/`` holds its runs.

Usage: ``python layer_norm.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/layer_norm``
"""

import os
import sys

from torch import nn

from benchmarks import run
from sb3_denfac.common import actor, networks
from sb3_denfac.denfac import policies

WHERE = os.environ.get("LN_WHERE", "critic")
if WHERE not in ("critic", "both"):
    raise ValueError(f"LN_WHERE must be 'critic' or 'both', not {WHERE!r}")
_create = networks.create_bn_mlp


def create_ln_mlp(*args, **kwargs) -> nn.Sequential:
    """``create_bn_mlp`` with a LayerNorm after every hidden Linear layer (before its activation)."""
    net = _create(*args, **kwargs)
    layers: list[nn.Module] = []
    linears = [m for m in net if isinstance(m, nn.Linear)]
    for module in net:
        layers.append(module)
        if isinstance(module, nn.Linear) and module is not linears[-1]:
            layers.append(nn.LayerNorm(module.out_features))
    return nn.Sequential(*layers)


if __name__ == "__main__":
    policies.create_bn_mlp = create_ln_mlp
    if WHERE == "both":
        actor.create_bn_mlp = create_ln_mlp
    sys.exit(run.main(sys.argv[1:]))
