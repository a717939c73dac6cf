"""The DENFAC ablation's configurations: named constructor settings, one factor apart, run by the benchmark runner.

Each configuration is a row ``abl:<name>`` of the ``ablation`` suite (``benchmarks/suites.py``, study ``ablation``):

    python -m benchmarks.run --suite ablation --algos abl:faithful abl:default --envs pendulum --seeds 0 1 2
    python -m benchmarks.ablation_analysis                       # tables: results/ablation/tables.md

Every run records per-episode returns, CPU seconds and critic-fit diagnostics (``benchmarks/diagnostics.py``).
``FAITHFUL`` is the paper's Algorithm 1 (``sb3_denfac.denfac.presets.PAPER``) and ``GOOD`` the 0.2 library default;
``FACTORS`` move one setting from one to the other. Configurations of the prototypes tried before 0.3
(``_proto``: prioritised replay, trust region, target normalisation...) are no longer runnable: the ones that worked
became library options (``actor_proximal``, ``n_critics``, ``prioritized``); their runs stay in the results file.
"""

from __future__ import annotations

import copy
from typing import Any

from benchmarks.suites import HYPERPARAMS_OF, PACKAGE_HYPERPARAMS_DIR, Budget, _yaml_hyperparams
from sb3_denfac.denfac.presets import paper
from sb3_denfac.envs.facts import env_facts

#: Episodes per env (the diagnosis budgets; no deterministic evaluations). Hopper and Reacher are held out: they were
#: not used to choose the 0.3 settings.
BUDGETS: dict[str, Budget] = {
    "pendulum": Budget(40, 10, 0),
    "halfcheetah": Budget(30, 10, 0),
    "cartpole": Budget(100, 10, 0),
    "acrobot": Budget(30, 10, 0),
    "invertedpendulum": Budget(100, 10, 0),
    "hopper": Budget(100, 10, 0),
    "reacher": Budget(100, 10, 0),
}
#: What the faithful configurations take from the paper's per-env YAML entry (Figure 5), where the env has one.
PER_ENV_KEYS = ("buffer_size", "reset_critic", "inverting_gradients")

#: The faithful Algorithm 1: the paper's preset; D = 6000 (Figure 5's Acrobot value) on envs without a Figure 5 entry.
FAITHFUL: dict[str, Any] = paper(buffer_size=6000)

# The candidate general configuration (fitted Q with minibatches, kept actor, bigger nets, modest lr).
GOOD: dict[str, Any] = dict(
    learning_rate=1e-3,
    adam_betas=(0.9, 0.999),
    buffer_size=100_000,
    batch_size=256,
    n_fitted_iterations=10,
    critic_steps=50,
    actor_steps=25,
    reset_actor=False,
    reset_critic=False,
    sigma=0.1,
    weighting="none",
    bootstrap_on_timeout=True,
    actor_proximal=0.0,  # the 0.2 library default; the 0.3 default is `default+proximal`
    # The targets of 0.2-0.4 (0.5 made the library default the critics' mean at a smoothed next action:
    # `default04+mean+smooth`, i.e. `default05`): pinned, so that these rows keep the meaning their runs were made with
    target_policy_noise=0.0,
    critic_target="min",
    policy_kwargs=dict(net_arch=dict(pi=[64, 64], qf=[64, 64]), batch_norm=False, init="default", n_critics=1),
)

# factor -> (faithful value, good value); each value is a dict of constructor overrides (policy_kwargs merged).
FACTORS: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {
    "lr": (dict(learning_rate=0.1), dict(learning_rate=1e-3)),
    "beta1": (dict(adam_betas=(0.0, 0.999)), dict(adam_betas=(0.9, 0.999))),
    "init": (dict(policy_kwargs=dict(init="paper")), dict(policy_kwargs=dict(init="default"))),
    "csteps": (dict(critic_steps=10), dict(critic_steps=50)),
    "batch": (dict(batch_size=None), dict(batch_size=256)),
    "nets": (
        dict(policy_kwargs=dict(net_arch=dict(pi=[20], qf=[50, 7]))),
        dict(policy_kwargs=dict(net_arch=dict(pi=[64, 64], qf=[64, 64]))),
    ),
    "sigma": (dict(sigma=0.05), dict(sigma=0.1)),
    "reset": (dict(reset_actor=True), dict(reset_actor=False)),
    "D": (dict(buffer_size=6000), dict(buffer_size=100_000)),
    "bn": (dict(policy_kwargs=dict(batch_norm=True)), dict(policy_kwargs=dict(batch_norm=False))),
    "weight": (dict(weighting="retrace"), dict(weighting="none")),
    # library default True (SB3 semantics) for both faithful and good; the ablation is the paper-era False
    "timeout": (dict(bootstrap_on_timeout=False), dict(bootstrap_on_timeout=True)),
}


def merge(base: dict[str, Any], *overrides: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for ov in overrides:
        for k, v in ov.items():
            if k == "policy_kwargs":
                pk = out.setdefault("policy_kwargs", {})
                for kk, vv in v.items():
                    if kk == "net_arch" and isinstance(pk.get("net_arch"), dict):
                        pk["net_arch"] = {**pk["net_arch"], **vv}
                    else:
                        pk[kk] = copy.deepcopy(vv)
            else:
                out[k] = copy.deepcopy(v)
    return out


def build_configs() -> dict[str, dict[str, Any]]:
    c: dict[str, dict[str, Any]] = {"faithful": merge(FAITHFUL), "good": merge(GOOD)}
    for name, (fv, gv) in FACTORS.items():
        c[f"faithful+{name}"] = merge(FAITHFUL, gv) if name != "timeout" else merge(FAITHFUL, fv)  # timeout: -> False
        c[f"good-{name}"] = merge(GOOD, fv)
    # combined steps of the step-size question, and joint factor groups
    c["faithful+lr+beta1"] = merge(FAITHFUL, FACTORS["lr"][1], FACTORS["beta1"][1])
    c["faithful+critfit"] = merge(FAITHFUL, FACTORS["init"][1], FACTORS["csteps"][1])
    c["faithful+opt+critfit"] = merge(
        FAITHFUL, FACTORS["lr"][1], FACTORS["beta1"][1], FACTORS["init"][1], FACTORS["csteps"][1]
    )
    c["faithful+opt+critfit+reset"] = merge(c["faithful+opt+critfit"], FACTORS["reset"][1])
    c["faithful+opt+critfit+reset+weight"] = merge(c["faithful+opt+critfit+reset"], FACTORS["weight"][1])
    c["good-lr+beta1"] = merge(GOOD, FACTORS["lr"][0], FACTORS["beta1"][0])
    c["good+lr3e-4"] = merge(GOOD, dict(learning_rate=3e-4))
    c["good+sigma0.2"] = merge(GOOD, dict(sigma=0.2))
    wide = dict(net_arch=dict(pi=[256, 256], qf=[256, 256]))  # SB3 SAC's and TD3's default width
    c["good+nets256"] = merge(GOOD, dict(policy_kwargs=wide))
    c["default+proximal+nets256"] = merge(GOOD, dict(actor_proximal=1.0, policy_kwargs=wide))
    c["good+csteps100"] = merge(GOOD, dict(critic_steps=100))
    c["good+csteps25"] = merge(GOOD, dict(critic_steps=25))
    c["good+vecnorm"] = merge(GOOD, dict(_vecnorm=True))
    c["good+bnmom"] = merge(GOOD, dict(policy_kwargs=dict(batch_norm=True, bn_momentum=0.01)))
    c["good+D3000"] = merge(GOOD, dict(buffer_size=3000))
    # the library options (options.py) on 0.2's default (= GOOD); default+proximal is 0.3's default
    c["default"] = merge(GOOD)
    c["default+per-critic"] = merge(GOOD, dict(prioritized="critic"))
    c["default+per-both"] = merge(GOOD, dict(prioritized="both"))
    c["default+proximal"] = merge(GOOD, dict(actor_proximal=1.0))
    c["default+proximal+n_critics2"] = merge(c["default+proximal"], dict(policy_kwargs=dict(n_critics=2)))  # library cdq
    # 0.4's default with about 2.5 critic steps per collected step (all K = 10 iterations after 181+ steps, fewer before)
    c["default04+utd2.5"] = merge(c["default+proximal+n_critics2"], dict(update_to_data_ratio=2.5))
    # The diagnosis against SAC on DENFAC's schedule (suite `diagnosis`): the library default (0.4/0.5) and one of
    # SAC's settings moved into it at a time (SAC's width and learning rate; no proximal term, as SAC has none)
    c["default04"] = merge(c["default+proximal+n_critics2"])
    c["default04+nets256"] = merge(c["default04"], dict(policy_kwargs=wide))
    c["default04+lr3e-4"] = merge(c["default04"], dict(learning_rate=3e-4))
    c["default04-proximal"] = merge(c["default04"], dict(actor_proximal=0.0))
    # 0.5 candidates: TD3's target policy smoothing in eq. (4)'s targets (SAC's targets average over its stochastic
    # next action; this is the deterministic actor's counterpart)
    c["default04+smooth"] = merge(c["default04"], dict(target_policy_noise=0.2, target_noise_clip=0.5))
    # the two critics' mean instead of their minimum in the targets (the minimum erases the sparse Acrobot's goal)
    c["default04+mean"] = merge(c["default04"], dict(critic_target="mean"))
    c["default04+mean+smooth"] = merge(c["default04+smooth"], dict(critic_target="mean"))
    # more exploration instead (SAC reaches the sparse Acrobot's goal by its entropy-driven exploration, TD3 does not)
    c["default04+sigma0.3"] = merge(c["default04"], dict(sigma=0.3))
    # 0.5's default (= default04+mean+smooth) and, on the sparse Acrobot (issue #23's target against the faithful
    # DENFAC), one change at a time: a longer horizon than the env's gamma 0.9 (a diagnosis: at 0.9 a goal 95 steps
    # ahead is worth 0.9^95 ~ 5e-5), no proximal term (faster policy change), TD-error prioritised critic batches
    c["default05"] = merge(c["default04+mean+smooth"])
    c["default05+gamma0.99"] = merge(c["default05"], dict(gamma=0.99))
    c["default05-proximal"] = merge(c["default05"], dict(actor_proximal=0.0))
    c["default05+per-critic"] = merge(c["default05"], dict(prioritized="critic"))
    c["default05+sigma0.3"] = merge(c["default05"], dict(sigma=0.3))
    c["faithful+gamma0.99"] = merge(FAITHFUL, dict(gamma=0.99))  # the same horizon for the paper's DENFAC
    # The diagnosis of issue #23 on 0.5's default (suite `diagnosis`): SAC's width and learning rate moved into it, one
    # at a time (``default05-proximal`` above: no proximal term, as SAC has none)
    c["default05+nets256"] = merge(c["default05"], dict(policy_kwargs=wide))
    c["default05+lr3e-4"] = merge(c["default05"], dict(learning_rate=3e-4))
    # Pendulum, where the matched SAC first holds the pendulum up at episode 10 and 0.5's default at 18: SAC's wider
    # early exploration (its entropy term; SB3's 100 uniform warm-up steps) in DENFAC's terms
    c["default05+warmup200"] = merge(c["default05"], dict(learning_starts=200))
    # eq. (4)'s bootstrap value clipped to the rewards' range (the library's ``bootstrap_bounds``; section 17)
    c["default05+bounds"] = merge(c["default05"], dict(bootstrap_bounds=True))
    # Fewer Bellman backups per episode, the same 500 critic and 250 actor steps (section 19): each fitted iteration
    # refreshes the targets once, so K = 10 backs up 10 times per episode; SAC on DENFAC's schedule (tau = 0.005 over
    # 500 steps: a target time constant of 200 steps) about 2.5 times
    c["default05+K5"] = merge(c["default05"], dict(n_fitted_iterations=5, critic_steps=100, actor_steps=50))
    c["default05+K2"] = merge(c["default05"], dict(n_fitted_iterations=2, critic_steps=250, actor_steps=125))
    # The targets' next actions drawn as widely as the behaviour's (section 20): 0.5's smoothing noise (0.2) is twice
    # the exploration's sigma (0.1), so eq. (4) reads Q_{k-1} at actions the data hardly covers; SAC's targets sample the
    # policy it explores with
    c["default05+tpn0.1"] = merge(c["default05"], dict(target_policy_noise=0.1))
    c["default05+tpn0.3"] = merge(c["default05"], dict(target_policy_noise=0.3))  # and wider than 0.5's
    # The soft actor (the library's ``ent_coef``, section 23's bounded variant: SAC's actor, temperature and soft targets
    # in the fitted iterations, the critics' mean bounded) and, for InvertedPendulum's and CartPole's exploring
    # episodes (behind the matched SAC's), the matched SAC's width and learning rate one at a time (section 24)
    c["soft"] = merge(c["default05+bounds"], dict(ent_coef="auto"))
    c["soft+nets256"] = merge(c["soft"], dict(policy_kwargs=wide))
    c["soft+lr3e-4"] = merge(c["soft"], dict(learning_rate=3e-4))
    # SAC's ratio of actor (and alpha) steps to critic steps, 1: G = 50 per fitted iteration instead of 25
    c["soft+G50"] = merge(c["soft"], dict(actor_steps=50))
    # fresher targets at about the same steps per episode: 20 fitted iterations of 25 critic and 12 actor steps
    c["soft+K20"] = merge(c["soft"], dict(n_fitted_iterations=20, critic_steps=25, actor_steps=12))
    # the critics' minimum in the soft targets (SAC's clipped double Q; section 23's "SAC's whole" held CartPole best),
    # alone and with the fresher targets of K = 20 (section 25)
    c["soft+min"] = merge(c["soft"], dict(critic_target="min"))
    c["soft+min+K20"] = merge(c["soft+K20"], dict(critic_target="min"))
    # a wider entropy target (0 instead of SAC's -dim(A)): alpha rises again when the policy narrows below it (section 25)
    c["soft+min+K20+te0"] = merge(c["soft+min+K20"], dict(target_entropy=0.0))
    # the sparse Acrobot at SB3's default gamma (0.99, what ``DENFAC("MlpPolicy", env)`` runs) instead of the env's 0.9:
    # is the minimum's cost there a property of the paper's short horizon? (section 27; cf. default05+gamma0.99)
    c["soft+gamma0.99"] = merge(c["soft"], dict(gamma=0.99))
    c["soft+min+K20+gamma0.99"] = merge(c["soft+min+K20"], dict(gamma=0.99))
    return c


CONFIGS = build_configs()


def hyperparams(config: str, env: str) -> dict[str, Any]:
    """Constructor arguments of ``config`` on ``env``: faithful configurations take the env's Figure 5 values (its
    ``hyperparams/denfac.yml`` entry: D, reset critic, inverting gradients, actor and critic sizes) where the
    configuration did not move that factor away from the paper."""
    kwargs = merge(CONFIGS[config])
    if kwargs.pop("_vecnorm", False):
        kwargs["normalize"] = True  # the zoo's VecNormalize (observations and rewards)
    if config.startswith("faithful") and env_facts(HYPERPARAMS_OF.get(env, env)).gym_id in _paper_entries():
        entry, _ = _yaml_hyperparams("denfac", env, ())
        keep = {k: entry[k] for k in PER_ENV_KEYS if k in entry}
        factors = config.split("+")
        if "nets" not in factors:
            keep["policy_kwargs"] = {"net_arch": entry["policy_kwargs"]["net_arch"]}
        if "D" in factors:
            keep.pop("buffer_size", None)
        kwargs = merge(kwargs, keep)
    return kwargs


def _paper_entries() -> dict[str, Any]:
    """The entries of ``hyperparams/denfac.yml`` (keyed by the paper's env ids)."""
    from sb3_denfac.zoo import load_config_file

    return load_config_file(PACKAGE_HYPERPARAMS_DIR / "denfac.yml")
