#!/usr/bin/env bash
# The figure3 suite's CrossQ cells on a lent GPU machine (one H200, 16 cores; the device tool's 10-minute command).
# Run from the repository root there, with the wheels the machine lacks in .whl/ (benchmarks/README.md, "On a GPU
# machine"). Three sweeps side by side, each seed its own process on the GPU, under one deadline: the small cells
# (Acrobot, the 75-decision Acrobot, CartPole), Half-Cheetah, and InvertedPendulum at a lower CPU priority (the longest
# runs: they take only the cores the others leave). Runs finished by the deadline land in runs.jsonl.gz; the progress
# files say how far the others got. Usage: run.sh OUT_DIR DEADLINE_SECONDS COMMIT [extra benchmarks.run arguments]
# (a rehearsal on a CPU machine: DEVICE=cpu WHEELS=<its own wheels> run.sh /tmp/out 120 HEAD --episodes 1).
set -u
out=$1 deadline=$2 commit=$3
shift 3
device=${DEVICE:-cuda}
started=$(date +%s)
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site "${WHEELS:-.whl}"/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD OMP_NUM_THREADS=1 PYTHONUNBUFFERED=1 BENCHMARK_GIT_COMMIT=$commit
export BENCHMARK_PROGRESS_DIR=/tmp/progress
mkdir -p "$BENCHMARK_PROGRESS_DIR" /tmp/r
nvidia-smi -L 2>/dev/null
# MPS lets the runs' small kernels share the GPU at once instead of taking turns; without it, the runs still work.
if nvidia-cuda-mps-control -d 2>/dev/null && python3 -c "import torch; torch.ones(1, device='cuda').sum().item()"; then
    echo "MPS on"
else
    echo quit | nvidia-cuda-mps-control 2>/dev/null
    echo "MPS off"
fi
left=$((deadline - ($(date +%s) - started) - 25))
echo "sweeps get ${left} s"
extra=("$@")
run() {  # niceness, name, then benchmarks.run arguments
    local niceness=$1 name=$2
    shift 2
    nice -n "$niceness" timeout "$left" python3 -m benchmarks.run --suite figure3 --algos crossq --device "$device" \
        --no-analysis --results /tmp/r/"$name" "$@" "${extra[@]}" > /tmp/r/"$name".log 2>&1 &
}
names="small cartpole halfcheetah invertedpendulum"
run 0 small --envs acrobot acrobot75 --workers 10
run 0 cartpole --envs cartpole --seeds 3 4 --workers 2  # seeds 0-2 ran on the CPU
run 0 halfcheetah --envs halfcheetah --workers 5
run 10 invertedpendulum --envs invertedpendulum --workers 5
tick=0
while [ -n "$(jobs -r)" ]; do
    sleep 5
    tick=$((tick + 1))
    [ $((tick % 6)) -ne 0 ] && continue
    echo "$(($(date +%s) - started)) s: $(cat /tmp/r/*.log | grep -c ' done ') runs done;" \
        "$(nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader 2>/dev/null)"
done
echo quit | nvidia-cuda-mps-control 2>/dev/null
for name in $names; do
    [ -f /tmp/r/$name/runs.jsonl.gz ] && cp /tmp/r/$name/runs.jsonl.gz "$out/$name.runs.jsonl.gz"
done
tar czf "$out/logs.tgz" -C /tmp progress $(cd /tmp && ls r/*.log r/*/sweeps.jsonl 2>/dev/null)
tail -n 3 /tmp/r/*.log
