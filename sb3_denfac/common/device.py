"""Devices: the five algorithms' networks are tiny, and a GPU only adds transfer and launch latency to them.

:func:`warn_small_networks_on_gpu` follows SB3's warning for PPO with an MLP policy on the GPU: when ``device="auto"``
picked CUDA for a policy of fewer than :data:`SMALL_NETWORK_PARAMETERS` parameters, one ``UserWarning`` per algorithm
and process says so and how to run on the CPU. An explicit ``device="cuda"`` is the caller's choice: no warning.
"""

from __future__ import annotations

import warnings
from typing import Any

import torch as th

#: Policies with fewer parameters than this are "small" (the paper's networks have a few hundred to a few thousand).
SMALL_NETWORK_PARAMETERS = 1_000_000

_warned: set[str] = set()


def _is_cuda(device: th.device | str) -> bool:
    return th.device(device).type == "cuda"


def warn_small_networks_on_gpu(algorithm: str, requested: Any, device: th.device, policy: th.nn.Module) -> bool:
    """Warn once per ``algorithm`` if ``requested`` was "auto", ``device`` is CUDA and ``policy`` is small; returns
    whether it warned."""
    if not (isinstance(requested, str) and requested == "auto") or not _is_cuda(device):
        return False
    n_parameters = sum(p.numel() for p in policy.parameters())
    if n_parameters >= SMALL_NETWORK_PARAMETERS or algorithm in _warned:
        return False
    _warned.add(algorithm)
    warnings.warn(
        f"{algorithm} is running on the GPU because device='auto' found CUDA, but its policy has only {n_parameters} "
        "parameters: networks this small train faster on the CPU (transfers and kernel launches dominate). Pass "
        f"device='cpu' to {algorithm}(...) (or device='cuda' to keep the GPU and silence this warning).",
        UserWarning,
        stacklevel=3,
    )
    return True
