#!/usr/bin/env bash
# The screen: each ingredient alone on rho2, Hopper-v5 and Walker2d-v5 at 100k env steps, seeds 0 and 1, two workers.
# Resumable: a rerun skips the (row, env, seed) cells already in runs.jsonl (a run cut off is rerun whole).
cd "$(dirname "$0")/../.."
probe() { .venv/bin/python -m research.mujoco100k.probe --rows-file research/frontier_critics/rows.yml \
  --envs Hopper-v5 Walker2d-v5 --seeds 0 1 --out "research/frontier_critics/runs_$1.jsonl" --rows "${@:2}"; }
probe a crossq resets > research/frontier_critics/logs/worker_a.log 2>&1 &
probe b droq redq5 > research/frontier_critics/logs/worker_b.log 2>&1 &
wait
