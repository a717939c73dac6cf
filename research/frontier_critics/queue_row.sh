#!/usr/bin/env bash
# One mujoco100k row's cells, 5 seeds, in the committed study (resumable: a rerun skips finished cells and resumes a
# checkpointed one). $1: a PID to wait for (or 0); $2: the row (benchmarks/runner/algos.py); the rest: this worker's envs.
cd "$(dirname "$0")/../.."
while [ "$1" != 0 ] && kill -0 "$1" 2>/dev/null; do sleep 20; done
OMP_NUM_THREADS=1 .venv/bin/python -m benchmarks.run --suite mujoco100k --algos "$2" --envs "${@:3}" \
  --seeds 0 1 2 3 4 --results benchmarks/results/mujoco100k --workers 0 --no-analysis
