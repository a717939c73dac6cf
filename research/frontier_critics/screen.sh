#!/usr/bin/env bash
# The screen: each ingredient alone on rho2 (and the soft actor with DroQ's critic), Hopper-v5 and Walker2d-v5 at 100k
# env steps, seeds 0 and 1, two workers, in order of what the preset's decision needs first.
# Resumable: a rerun skips the (row, env, seed) cells already in runs_<worker>.jsonl (a run cut off is rerun whole).
cd "$(dirname "$0")/../.."
probe() { .venv/bin/python -m research.mujoco100k.probe --rows-file research/frontier_critics/rows.yml \
  --out "research/frontier_critics/runs_$1.jsonl" "${@:2}"; }
{
  probe a --rows crossq --envs Hopper-v5 Walker2d-v5 --seeds 0 1
  probe a --rows droq --envs Hopper-v5 Walker2d-v5 --seeds 1
  probe a --rows resets --envs Hopper-v5 Walker2d-v5 --seeds 1
} > research/frontier_critics/logs/worker_a.log 2>&1 &
{
  probe b --rows soft_rho2 soft_droq --envs Hopper-v5 --seeds 0
  probe b --rows droq redq5 --envs Hopper-v5 Walker2d-v5 --seeds 0
  probe b --rows simba --envs Hopper-v5 Walker2d-v5 --seeds 0
} > research/frontier_critics/logs/worker_b.log 2>&1 &
wait
