#!/usr/bin/env bash
# The mujoco100k suite's row soft_crossq_wide, 5 seeds (queue_row.sh with that row). $1: a PID to wait for (or 0); the
# rest: the envs of this worker.
exec "$(dirname "$0")/queue_row.sh" "$1" soft_crossq_wide "${@:2}"
