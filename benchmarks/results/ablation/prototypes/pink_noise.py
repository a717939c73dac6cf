"""Prototype, not in the library (ablation README, section 11): the 0.5 default DENFAC exploring with temporally
correlated Gaussian noise of a 1/f^beta spectrum (pink for beta = 1; Eberhard et al. 2023) instead of white noise,
clipped to [-1, 1], on the sparse Acrobot at its gamma 0.9, 100 episodes.

Usage: ``python pink_noise.py BETA SIGMA SEED [ENV_ID]``; prints one JSON line (``pink_noise/runs.jsonl``).
"""

import json
import sys
import time

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback, StopTrainingOnMaxEpisodes

from sb3_denfac import DENFAC


def powerlaw_noise(beta: float, n: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """(n, dim) unit-variance Gaussian noise with a 1/f^beta power spectrum."""
    freqs = np.fft.rfftfreq(n)
    freqs[0] = freqs[1] if n > 1 else 1.0
    spectrum = rng.standard_normal((dim, len(freqs))) + 1j * rng.standard_normal((dim, len(freqs)))
    x = np.fft.irfft(spectrum * freqs ** (-beta / 2.0), n=n, axis=-1)
    return (x / x.std(axis=-1, keepdims=True)).T.astype(np.float32)


class ColoredDENFAC(DENFAC):
    """DENFAC whose exploration noise of each episode is one draw of :func:`powerlaw_noise`."""

    new_episode = True

    def __init__(self, *args, beta: float = 1.0, seq_len: int = 500, **kwargs):
        self.beta, self.seq_len = beta, seq_len
        super().__init__(*args, **kwargs)
        self._rng = np.random.default_rng(kwargs.get("seed"))
        self._noise, self._t = None, 0

    def _sample_action(self, learning_starts, action_noise=None, n_envs=1):
        if self._noise is None or self._t >= len(self._noise) or self.new_episode:
            self._noise = powerlaw_noise(self.beta, self.seq_len, self.action_space.shape[0], self._rng)
            self._t, self.new_episode = 0, False
        mean = self._exploration_mean(self._last_obs)
        buffer_action = np.clip(mean + self.sigma * self._noise[self._t], -1.0, 1.0).astype(np.float32)
        self._t += 1
        self._last_behaviour_mean = mean
        return self.policy.unscale_action(buffer_action), buffer_action


class Record(BaseCallback):
    def __init__(self):
        super().__init__()
        self.performance = []

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            if done:
                self.performance.append(info.get("paper_performance"))
                self.model.new_episode = True
        return True


def main() -> None:
    beta, sigma, seed = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
    env_id = sys.argv[4] if len(sys.argv) > 4 else "sb3_denfac/ContinuousAcrobot-v0"
    th.set_num_threads(1)
    model = ColoredDENFAC("MlpPolicy", gym.make(env_id), gamma=0.9, sigma=sigma, beta=beta, seed=seed)
    record, start = Record(), time.process_time()
    model.learn(10**7, callback=[record, StopTrainingOnMaxEpisodes(100)])
    perf = record.performance
    summary = dict(beta=beta, sigma=sigma, seed=seed, best=min(perf), goals=sum(p < 500 for p in perf))
    summary.update(last10=float(np.mean(perf[-10:])), cpu=round(time.process_time() - start), perf=perf)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
