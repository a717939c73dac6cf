#!/usr/bin/env bash
# Worker b's queue after the soft actor's first Hopper run: the soft actor's rows on Walker2d-v5 and a second seed.
cd "$(dirname "$0")/../.."
while kill -0 "$1" 2>/dev/null; do sleep 20; done  # the run in flight
probe() { .venv/bin/python -m research.mujoco100k.probe --rows-file research/frontier_critics/rows.yml \
  --out "research/frontier_critics/runs_$1.jsonl" "${@:2}"; }
{
  probe b --rows soft_rho2 soft_droq --envs Walker2d-v5 --seeds 0
  probe b --rows soft_rho2 soft_droq --envs Hopper-v5 --seeds 1
  probe b --rows droq redq5 --envs Hopper-v5 Walker2d-v5 --seeds 0
  probe b --rows simba --envs Hopper-v5 Walker2d-v5 --seeds 0
} >> research/frontier_critics/logs/worker_b.log 2>&1
