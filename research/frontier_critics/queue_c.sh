#!/usr/bin/env bash
# After worker a's chain ($1): the 256-wide critic at SAC's CPU on Ant-v5 (30k steps, seed 0).
cd "$(dirname "$0")/../.."
while kill -0 "$1" 2>/dev/null; do sleep 20; done
P=research/frontier_critics
for row in soft_crossq_w256_b64 soft_crossq_w256_b128_rho1; do
  OMP_NUM_THREADS=1 .venv/bin/python -m research.mujoco100k.probe --rows-file $P/rows.yml --rows $row --envs Ant-v5 \
    --seeds 0 --steps 30000 --eval-every 5000 --out $P/ant.jsonl --log $P/logs/ant
done >> $P/logs/worker_a.log 2>&1
