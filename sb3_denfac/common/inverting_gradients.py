"""Inverting gradients for bounded action spaces (Hausknecht & Stone 2016), used by DENFAC (Algorithm 1) and DDPG.

With an unbounded (linear) actor output, the critic's action gradient is scaled so that it shrinks as the action
approaches the bound it is pushing toward and reverses sign once the action lies beyond it:

    g = dQ/da (ascent direction)
    g > 0 (increase a):  g * (a_max - a) / (a_max - a_min)
    g <= 0 (decrease a): g * (a - a_min) / (a_max - a_min)

The paper's Algorithm 1 writes the same rule for the descent gradient -dQ/da (hence its swapped cases), as does the
authors' Caffe code. Out-of-bound actions are therefore always pulled back inside [a_min, a_max].
"""

from __future__ import annotations

import torch as th


def invert_gradients(dq_da: th.Tensor, actions: th.Tensor, low: th.Tensor, high: th.Tensor) -> th.Tensor:
    """Return the inverted ascent gradient for ``actions`` given ``dq_da = dQ/da`` (same shapes)."""
    span = high - low
    return th.where(dq_da > 0, dq_da * (high - actions) / span, dq_da * (actions - low) / span)


def invert_gradients_unit_box(dq_da: th.Tensor, actions: th.Tensor, out: th.Tensor | None = None) -> th.Tensor:
    """:func:`invert_gradients` for the bounds [-1, 1] (SB3's scaled action space) in a few in-place passes.

    There the rule is g (1 - sign(g) a) / 2: (1 - a) / 2 for g > 0, (a + 1) / 2 for g < 0, 0 for g = 0; the same
    float operations as the general form, without its branches and temporaries. Written into ``out`` if given.
    """
    return th.sign(dq_da, out=out).mul_(actions).neg_().add_(1.0).mul_(dq_da).mul_(0.5)


def inverting_gradient_actor_backward(q_values: th.Tensor, actions: th.Tensor, low: th.Tensor, high: th.Tensor) -> th.Tensor:
    """Back-propagate the inverted gradient of ``mean(Q(s, pi(s)))`` into the actor parameters.

    ``actions`` must be the actor output pi(s) (part of the graph), ``q_values`` = Q(s, actions). Only the actor's
    gradients should be stepped afterwards (the critic also receives gradients through Q and must be zeroed).

    :return: the mean Q value (detached), for logging.
    """
    (dq_da,) = th.autograd.grad(q_values.mean(), actions, retain_graph=False)
    inverted = invert_gradients(dq_da, actions.detach(), low, high)
    # Descent on -Q: the gradient fed into the actor output is minus the (inverted) ascent direction.
    actions.backward(-inverted)
    return q_values.detach().mean()
