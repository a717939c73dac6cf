"""Per-environment facts used to train and to score on this package's environments and the held-out Gymnasium ones.

One :class:`EnvFacts` per environment, in :data:`ENV_FACTS` (keyed by short name); :func:`env_facts` looks one up by
short name or Gymnasium id. The paper's envs take their facts from the paper (section 4); the held-out envs from
Gymnasium's documentation.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EnvFacts:
    """What is fixed about an environment, whatever the algorithm.

    :param name: short name (command lines, file names).
    :param gym_id: Gymnasium id.
    :param gamma: the discount the env prescribes (the paper's), ``None`` if it prescribes none.
    :param measure: what the per-episode performance is (``info["paper_performance"]``, else ``info["is_success"]``
        for a goal-conditioned env, else the episode return).
    :param lower_is_better: direction of the measure (Acrobot: steps to the goal).
    :param threshold: "solved" level of the measure (reached when ``< threshold`` if lower is better, else
        ``>= threshold``); ``None``: no threshold.
    :param threshold_meaning: what reaching the threshold means.
    :param score_range: (worst, best) reference values of the measure, for normalising scores to [0, 1] across envs;
        ``None``: no fixed reference (normalise over the runs compared).
    :param label: a short human-readable title.
    :param survival_bonus: the reward every step pays for not having terminated (Gymnasium's ``healthy_reward`` of
        the MuJoCo locomotion envs), ``None`` if none. The return then mixes surviving and the task: standing still
        for the whole episode earns ``survival_bonus`` x its length, so the reports also give the return beyond it.
    """

    name: str
    gym_id: str
    gamma: float | None
    measure: str
    lower_is_better: bool = False
    threshold: float | None = None
    threshold_meaning: str = ""
    score_range: tuple[float, float] | None = None
    label: str = ""
    survival_bonus: float | None = None

    def reached(self, value: float) -> bool:
        """Whether ``value`` of the measure reaches the threshold (False without a threshold or for NaN)."""
        if self.threshold is None or value != value:
            return False
        return value < self.threshold if self.lower_is_better else value >= self.threshold


ENV_FACTS: dict[str, EnvFacts] = {
    f.name: f
    for f in (
        EnvFacts(
            "acrobot",
            "sb3_denfac/ContinuousAcrobot-v0",
            gamma=0.9,
            measure="decisions to the goal (500 if not reached)",
            lower_is_better=True,
            threshold=500.0,
            threshold_meaning="the goal is reached at all",
            score_range=(500.0, 0.0),
            label="Acrobot (steps to goal, lower is better)",
        ),
        EnvFacts(
            "acrobot75",
            "sb3_denfac/ContinuousAcrobot75-v0",
            gamma=0.9,
            measure="decisions to the goal (75 if not reached)",
            lower_is_better=True,
            threshold=75.0,
            threshold_meaning="the goal is reached at all within the authors' 75 decisions",
            score_range=(75.0, 0.0),
            label="Acrobot, 75 decisions (steps to goal, lower is better)",
        ),
        EnvFacts(
            "cartpole",
            "sb3_denfac/ContinuousCartPole-v0",
            gamma=0.99,
            measure="episode return",
            threshold=-500.0,
            threshold_meaning="the pole stays up for the 500 steps (falling at step t costs -2 (500 - t))",
            score_range=(-1000.0, 0.0),
            label="CartPole (return, higher is better)",
        ),
        EnvFacts(
            "halfcheetah",
            "sb3_denfac/HalfCheetahPaper-v0",
            gamma=0.99,
            measure="episode return",
            threshold=50.0,
            threshold_meaning="runs forward (the initial near-zero policy stands still at |return| < 2)",
            score_range=None,
            label="Half-Cheetah (return, higher is better)",
        ),
        EnvFacts(
            "pendulum",
            "Pendulum-v1",
            gamma=None,
            measure="episode return (200 steps)",
            threshold=-200.0,
            threshold_meaning="swung up and held (random policies score about -1200 to -1500)",
            score_range=(-1500.0, 0.0),
            label="Pendulum-v1 (return, higher is better)",
        ),
        EnvFacts(
            "invertedpendulum",
            "InvertedPendulum-v5",
            gamma=None,
            measure="episode return (= steps balanced, at most 1000)",
            threshold=1000.0,
            threshold_meaning="balanced for the whole 1000 steps",
            score_range=(0.0, 1000.0),
            label="InvertedPendulum-v5 (return, higher is better)",
        ),
        # Held-out envs of the benchmark: no threshold of our own; Gymnasium's reward_threshold where it has one.
        EnvFacts(
            "hopper",
            "Hopper-v5",
            gamma=None,
            measure="episode return (at most 1000 steps; ends when the hopper falls)",
            threshold=3800.0,
            threshold_meaning="Gymnasium's reward_threshold",
            label="Hopper-v5 (return, higher is better)",
            survival_bonus=1.0,
        ),
        EnvFacts(
            "reacher",
            "Reacher-v5",
            gamma=None,
            measure="episode return (50 steps)",
            threshold=-3.75,
            threshold_meaning="Gymnasium's reward_threshold",
            label="Reacher-v5 (return, higher is better)",
        ),
        # panda-gym's goal-conditioned arm (the robotics extra): the measure is the share of goals reached
        EnvFacts(
            "pandareach",
            "PandaReach-v3",
            gamma=None,
            measure="success: the goal reached at the episode's end (info['is_success']; 50 steps, ends at the goal)",
            threshold=0.9,
            threshold_meaning="90% of the evaluation's goals reached",
            score_range=(0.0, 1.0),
            label="PandaReach-v3 (success rate)",
        ),
        EnvFacts(
            "pandapush",
            "PandaPush-v3",
            gamma=None,
            measure="success: the object at the goal at the episode's end (info['is_success']; 50 steps)",
            threshold=0.9,
            threshold_meaning="90% of the evaluation's goals reached",
            score_range=(0.0, 1.0),
            label="PandaPush-v3 (success rate)",
        ),
    )
}


def env_facts(name_or_id: str) -> EnvFacts:
    """The facts of a short name or Gymnasium id; an unknown id gets "episode return, higher is better, no gamma"."""
    if name_or_id in ENV_FACTS:
        return ENV_FACTS[name_or_id]
    for facts in ENV_FACTS.values():
        if facts.gym_id == name_or_id:
            return facts
    return EnvFacts(name_or_id, name_or_id, gamma=None, measure="episode return", label=name_or_id)
