#!/usr/bin/env bash
# Reproduces brdfgan-default-v3, the default model shipped before v4 (research/ keeps it as history;
# scripts/default_model_v4.sh reproduces the shipped one), and its measurements (research/notes/2026-12-default-model-v3.md):
# the v3 dataset, v3, a second seed of its recipe, the same-budget baseline, the trivial references, the evaluation on the
# procedural test split and on the out-of-distribution benchmark, the export into the package.
# One training at a time on the two threads (two side by side each ran at 40-60 % speed).
# About 2.5 hours on the 2-core CPU machine this project was developed on (no GPU); the
# equal-wall-time comparisons that chose the recipe are in research/notes/2026-12-default-model-v3.md, "How the v3 recipe was chosen" (logs/v3cmp).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
export OMP_NUM_THREADS=2
OUT=logs/default_model_v3
BASELINE=(model=deschaintre2018 model.generator.levels=7)
# Grid samples, fixed before v3 was evaluated: the first crop of the first test material of each
# of the first eight families in the test split's order.
GRID='[test-m000003-c0-r0,test-m000005-c0-r0,test-m000007-c0-r0,test-m000016-c0-r0,test-m000027-c0-r0,test-m000038-c0-r0,test-m000049-c0-r0,test-m000061-c0-r0]'
REF=src/brdfgan/weights/references

$PY generate.py dataset_spec=procedural                               # 1 200 materials, ~19 min
# v3: one stage, parameter + rendering losses (cross-entropy metallic, unit-z normal head),
# 30 epochs × 400 batches of 4 × 128² crops = 12 000 batches, ~75 min.
$PY train.py experiment=procedural test=false hydra.run.dir=$OUT/v3
# The baseline, Deschaintre et al. 2018 (width 16, 7 levels), same data, loss, crops, batches.
$PY train.py experiment=procedural seed=1 data.seed=1 test=false hydra.run.dir=$OUT/v3_seed1   # the spread
$PY train.py experiment=procedural "${BASELINE[@]}" test=false hydra.run.dir=$OUT/baseline
# v2, the previous shipped model, from the history, to compare against.
git show fb60550:src/brdfgan/weights/default.safetensors > $OUT/v2.safetensors
MODELS="v3: $OUT/v3/checkpoints/last.ckpt, v3_seed1: $OUT/v3_seed1/checkpoints/last.ckpt, v2: $OUT/v2.safetensors"
MODELS="$MODELS, baseline: $OUT/baseline/checkpoints/last.ckpt"
MODELS="$MODELS, mean_maps: $REF/mean_maps.safetensors, photo_basecolor: $REF/photo_basecolor.safetensors"
$PY evaluate.py data=procedural split=test grid_keys="$GRID" hydra.run.dir=$OUT/eval_test "ckpt={$MODELS}"
$PY generate.py dataset_spec=ood progress=false                          # the OOD photos (make ood)
$PY evaluate.py data=ood hydra.run.dir=$OUT/eval_ood "ckpt={$MODELS}"
$PY scripts/grid_figure.py $OUT/eval_test docs/default_model_grid.png --models v3 v2 baseline --panel 80
$PY -m brdfgan.cli export-weights $OUT/v3 --out src/brdfgan/weights/default.safetensors \
    --model-id brdfgan-default-v3 --metrics $OUT/eval_test/metrics.json --metrics-model v3 \
    --hardware "2 vCPU x86_64 (no GPU), 2 threads, one training at a time"
$PY -m tests.inference.model.test_shipped_weights  # refresh the stored statistics
