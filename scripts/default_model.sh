#!/usr/bin/env bash
# Reproduces the shipped default model and the README section "Default model": dataset, GAN,
# baseline, loss ablation, trivial references, evaluation on the test split, export into the package.
# About 3 hours on the 2-core CPU machine this project was developed on (no GPU).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
OUT=logs/default_model
BASELINE=(model=deschaintre2018 model.generator.levels=7 loss=supervised)
# Grid samples, fixed before training: the first crop of the first test material of every family.
GRID='[test-m000008-c0-r0,test-m000020-c0-r0,test-m000029-c0-r0,test-m000031-c0-r0,test-m000033-c0-r0,test-m000066-c0-r0,test-m000067-c0-r0,test-m000082-c0-r0]'

$PY generate.py dataset_spec=default_model                               # 672 samples, ~4.5 min
# The GAN and the baseline: same data and batches of 4 × 128² crops, one thread each; 5 epochs
# (1 750 batches), then both resumed to 8 epochs (the schedule follows the new length).
OMP_NUM_THREADS=1 $PY train.py experiment=default_model hydra.run.dir=$OUT/gan &
OMP_NUM_THREADS=1 $PY train.py experiment=default_model "${BASELINE[@]}" hydra.run.dir=$OUT/baseline &
wait
for run in gan baseline; do
    extra=(); [ $run = baseline ] && extra=("${BASELINE[@]}")
    OMP_NUM_THREADS=1 $PY train.py experiment=default_model "${extra[@]}" trainer.max_epochs=8 \
        ckpt_path=$OUT/$run/checkpoints/last.ckpt hydra.run.dir=$OUT/$run &
done
wait
# Stage 2: the GAN fine-tuned with the parameter and rendering losses only (2 100 batches); the
# baseline resumed to the same total number of batches (2 450 + 2 100 = 4 550 = 13 epochs).
OMP_NUM_THREADS=2 $PY train.py experiment=default_model_finetune hydra.run.dir=$OUT/gan_finetune
OMP_NUM_THREADS=2 $PY train.py experiment=default_model "${BASELINE[@]}" trainer.max_epochs=13 \
    ckpt_path=$OUT/baseline/checkpoints/last.ckpt hydra.run.dir=$OUT/baseline
# The five loss variants with the same smaller budget (250 batches each), three seeds (the seed
# sets the initialisation, the rendering-loss draws and the data order).
OMP_NUM_THREADS=2 $PY train.py -m experiment=default_model loss=full,no_adv,no_feat,no_param,no_render \
    seed=0,1,2 'data.seed=${seed}' trainer.max_epochs=1 data.epoch_samples=1000 \
    task_name=default_model_ablation hydra.sweep.dir=$OUT/ablation
$PY -m brdfgan.report $OUT/ablation --out $OUT/ablation_report
$PY -m brdfgan.cli references data/default_model --out $OUT/references
$PY evaluate.py data=default_model split=test grid_keys="$GRID" metrics.downscale_to=128 hydra.run.dir=$OUT/evaluation \
    "ckpt={shipped: $OUT/gan_finetune/checkpoints/last.ckpt, gan_stage1: $OUT/gan/checkpoints/last.ckpt, baseline: $OUT/baseline/checkpoints/last.ckpt, mean_maps: $OUT/references/mean_maps.safetensors, photo_basecolor: $OUT/references/photo_basecolor.safetensors}"
$PY scripts/grid_figure.py $OUT/evaluation docs/default_model_grid.png --models shipped gan_stage1 baseline --panel 80
$PY -m brdfgan.cli export-weights $OUT/gan_finetune --out src/brdfgan/weights/default.safetensors \
    --model-id brdfgan-default-v2 --metrics $OUT/evaluation/metrics.json --metrics-model shipped \
    --hardware "2 vCPU x86_64 (no GPU); stage 1: 1 thread, shared with the baseline run; stage 2: 2 threads"
$PY -m tests.test_shipped_weights                                        # refresh the stored statistics
