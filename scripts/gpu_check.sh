#!/usr/bin/env bash
# GPU readiness check (scripts/gpu_check.py): the paper configuration's training step on CUDA in
# bf16-mixed and fp32, the rendering loss's share, peak memory, throughput, DDP with 2+ GPUs.
# Unattended, under 8 minutes, no network, no Mitsuba. The table goes to stdout and $OUT/gpu_check.md.
#
#   scripts/gpu_check.sh                      # on a CUDA machine
#   scripts/gpu_check.sh --device cpu --tiny  # the CPU smoke mode (seconds)
#
# Uses .venv (make setup) when there is one, else python3 with the repo's src/ on PYTHONPATH.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -x .venv/bin/python ]; then PY=.venv/bin/python; else PY=python3; fi
export PYTHONPATH="$PWD/src:$PWD${PYTHONPATH:+:$PYTHONPATH}"
export PYTHONUNBUFFERED=1
exec "$PY" -m scripts.gpu_check "$@"
