"""Devices: the algorithms' networks are tiny, and a GPU only adds transfer and launch latency to them.

:func:`warn_about_device`, called by every algorithm once its policy is built, warns once per algorithm and process:

- when ``device="cuda"`` (or ``"cuda:N"``) was asked where CUDA is not available: SB3 then runs on the CPU without a
  word (``get_device``); the run goes on there, and the warning says so;
- following SB3's warning for PPO with an MLP policy on the GPU: when ``device="auto"`` picked CUDA for a policy of
  fewer than :data:`SMALL_NETWORK_PARAMETERS` parameters, it says so and how to run on the CPU. An explicit
  ``device="cuda"`` on a GPU is the caller's choice: no warning.
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


def warn_about_device(algorithm: str, requested: Any, device: th.device, policy: th.nn.Module) -> bool:
    """Warn once per ``algorithm`` (module docstring) if CUDA was asked where there is none, or if ``requested`` was
    "auto", ``device`` is CUDA and ``policy`` is small; returns whether it warned."""
    auto = isinstance(requested, str) and requested == "auto"
    if not auto and _is_cuda(requested) and not _is_cuda(device):
        key = f"{algorithm}: no CUDA"
        if key in _warned:
            return False
        _warned.add(key)
        warnings.warn(
            f"{algorithm} was given device={str(requested)!r} but CUDA is not available here "
            f"(torch.cuda.is_available() is False): it runs on the {device.type.upper()}, as SB3 falls back.",
            UserWarning,
            stacklevel=3,
        )
        return True
    if not auto or not _is_cuda(device):
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
