"""Shared by the prototypes that change how the soft actor draws its exploring action (``oac_exploration.py``,
``pink_soft.py``): :func:`patch` replaces the soft actor's branch of ``DENFAC._sample_action`` with one whose squashed
action comes from ``draw(model, obs, mean, log_std)`` (the observation tensor, the actor's pre-tanh mean and clamped
log std, computed without gradient); the rest (warm-up, the deterministic actor, the buffer's action and behaviour
mean) is the library's."""

from collections.abc import Callable

import numpy as np
import torch as th

from sb3_denfac.denfac import denfac as denfac_module


def patch(draw: Callable[..., th.Tensor]) -> None:
    library_sample_action = denfac_module.DENFAC._sample_action

    def sample_action(self, learning_starts, action_noise=None, n_envs=1):
        if not self.policy.soft_actor or self.num_timesteps < learning_starts:
            return library_sample_action(self, learning_starts, action_noise, n_envs)
        assert action_noise is None
        self.policy.set_training_mode(False)
        obs, _ = self.policy.obs_to_tensor(self._last_obs)
        with th.no_grad():
            mean, log_std, _ = self.actor.get_action_dist_params(obs)
        sampled = draw(self, obs, mean, log_std)
        shape = (-1, *self.action_space.shape)
        buffer_action = sampled.detach().cpu().numpy().reshape(shape).astype(np.float32)
        self._last_behaviour_mean = th.tanh(mean).cpu().numpy().reshape(shape).astype(np.float32)
        return self.policy.unscale_action(buffer_action), buffer_action

    denfac_module.DENFAC._sample_action = sample_action
