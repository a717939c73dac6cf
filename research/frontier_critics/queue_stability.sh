#!/usr/bin/env bash
# What holds the candidate's gait, and its CPU without Algorithm 1's floor (rows.yml: soft_wide15_*): Hopper-v5 and
# Walker2d-v5 at 100k env steps, seed 0 then 1, in order of what the preset's decision needs first. $1: the worker
# (a or b, its runs file runs_<worker>.jsonl); $2...: the rows (default: all five, the candidate's own probe first).
# Resumable: a rerun skips the (row, env, seed) cells already in the runs file (a run cut off is rerun whole).
cd "$(dirname "$0")/../.."
worker=$1; shift
rows=${*:-soft_wide15 soft_wide15_nofloor soft_wide15_beta05 soft_wide15_delay3 soft_wide15_lr3e4}
for seed in 0 1; do
  for row in $rows; do
    OMP_NUM_THREADS=1 .venv/bin/python -m research.mujoco100k.probe --rows-file research/frontier_critics/rows.yml \
      --out "research/frontier_critics/runs_$worker.jsonl" --rows "$row" --envs Hopper-v5 Walker2d-v5 --seeds "$seed"
  done
done
