"""The reports of a study's runs: tables, rliable statistics and verdicts, figures, one report per suite; the
step-budget (MuJoCo at 100k), goal-conditioned and ablation reports; the README's answer. Each reads the runs file
that ``benchmarks.runner`` writes and imports nothing of ``benchmarks.studies``.
"""
