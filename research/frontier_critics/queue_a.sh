#!/usr/bin/env bash
# Worker a's queue after CrossQ's second seed: the soft actor with CrossQ's critic, then DroQ's second seed.
cd "$(dirname "$0")/../.."
while kill -0 "$1" 2>/dev/null; do sleep 20; done  # the run in flight
probe() { .venv/bin/python -m research.mujoco100k.probe --rows-file research/frontier_critics/rows.yml \
  --out "research/frontier_critics/runs_$1.jsonl" "${@:2}"; }
{
  probe a --rows soft_crossq --envs Hopper-v5 Walker2d-v5 --seeds 0
  probe a --rows droq --envs Hopper-v5 Walker2d-v5 --seeds 1
  probe a --rows resets --envs Hopper-v5 Walker2d-v5 --seeds 1
} >> research/frontier_critics/logs/worker_a.log 2>&1
