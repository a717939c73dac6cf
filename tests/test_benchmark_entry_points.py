"""Every benchmark entry point (``python -m benchmarks.<module>``) runs end to end on a tiny configuration."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from benchmarks import run as runner
from benchmarks.reports import ablation_analysis, analysis, stats
from benchmarks.runner import diagnostics, store
from benchmarks.runner import sweep as sweeps
from benchmarks.studies import acrobot_horizon, cost, throughput, update_cost, update_cost_critics, update_threads

REPO = Path(__file__).resolve().parent.parent


def test_runner_runs_as_a_module_from_the_repository_root():
    result = subprocess.run(
        [sys.executable, "-m", "benchmarks.run", "--help"], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert "--suite" in result.stdout and "matched" in result.stdout


def test_run_and_analysis_command_lines(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(stats, "REPS", 50)
    args = ["--algos", "denfac_default", "cmaes", "--envs", "pendulum", "--seeds", "0", "1", "--episodes", "2"]
    assert runner.main([*args, "--results", str(tmp_path), "--workers", "0", "--no-analysis"]) == 0
    assert len(store.read_runs(tmp_path)) == 4 and not (tmp_path / "all_runs.md").exists()
    analysis.main(["--results", str(tmp_path), "--suites", "generalisation"])
    assert (tmp_path / "generalisation.md").exists() and not (tmp_path / "all_runs.md").exists()
    with pytest.raises(SystemExit):
        analysis.main(["--results", str(tmp_path), "--suites", "figure"])
    capsys.readouterr()
    analysis.main(["--results", str(tmp_path)])  # every report: figure3, generalisation, matched, all_runs
    assert {"figure3.md", "matched.md", "all_runs.md"} <= {p.name for p in tmp_path.glob("*.md")}
    assert "DENFAC (default)" in (tmp_path / "all_runs.md").read_text()
    assert capsys.readouterr().out.startswith("wrote ")  # the files written, not their tables


def test_a_run_of_one_suite_writes_its_report_alone_and_prints_no_table(tmp_path, monkeypatch, capsys):
    """The cell (DENFAC's default, Pendulum, seed 0) is in ``figure3``, ``generalisation`` and ``matched``: a run of
    ``generalisation`` writes ``generalisation.md`` and no other suite's report, and the console gets a line per cell
    and the summary, no markdown (``python -m benchmarks.reports.analysis`` writes every report: the test above)."""
    monkeypatch.setattr(stats, "REPS", 50)
    args = ["--suite", "generalisation", "--algos", "denfac_default", "--envs", "pendulum", "--seeds", "0"]
    assert runner.main([*args, "--episodes", "2", "--results", str(tmp_path), "--workers", "0"]) == 0
    reports = sorted(p.name for p in tmp_path.glob("*.md"))
    assert reports == ["generalisation.md"] and "DENFAC (default)" in (tmp_path / "generalisation.md").read_text()
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 4 and not [line for line in lines if line.startswith(("|", "#", "!["))], lines
    assert "[1/1] done denfac_default pendulum seed 0" in lines[1]
    assert lines[2:] == [f"report: {tmp_path / 'generalisation.md'}", "finished: 1 done, 0 skipped, 0 failed"]


DOCUMENTS = ["README.md", "benchmarks/README.md", *(f"docs/{p.name}" for p in sorted((REPO / "docs").glob("*.md")))]
DOCUMENTS += [str(p.relative_to(REPO)) for p in sorted((REPO / "research").glob("*/README.md"))]


@pytest.mark.parametrize("document", DOCUMENTS)
def test_every_benchmark_command_quoted_in_the_docs_names_a_module(document):
    """``python -m benchmarks...`` and ``python -m research...`` in the README, docs/, benchmarks/ and research/'s
    READMEs name modules that exist (a module moved without its commands fails here)."""
    text = (REPO / document).read_text()
    for module in sorted(set(re.findall(r"python -m ((?:benchmarks|research)(?:\.\w+)*)", text))):
        try:
            found = importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:  # a package above it is missing
            found = False
        assert found, f"{document} quotes python -m {module}, which is no module"


def test_ablation_study_records_diagnostics_and_tables(tmp_path):
    args = ["--suite", "ablation", "--algos", "abl:default", "abl:faithful", "--envs", "pendulum", "--seeds", "0"]
    assert runner.main([*args, "--episodes", "6", "--results", str(tmp_path), "--workers", "0", "--no-analysis"]) == 0
    records = {r["algo"]: r for r in store.read_runs(tmp_path)}
    assert set(records) == {"abl:default", "abl:faithful"}
    diagnostics = records["abl:default"]["diagnostics"]
    assert [d["episode"] for d in diagnostics] == [5] and diagnostics[0]["n"] == 5 * 200
    assert ablation_analysis.main([str(tmp_path)]) == 0
    tables = (tmp_path / "tables.md").read_text()
    assert "| faithful (6 ep) | 1 |" in tables  # a run of 6 episodes is not one of the 40-episode budget
    assert (tmp_path / "runs.csv").read_text().count("(6 ep),pendulum,0,") == 2


def test_diagnostics_outside_a_suite(tmp_path):
    # any env, algos and seeds, with a suite's critic diagnostics: --diagnostics-every without --suite
    args = ["--algos", "abl:default05", "--envs", "Pendulum-v1", "--seeds", "0", "--episodes", "3"]
    assert runner.main([*args, "--diagnostics-every", "2", "--results", str(tmp_path), "--workers", "0",
                        "--no-analysis"]) == 0  # fmt: skip
    (record,) = store.read_runs(tmp_path)
    assert [d["episode"] for d in record["diagnostics"]] == [2] and record["diagnostics"][0]["n"] == 2 * 200
    assert all(0.0 <= record["diagnostics"][0][key] <= 1.0 for key in ("grad_sign_agreement", "grad_sign_agreement_data"))
    with pytest.raises(ValueError, match="diagnostics_every must be an int >= 0"):
        sweeps.sweep(["abl:default05"], ["Pendulum-v1"], [1], 1, results_dir=tmp_path, diagnostics_every=-1)


def test_action_gradient_sign_agreement_of_two_critics():
    # 1 where Q_2 is Q_1, 0 where Q_2 = -Q_1, in between for two independently initialised critics; by chunks of rows
    from sb3_denfac import DENFAC

    model = DENFAC("MlpPolicy", "Pendulum-v1", seed=0)
    critic = model.critic
    critic.set_training_mode(False)
    obs, actions = torch.randn(512, 3), torch.rand(512, 1) * 2 - 1
    independent = diagnostics.action_gradient_sign_agreement(critic, obs, actions)
    assert 0.0 < independent < 1.0
    assert diagnostics.action_gradient_sign_agreement(critic, obs, actions, chunk=100) == independent
    assert all(p.grad is None and p.requires_grad for p in critic.parameters())  # the critic is left as it was
    twin = critic.twin_qfs[0]
    twin.load_state_dict(critic.qf.state_dict())
    assert diagnostics.action_gradient_sign_agreement(critic, obs, actions) == 1.0
    with torch.no_grad():
        twin[-1].weight.neg_()
        twin[-1].bias.neg_()
    assert diagnostics.action_gradient_sign_agreement(critic, obs, actions) == 0.0


def test_cost_measures_and_plans(tmp_path):
    cost.main(["--algos", "cmaes", "--envs", "pendulum", "--results", str(tmp_path), "--sweep", str(tmp_path / "none")])
    plan = (tmp_path / "sweep_plan.md").read_text()
    assert "Estimated CPU seconds per full run" in plan and (tmp_path / "sweep_plan.csv").exists()


@pytest.mark.slow
def test_update_cost_entry_points(tmp_path):
    update_cost.main(["--repeats", "1", "--threads", "1", "--envs", "acrobot", "--episodes", "1", "--output",
                      str(tmp_path / "uc")])  # fmt: skip
    result = json.loads((tmp_path / "uc.json").read_text())
    assert {r["buffer"] for r in result["runs"]} == {"early", "trained"} and result["meta"]["git"]
    update_cost_critics.main(["--repeats", "1", "--episodes", "1", "--envs", "Pendulum-v1", "--output",
                              str(tmp_path / "critics")])  # fmt: skip
    assert json.loads((tmp_path / "critics.json").read_text())["rows"][0]["ratio"] > 0
    update_threads.main(["--repeats", "1", "--episodes", "1", "--output", str(tmp_path / "threads.json")])
    assert len(json.loads((tmp_path / "threads.json").read_text())) == 1


def test_throughput_prices_runs_side_by_side(tmp_path, capsys):
    """Two processes train at once (one per env), each past its warm-up; the table prices a run from their rates."""
    out = tmp_path / "throughput.json"
    args = ["--algo", "td3", "--envs", "pendulum", "acrobot", "--seconds", "1", "--steps", "1000"]
    throughput.main([*args, "--output", str(out)])
    (run,) = json.loads(out.read_text())
    assert [r["env"] for r in run["records"]] == ["pendulum", "acrobot"]
    assert all(r["steps"] > 0 and r["seconds"] >= 1 for r in run["records"])
    assert run["machine"]["device"] == "cpu" and "| pendulum | 1 |" in capsys.readouterr().out


def test_runs_record_their_device_commit_and_progress(tmp_path, monkeypatch):
    monkeypatch.setenv("BENCHMARK_GIT_COMMIT", "f" * 40)  # the commit given wins over the .git of the tree run
    monkeypatch.setenv("BENCHMARK_PROGRESS_DIR", str(tmp_path))
    args = ["--algos", "td3", "--envs", "pendulum", "--seeds", "0", "--episodes", "1", "--device", "cpu"]
    assert runner.main([*args, "--results", str(tmp_path), "--workers", "0", "--no-analysis"]) == 0
    (run,) = store.read_runs(tmp_path)
    assert run["machine"]["device"] == "cpu" and run["git"]["commit"] == "f" * 40
    progress = json.loads((tmp_path / "td3_pendulum_0.json").read_text())  # the last episode's
    assert progress["episodes"] == 1 and progress["timesteps"] == run["timesteps"] == 200


def test_store_merges_runs_from_another_machine(tmp_path, capsys):
    """Runs made elsewhere (their own --results) join the study; a cell it already holds is kept, not doubled."""
    args = ["--algos", "td3", "--envs", "pendulum", "--episodes", "1", "--workers", "0", "--no-analysis"]
    here, there = tmp_path / "here", tmp_path / "there"
    assert runner.main([*args, "--seeds", "0", "--results", str(here)]) == 0
    assert runner.main([*args, "--seeds", "0", "1", "--results", str(there)]) == 0
    store.main([str(store.runs_path(there)), "--into", str(here)])
    assert "added td3 pendulum seed 1 (1 episodes)" in capsys.readouterr().out
    assert sorted(r["seed"] for r in store.read_runs(here)) == [0, 1]
    assert store.merge(here, [there]) == []  # again: nothing new
    with pytest.raises(SystemExit):
        store.main([str(tmp_path / "missing.jsonl.gz"), "--into", str(here)])
    assert "no runs file at" in capsys.readouterr().err


def test_acrobot_horizon(tmp_path):
    acrobot_horizon.main(["--restarts", "1", "--generations", "2", "--switches", "1", "--stride", "25",
                          "--output", str(tmp_path)])  # fmt: skip
    assert "steps to goal" in (tmp_path / "acrobot_horizon.md").read_text()


def test_long_hopper_record_script():
    """``research/ablation/long_hopper/run.py`` (the journal's section 17: longer Hopper runs) prints its per-10-episode
    rows; with ``--bounds`` the q targets stay within what the rewards allow (|q| < 1000 on Hopper's rewards)."""
    script = REPO / "research/ablation/long_hopper/run.py"
    result = subprocess.run(
        [sys.executable, str(script), "0", "10", "--bounds"], cwd=REPO, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    row = json.loads(result.stdout.strip().splitlines()[-1])
    assert row["ep"] == 10 and row["len"] > 0 and abs(row["beyond"] - (row["ret"] - row["len"])) < 1e-6
    assert abs(row["q"]) < 1000


def test_default_choice_record_script(monkeypatch, capsys):
    """``research/ablation/default_choice.py`` (the journal's section 27) reads the committed runs of every compared row
    on every env and seed (one run per cell) and prints a probability of improvement per candidate and measure."""
    from research.ablation import default_choice

    monkeypatch.setattr(stats, "REPS", 50)
    runs = default_choice.load_runs()
    cells = runs.groupby("algo").size()
    assert dict(cells) == dict.fromkeys(set(default_choice.NAMES.values()), 8 * 5)
    default_choice.main()
    out = capsys.readouterr().out
    assert out.count("(5 vs 5)") == 2 * 4 * len(default_choice.MEASURES) and "–" not in out


def test_frontier_critics_study_scripts(tmp_path, capsys):
    """``research/frontier_critics``: every row of its file resolves to a constructor that builds (the soft rows a
    SoftDENFAC), the probe runs a row of it and resumes, the actor-step diagnostic writes a line per update, and the
    summary reads the committed runs with the suite's baseline."""
    from research.frontier_critics import actor_step, summary
    from research.mujoco100k import probe

    rows_file = REPO / "research/frontier_critics/rows.yml"
    out = tmp_path / "runs.jsonl"
    args = ["--rows-file", str(rows_file), "--rows", "crossq", "soft_droq", "--envs", "Pendulum-v1", "--steps", "400"]
    probe.main([*args, "--eval-every", "200", "--eval-episodes", "1", "--out", str(out)])
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(r["row"], r["algo"]) for r in records] == [("crossq", "denfac"), ("soft_droq", "soft_denfac")]
    assert all(len(r["evaluations"]) == 2 for r in records)
    probe.main([*args, "--out", str(out)])  # resumes: nothing left to run
    assert len(out.read_text().splitlines()) == 2
    diag = tmp_path / "actor_step.jsonl"
    actor_step.main(["--env", "Pendulum-v1", "--rows", "ln", "--steps", "400", "--out", str(diag)])
    updates = json.loads(diag.read_text())["updates"]
    assert len(updates) >= 1 and {"move", "gain", "agree", "q_spread"} <= set(updates[0])
    table = summary.table()
    assert "rho2 (suite)" in set(table["row"]) and set(table["env"]) <= {"Hopper-v5", "Walker2d-v5"}


def test_frontier_critics_checkpoint_probe(tmp_path):
    """``research/frontier_critics/checkpoint_probe.py``: each evaluation point evaluates the best training episode's
    actor beside the last one, and records which episode it was (the best return of the episodes before it)."""
    from research.frontier_critics import checkpoint_probe

    out = tmp_path / "checkpoint.jsonl"
    rows_file = REPO / "research/frontier_critics/rows.yml"
    args = ["--rows-file", str(rows_file), "--rows", "soft_droq", "--envs", "Pendulum-v1", "--steps", "600"]
    checkpoint_probe.main(
        [*args, "--eval-every", "200", "--eval-episodes", "1", "--out", str(out)],
        evaluations=checkpoint_probe.CheckpointEvaluations,
    )
    (record,) = [json.loads(line) for line in out.read_text().splitlines()]
    checks = record["checkpoint_evaluations"]
    assert len(checks) == len(record["evaluations"]) == 3
    returns = record["episode_returns"]
    for check in checks:
        seen = returns[: check["episode"]]
        assert check["mean"] is not None and check["training_return"] == pytest.approx(max(seen), abs=0.01)
        assert returns[check["episode"] - 1] == pytest.approx(max(seen), abs=0.01)


def test_zero_action_reference_stands_on_ant():
    """``research/frontier_critics/zero_action.py``: the reference docs/results.md quotes, that on Ant-v5 the zero
    action stands a whole episode (1000 steps) and scores above the published SAC's 747 at 100k steps."""
    pytest.importorskip("mujoco")
    from research.frontier_critics.zero_action import zero_action_returns

    returns, lengths = zero_action_returns("Ant-v5", episodes=1)
    assert lengths == [1000] and returns[0] > 900


@pytest.mark.parametrize(
    "module",
    [
        "benchmarks.rows",
        "benchmarks.runner.rows",
        "benchmarks.runner.algos",
        "benchmarks.runner.suites",
        "benchmarks.runner.hyperparams",
        "benchmarks.run",
    ],
)
def test_benchmark_modules_import_first_in_a_fresh_interpreter(module):
    """No import circle: each module imports on its own (the ablation's rows and suite are data that ``algos`` and
    ``suites`` read)."""
    result = subprocess.run([sys.executable, "-c", f"import {module}"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_research_code_assigns_no_library_attribute():
    """Studies use the library's public API: no module of ``research/`` assigns to an attribute of something it imported
    from ``sb3_denfac``, Stable-Baselines3 or ``benchmarks`` (the prototypes that did are removed: research/ablation)."""
    import ast

    libraries = ("sb3_denfac", "stable_baselines3", "sb3_contrib", "benchmarks")
    found = []
    for path in sorted((REPO / "research").rglob("*.py")):
        tree = ast.parse(path.read_text())
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                imported |= {(a.asname or a.name).split(".")[0] for a in node.names if a.name.startswith(libraries)}
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith(libraries):
                imported |= {a.asname or a.name for a in node.names}
        for node in ast.walk(tree):
            targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
            for target in targets if isinstance(node, ast.Assign | ast.AugAssign | ast.AnnAssign) else []:
                while isinstance(target, ast.Attribute):
                    target = target.value
                    if isinstance(target, ast.Name) and target.id in imported:
                        found.append(f"{path.relative_to(REPO)}:{node.lineno}")
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "setattr":
                if isinstance(node.args[0], ast.Name) and node.args[0].id in imported:
                    found.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert not found, found


@pytest.mark.parametrize(
    ("args", "cause"),
    [
        (["--algos", "denfac_dflt", "--envs", "pendulum", "--seeds", "0"], "unknown --algos ['denfac_dflt']"),
        (["--suite", "figure3", "--envs", "hopper"], "--envs ['hopper'] not in suite 'figure3'"),
        (["--algos", "cmaes", "--envs", "pendulum"], "give --suite, or --algos, --envs and --seeds"),
        (["--suite", "figure3", "--episodes", "pendulum:3"], "expected N or ENV=N"),
        (["--suite", "figure3", "--episodes", "100", "40"], "one N applies to every env, got 100 and 40"),
        (["--suite", "figure3", "--episodes", "pendulum=3", "pendulum=4"], "two values for 'pendulum'"),
        (["--suite", "figure3", "--diagnostics-every", "-1"], "--diagnostics-every must be >= 0"),
        (["--suite", "figure3", "--device", "gpu0"], "--device 'gpu0' is not a torch device"),
        pytest.param(
            ["--suite", "figure3", "--device", "cuda"],
            "torch sees no CUDA GPU here",
            marks=pytest.mark.skipif(torch.cuda.is_available(), reason="a CUDA GPU is there"),
        ),
    ],
)
def test_runner_names_a_bad_argument_as_a_usage_error(tmp_path, capsys, args, cause):
    with pytest.raises(SystemExit) as exit_info:
        runner.main([*args, "--results", str(tmp_path), "--workers", "0"])
    assert exit_info.value.code == 2  # argparse's usage error: a message, not a traceback, and no run started
    assert cause in capsys.readouterr().err
    assert not store.runs_path(tmp_path).exists()


def test_step_budgets_evaluate_by_env_steps_and_report_against_the_frontier(tmp_path, capsys):
    """``--timesteps``: runs end at the step budget, evaluate at the first episode end past every tenth of it and once
    more at the budget, resume as finished cells, and get the mujoco100k report (table, published references, figure)."""
    algos = ["denfac_data_efficient", "sac_zoo", "crossq_zoo"]  # the peers' warm-up outlasts 500 steps: no training
    args = ["--algos", *algos, "--envs", "Pendulum-v1", "--seeds", "0", "--timesteps", "500"]
    assert runner.main([*args, "--results", str(tmp_path), "--workers", "0"]) == 0
    records = store.read_runs(tmp_path)
    assert len(records) == 3
    for record in records:
        assert record["timesteps"] == 500 and record["timesteps_requested"] == 500 and record["n_episodes"] == 2
        assert [e["timesteps"] for e in record["evaluations"]] == [200, 400, 500]
    text = (tmp_path / "mujoco100k.md").read_text()
    assert "SoftDENFAC (data-efficient preset)" in text and "6156 ± 738 (10 seeds, at 100k)" in text
    assert "sb3-contrib CrossQ (RL Zoo MuJoCo settings)" in text
    assert (tmp_path / "mujoco100k.png").stat().st_size > 0
    capsys.readouterr()
    assert runner.main([*args, "--results", str(tmp_path), "--workers", "0", "--no-analysis"]) == 0
    assert "0 runs to do, 3 already finished" in capsys.readouterr().out


def test_the_jax_peer_runs_where_sbx_is_installed(tmp_path):
    """mujoco100k's ``crossq_sbx`` row (sbx's CrossQ, the frontier extra) goes through the runner as any row: registered
    with the zoo on first use, its YAML entry, its evaluations at the step budget."""
    if importlib.util.find_spec("sbx") is None:
        pytest.skip("the frontier extra (sbx-rl) is not installed")
    # in a process of its own: JAX's threads would make this test process's later fork()s unsafe
    args = ["--algos", "crossq_sbx", "--envs", "Pendulum-v1", "--seeds", "0", "--timesteps", "400", "--workers", "0"]
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    command = [sys.executable, "-m", "benchmarks.run", *args, "--results", str(tmp_path), "--no-analysis"]
    subprocess.run(command, cwd=REPO, check=True, timeout=300, env=env, capture_output=True)
    (record,) = store.read_runs(tmp_path)
    assert record["status"] == "done" and record["timesteps"] == 400, record.get("log")
    assert record["hyperparams"]["learning_starts"] == "5000" and record["zoo_algo"] == "sbx_crossq"
    assert [e["timesteps"] for e in record["evaluations"]] == [200, 400]


def test_the_jax_peer_without_sbx_names_the_package_to_install(monkeypatch):
    from benchmarks.runner.algos import register_external

    monkeypatch.setitem(sys.modules, "sbx", None)  # import sbx now raises ImportError
    monkeypatch.setenv("XLA_FLAGS", "")  # register_external sets it where unset: kept out of this process's environment
    with pytest.raises(ImportError, match=r"sbx-rl's CrossQ: pip install sbx-rl"):
        register_external("sbx_crossq")
    register_external("sac")  # the zoo's own algorithms: nothing to register


def test_step_budget_suite_refuses_an_episode_budget(tmp_path):
    with pytest.raises(ValueError, match="100000 env steps, not episodes"):
        sweeps.sweep(suite="mujoco100k", episodes=3, envs=["Hopper-v5"], results_dir=tmp_path, verbose=0)


def test_slow_env_benchmark_runs_resumes_and_reports(tmp_path, capsys):
    from benchmarks.studies import slow_env

    args = ["--envs", "Pendulum-v1", "--delays", "0.0005", "--seeds", "0", "--episodes", "2", "--output", str(tmp_path)]
    slow_env.main([*args, "--rows", "denfac_n1", "denfac_n2_async", "sac_n4"])
    runs = [json.loads(line) for line in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert [r["row"] for r in runs] == ["denfac_n1", "denfac_n2_async", "sac_n4"]
    for run in runs:
        assert len(run["returns"]) >= 2 and run["evaluations"] and run["wall"] > 2 * 200 * 0.0005
        assert run["evaluations"][-1]["episodes"] == len(run["returns"])
    assert runs[0]["evaluations"][0]["episodes"] == 1 and runs[1]["evaluations"][0]["episodes"] == 2  # both envs at once
    slow_env.main([*args, "--rows", "denfac_n1"])  # done already: skipped
    assert len((tmp_path / "runs.jsonl").read_text().splitlines()) == 3
    report = (tmp_path / "slow_env.md").read_text()
    assert "| DENFAC, 2 envs, async |" in report and "predict() latency" in report and "0 of 1" in report
