#!/usr/bin/env bash
# GPU readiness check (research/gpu_check.py): the paper configuration's training step on CUDA in
# bf16-mixed and fp32, the rendering loss's share, peak memory, throughput,
# experiment=anchored_rendered on photos rendered on the GPU each batch (data=rendered), DDP with
# 2+ GPUs.
# Unattended, under 8 minutes, no network, no Mitsuba. The table goes to stdout and $OUT/gpu_check.md.
#
#   research/gpu_check.sh                      # on a CUDA machine
#   research/gpu_check.sh --device cpu --tiny  # the CPU smoke mode (seconds)
#
# Uses .venv (make setup) when there is one, else python3 with the repo's src/ on PYTHONPATH.
#
# On the lent GPU machine (kind nvidia-h200: Python 3.12, torch 2.11, Lightning 2.6.6, no network),
# first run research/fetch_device_wheels.sh here (once; it fills the git-ignored .whl/, ~15 MiB,
# with the packages train.py needs that the machine lacks: hydra-core, omegaconf,
# antlr4-python3-runtime, webdataset, braceexpand, kornia, kornia_rs, OpenEXR, zstandard), then
# call the device tool's run with carry: [".whl"], timeout_s: 540 (the default --budget of 480 s,
# plus imports and the install) and the command:
#
#   python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site || exit; research/gpu_check.sh
#
# .venv is not carried, so this uses the machine's python3 (the one with torch) and PYTHONPATH
# becomes src:<repo>:/tmp/site. To keep device time for a rerun, pass e.g. --budget 360 with
# timeout_s: 420.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -x .venv/bin/python ]; then PY=.venv/bin/python; else PY=python3; fi
export PYTHONPATH="$PWD/src:$PWD${PYTHONPATH:+:$PYTHONPATH}"
export PYTHONUNBUFFERED=1
exec "$PY" -m research.gpu_check "$@"
