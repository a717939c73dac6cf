"""Which :class:`~sb3_denfac.denfac.updaters.Updater` carries out an update: DENFAC's ``update_path``.

The one place that picks between the autograd updater (the reference) and the fast one. An algorithm names its two
implementations in :class:`UpdaterClasses` (DENFAC's ``updater_classes``; :class:`~sb3_denfac.soft_denfac.SoftDENFAC`
names its own): a study that changes how the networks are fitted subclasses them and the algorithm, and declares its
classes there, instead of replacing library attributes.
"""

from __future__ import annotations

from typing import NamedTuple

from torch import nn

from sb3_denfac.denfac.fast import FastUpdater, supported_networks
from sb3_denfac.denfac.updaters import AutogradUpdater, FitSettings, Updater

#: DENFAC's ``update_path`` values: the fast updater where it applies, the fast one (or an error), the autograd one.


class UpdaterClasses(NamedTuple):
    """An algorithm's two implementations of the update: ``plain`` (autograd, any policy) and ``fast`` (flat
    parameters, the networks :func:`~sb3_denfac.denfac.fast.supported_networks` accepts)."""

    plain: type[AutogradUpdater]
    fast: type[FastUpdater]


#: DENFAC's updaters.
DENFAC_UPDATERS = UpdaterClasses(plain=AutogradUpdater, fast=FastUpdater)


def _options_refusal(settings: FitSettings) -> str | None:
    """Why the fast updater cannot carry out these settings (an option only the autograd updater implements), or None."""
    if settings.prioritized != "none":
        return f"update_path='fast' does not support prioritized={settings.prioritized!r}: use update_path='auto' or 'plain'"
    if not settings.frozen_targets:
        return "update_path='fast' does not support frozen_targets=False (CrossQ): use update_path='auto' or 'plain'"
    return None


#: Devices the fast updater is verified on: its tests run on the CPU and, for "nothing assumes the CPU", on the meta
#: device. Elsewhere (CUDA, MPS...) "auto" takes the autograd updater (standard torch ops) and "fast" is refused.
FAST_DEVICES = ("cpu", "meta")


def _device_refusal(policy: nn.Module) -> str | None:
    """Why the fast updater is not used on the policy's device, or None on a device it is verified on."""
    parameter = next(policy.parameters(), None)
    device = parameter.device.type if parameter is not None else "cpu"
    if device in FAST_DEVICES:
        return None
    return (
        f"update_path='fast' is verified on the CPU only (its fused Adam kernel and hand-written steps are tested there),"
        f" the policy is on {device!r}: use update_path='auto' (the autograd updater there) or 'plain'"
    )


def check_update_path(update_path: str, settings: FitSettings) -> None:
    """At construction, before any network exists: a ValueError if ``update_path="fast"`` asks for an option the fast
    updater does not implement (the networks are checked by :func:`make_updater`, at the update)."""
    refusal = _options_refusal(settings)
    if update_path == "fast" and refusal is not None:
        raise ValueError(refusal)


class UpdaterChoice(NamedTuple):
    updater: Updater
    #: why the fast updater was not used ("auto" fell back to the autograd one); None if it was, or with "plain"
    fast_refused: str | None


def make_updater(
    policy: nn.Module, settings: FitSettings, update_path: str, classes: UpdaterClasses = DENFAC_UPDATERS
) -> UpdaterChoice:
    """The updater of one update (``update_path``: "plain" the autograd one; "fast" the fast one, a ValueError saying
    why where it cannot; "auto" the fast one where it can, else the autograd one), and why the fast one was refused."""
    if update_path == "plain":
        return UpdaterChoice(classes.plain(policy, settings), None)
    refusal = _options_refusal(settings) or _device_refusal(policy)
    layers = supported_networks(policy, flat_actor=classes.fast.flat_actor) if refusal is None else None
    if refusal is None and getattr(policy.critic, "target_subset", None) is not None:
        refusal = "update_path='fast' does not support the critic's target_subset (REDQ): use update_path='auto' or 'plain'"
    if refusal is None and layers is None:
        refusal = (
            "update_path='fast' needs vector observations (or a Dict of them with SB3's CombinedExtractor), the default "
            "MLP networks and Adam"
        )
    if refusal is None:
        return UpdaterChoice(classes.fast(policy, settings, *layers), None)  # type: ignore[misc]
    if update_path == "fast":
        raise ValueError(refusal)
    return UpdaterChoice(classes.plain(policy, settings), refusal)
