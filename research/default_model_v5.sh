#!/usr/bin/env bash
# Reproduces the v5 candidate (issue 46) and its measurements (research/notes/2026-12-v5-candidate.md): stage 1
# (experiment=anchored_rendered: photos rendered on the fly, no training set to generate), stage 2
# on whole 256² photos (experiment=anchored_rendered_fixres), the normals' learning curve, and the
# evaluation on the validation split's two parts, the procedural and scan test sets and both OOD
# variants beside v4 and the trivial references; export_weights ships it. One training at a time on the two threads.
#
#   research/default_model_v5.sh [final|fixres|normal_curve|evaluate|ablation|shading_curve|relief_light|export_weights]...
#   (default: final fixres normal_curve evaluate, in order; SEEDS="1" runs one seed per session)
#
# Long trainings resume: rerunning a stage continues each unfinished run from its last.ckpt.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
export OMP_NUM_THREADS=2
OUT=logs/v5
RUNS_OUT=$OUT/height  # the stages' runs of today's recipe (logs/v5/final_seed0, fixres_seed0: the first recipe's)
REF=src/brdfgan/weights/references
SHIPPED=$RUNS_OUT/fixres_seed0  # the run a v5 release is exported from (stage 2, seed 0)

resume() {  # the checkpoint to resume a run folder from, if any
  [ -f "$1/checkpoints/last.ckpt" ] && echo "ckpt_path=$1/checkpoints/last.ckpt" || true
}

final() {  # stage 1 (conf/experiment/anchored_rendered.yaml), 6 000 batches of 4 rendered 128² crops, ~85 min each
  for seed in ${SEEDS:-0 1}; do
    $PY train.py experiment=anchored_rendered test=false seed=$seed hydra.run.dir=$RUNS_OUT/final_seed$seed \
      $(resume $RUNS_OUT/final_seed$seed)
  done
}

fixres() {  # stage 2 (conf/experiment/anchored_rendered_fixres.yaml): each stage-1 run on whole 256² photos
  for seed in ${SEEDS:-0 1}; do
    $PY train.py experiment=anchored_rendered_fixres init_from=$RUNS_OUT/final_seed$seed/checkpoints/last.ckpt test=false \
      seed=$seed hydra.run.dir=$RUNS_OUT/fixres_seed$seed $(resume $RUNS_OUT/fixres_seed$seed)
  done
}

normal_curve() {  # validation normal angle through both stages (v4 ended at 7.91°, a flat map 7.95°)
  local runs=() seed
  for seed in 0 1; do
    [ -d $RUNS_OUT/final_seed$seed ] && runs+=("seed $seed=$RUNS_OUT/final_seed$seed+$RUNS_OUT/fixres_seed$seed")
  done
  $PY -m scripts.learning_curve "${runs[@]}" --metric val/normal_angle_deg --reference "flat map=7.95" \
    --out $RUNS_OUT/normal_curve
  cp $RUNS_OUT/normal_curve.png docs/default_model_v5_normal_curve.png  # the table is in research/notes/2026-12-v5-candidate.md
}

evaluate() {  # validation parts, test sets, both OOD variants: the v5 runs there are, v4, the references
  local models="v4: $V4" run
  # Today's recipe's runs, and the first recipe's stage 2 (v5_first) beside them.
  declare -A RUNS=([v5]=$RUNS_OUT/fixres_seed0 [v5_seed1]=$RUNS_OUT/fixres_seed1 [v5_stage1]=$RUNS_OUT/final_seed0
                   [v5_stage1_seed1]=$RUNS_OUT/final_seed1 [v5_first]=$OUT/fixres_seed0)
  for run in v5 v5_seed1 v5_stage1 v5_stage1_seed1 v5_first; do  # those that have finished (the machine may be new)
    if [ -f "${RUNS[$run]}/checkpoints/last.ckpt" ]; then
      models="$models, $run: ${RUNS[$run]}/checkpoints/last.ckpt"
    fi
  done
  models="$models, mean_maps: $REF/mean_maps.safetensors, photo_basecolor: $REF/photo_basecolor.safetensors"
  models="$models, de_lit: $REF/de_lit.safetensors"
  score "$models" $RUNS_OUT/eval_ "" ood ${SPLITS:-val test}
}

score() {  # score MODELS PREFIX SUFFIX OOD SPLIT...: "ckpt={MODELS}" on each split's two parts and,
  # OOD non-empty, both OOD variants; each set's results in PREFIX<set>SUFFIX
  local models=$1 prefix=$2 suffix=$3 ood=$4 split part
  shift 4
  for split in "$@"; do
    for part in procedural scans; do
      $PY evaluate.py data=procedural_and_scans data.data_dir=data/procedural_and_scans_${split}_$part \
        data.prepare=null grid_samples=0 hydra.run.dir=$prefix${split}_$part$suffix "ckpt={$models}"
    done
  done
  if [ -n "$ood" ]; then
    $PY generate.py dataset_spec=ood progress=false
    $PY generate.py dataset_spec=ood_close progress=false
    $PY evaluate.py data=ood grid_samples=0 hydra.run.dir=${prefix}ood_standard$suffix "ckpt={$models}"
    $PY evaluate.py data=ood_close grid_samples=0 hydra.run.dir=${prefix}ood_close$suffix "ckpt={$models}"
  fi
}

export_weights() {
  $PY -m brdfgan.cli export-weights $SHIPPED --out src/brdfgan/weights/default.safetensors \
    --model-id brdfgan-default-v5 --metrics $RUNS_OUT/eval_test_procedural/metrics.json --metrics-model v5 \
    --hardware "2 vCPU x86_64 (no GPU), 2 threads, one training at a time"
  $PY -m tests.inference.model.test_shipped_weights  # refresh the stored statistics
}

ablation() {  # what costs v5 its base colour: v4's recipe, then one of v5's changes added at a time
  # (rendered photos with the calibrated sensor; + relief sampling; + no shading image = the first
  # v5 recipe), then the height head and the slope term (today's experiment=anchored_rendered), 1 000
  # batches each, scored on the validation split's two parts (research/notes/2026-12-v5-candidate.md). ROWS picks
  # rows (default all), SEED another seed (its runs are <row>_seed<SEED>), EVAL the scores' folders.
  local seed=${SEED:-0} suffix=""
  [ "$seed" = 0 ] || suffix=_seed$seed
  local steps="data.epoch_samples=2000 trainer.max_epochs=2 trainer.check_val_every_n_epoch=2 test=false seed=$seed"
  # Each row in today's experiment=anchored_rendered and explicit overrides, so the rows stay what they were
  # when the recipe moves on.
  local slopes="experiment=anchored_rendered model.generator.normal_head=slopes loss.normal_tilt_weight=0"
  local relief="data.relief.swap_probability=0.25 data.relief.bump_probability=0.5"
  declare -A RUNS=(
    [v4_recipe]="experiment=anchored data.prepare=null"  # the training shards there are (a session cannot wait for all 63)
    [rendered]="$slopes"
    [rendered_relief]="$slopes $relief"
    [v5_recipe]="$slopes $relief model.generator.shading=none"  # the first v5 recipe
    # The normals as a height's differences (integrable slopes; research/notes/2026-12-relief-investigation.md, "(e)"),
    [rendered_height]="experiment=anchored_rendered loss.normal_tilt_weight=0"
    # and a squared slope error beside the angle (the angle alone is minimised by a flat map
    # where a tilt is uncertain; research/notes/2026-12-default-model-v3.md): today's experiment=anchored_rendered.
    [rendered_height_tilt]="experiment=anchored_rendered"
    # Each with a quarter of the crops' own relief removed: a texture over a flat surface, where
    # every model drew relief on the near-flat held-out scans (research/notes/2026-12-v5-candidate.md).
    [rendered_height_flat]="experiment=anchored_rendered loss.normal_tilt_weight=0 data.relief.flat_probability=0.25"
    [rendered_height_tilt_flat]="experiment=anchored_rendered data.relief.flat_probability=0.25"
    # Half of the crops' relief turned inside out: whether dark is low is then not in the base
    # colour (the training scans disagree on it; research/notes/2026-12-relief-investigation.md), only in the photo's shading.
    [rendered_height_invert]="experiment=anchored_rendered loss.normal_tilt_weight=0 data.relief.invert_probability=0.5"
    # and with half of the base colours faded besides: relief shading under a plain albedo, which
    # the issue's scratch harness learned from (research/notes/2026-12-relief-investigation.md, "(d)").
    [rendered_height_invert_plain]="experiment=anchored_rendered loss.normal_tilt_weight=0 data.relief.invert_probability=0.5 data.relief.plain_albedo_probability=0.5"
    # Shading first: the normals trained alone on those photos (experiment=anchored_rendered_normals), which
    # read some relief from the shading where the full recipe reads none; then the inverted row's
    # recipe starting from its weights, so the whole generator learns on with that reading.
    [shading_first]="experiment=anchored_rendered_normals"
    # The same on photos without room light, validated on the validation split re-generated
    # without it (relief_light makes it and scores this row; research/notes/2026-12-relief-investigation.md "(h)").
    [shading_noenv]="experiment=anchored_rendered_normals data.data_dir=data/pas_noenv data.prepare.spec.lighting.env_to_flash_min=1e-6 data.prepare.spec.lighting.env_to_flash_max=1e-6"
    [rendered_height_invert_after_shading]="experiment=anchored_rendered loss.normal_tilt_weight=0 data.relief.invert_probability=0.5 init_from=$OUT/ablation/shading_first$suffix/checkpoints/last.ckpt"
    # v4 itself (both stages) trained on for 1 000 batches of rendered photos at stage 2's rate:
    # whether the fresh light of every draw (room light, exposure, the phone) teaches v4's
    # roughness and metal without costing the base colour it learned from the Mitsuba shards,
    # and the same with half the relief inverted (no dark-is-low prior to pick up on the way).
    [v4_then_rendered]="$slopes init_from=$V4 model.optimizer.lr=1e-4"
    [v4_then_rendered_invert]="$slopes init_from=$V4 model.optimizer.lr=1e-4 data.relief.invert_probability=0.5"
    # A curriculum for reading relief from shading: the normals alone first on photos whose base
    # colour is faded on every crop (contrast uniform in [0, 1): mostly plain, where the issue's
    # harness learned relief best), then shading_first's photos from those weights.
    [shading_plain]="experiment=anchored_rendered_normals data.relief.plain_albedo_probability=1.0"
    [shading_after_plain]="experiment=anchored_rendered_normals init_from=$OUT/ablation/shading_plain$suffix/checkpoints/last.ckpt"
    # Capacity: shading_first at twice the width (four times the weights; the GPU plan's
    # network), the same 1 000 batches: whether a larger network reads more of the shading
    # from the same photos.
    [shading_wide]="experiment=anchored_rendered_normals model.generator.width=32"
  )
  local run models="v4: $V4, mean_maps: $REF/mean_maps.safetensors"  # the shipped model and the flat, constant reference beside every row
  for run in ${ROWS:-v4_recipe rendered rendered_relief v5_recipe rendered_height rendered_height_tilt rendered_height_flat rendered_height_tilt_flat rendered_height_invert rendered_height_invert_plain shading_first rendered_height_invert_after_shading v4_then_rendered v4_then_rendered_invert shading_plain shading_after_plain shading_wide}; do
    [ -f $OUT/ablation/$run$suffix/checkpoints/last.ckpt ] ||
      $PY train.py ${RUNS[$run]} $steps hydra.run.dir=$OUT/ablation/$run$suffix
    models="$models, $run$suffix: $OUT/ablation/$run$suffix/checkpoints/last.ckpt"
  done
  # Chosen on validation; HELD_OUT=1 also scores the test split's parts and both OOD variants,
  # to report (never to choose by). EVAL names the scores' folders (default eval: a later subset
  # of ROWS given its own name keeps the earlier scores).
  score "$models" $OUT/ablation/${EVAL:-eval}_ "$suffix" "${HELD_OUT:-}" val ${HELD_OUT:+test}
}

shading_curve() {  # the normals alone (experiment=anchored_rendered_normals) 8x as long: 8 000 batches of 4, 61 min,
  # validated every 2 000: whether more photos lift the slope cosine past the 1 000-2 000-batch
  # plateau (research/notes/2026-12-v5-candidate.md, "More photos"); scored beside v4 like an ablation row.
  local run=$OUT/shading_curve
  [ -f $run/.done ] || {
    $PY train.py experiment=anchored_rendered_normals data.epoch_samples=8000 trainer.max_epochs=4 \
      trainer.check_val_every_n_epoch=1 test=false hydra.run.dir=$run $(resume $run)
    touch $run/.done
  }
  score "v4: $V4, mean_maps: $REF/mean_maps.safetensors, shading_curve: $run/checkpoints/last.ckpt" \
    $OUT/shading_curve_ "" "${HELD_OUT:-}" val ${HELD_OUT:+test}
}

relief_light() {  # research/notes/2026-12-relief-investigation.md "(h)": what hides the flash's relief shading. The validation split and
  # the standard OOD variant re-generated without room light (and once with the camera square on),
  # each read with and without the evaluation sensor; relief_oracle --steps 0 scores only the
  # observation's correlation with the true relief shading (~5 min); then the fit on the photos
  # without room light (~20 min).
  local noenv="dataset_spec.lighting.env_to_flash_min=1e-6 dataset_spec.lighting.env_to_flash_max=1e-6"
  local square="dataset_spec.capture.tilt_max_deg=0 dataset_spec.capture.distance_min=1 dataset_spec.capture.distance_max=1"
  local part out=$OUT/relief_light scored="data=procedural_and_scans data.prepare=null"
  # validation_variant DIR OVERRIDES...: the validation split generated with OVERRIDES into DIR,
  # its two parts apart (DIR_val_procedural, DIR_val_scans)
  validation_variant() {
    [ -d $1_val_scans ] || {
      $PY generate.py dataset_spec=procedural_and_scans "${@:2}" out_dir=$1 progress=false contact_sheet=0 \
        "shard=[$(split_shards val)]"
      $PY -m scripts.source_subsets $1 --split val; }
  }
  validation_variant data/pas_noenv $noenv
  validation_variant data/pas_aligned $noenv $square
  [ -d data/ood_noenv/test ] || $PY generate.py dataset_spec=ood $noenv out_dir=data/ood_noenv progress=false contact_sheet=0
  # oracle NAME STEPS OVERRIDES...: one relief_oracle photo row at ridge 1 (kept if already there)
  oracle() { [ -f $out/$1.json ] || $PY -m research.relief_oracle --out $out/$1 --observations photo --ridge 1 --steps $2 "${@:3}"; }
  row() { oracle $1 0 "${@:2}"; }
  for part in procedural scans; do
    row val_${part}_photo $scored data.data_dir=data/procedural_and_scans_val_$part
    row val_${part}_nosensor $scored data.data_dir=data/procedural_and_scans_val_$part data.eval_sensor=null
    row val_${part}_noenv $scored data.data_dir=data/pas_noenv_val_$part
    row val_${part}_noenv_nosensor $scored data.data_dir=data/pas_noenv_val_$part data.eval_sensor=null
    row val_${part}_aligned_nosensor $scored data.data_dir=data/pas_aligned_val_$part data.eval_sensor=null
    # the fit of "(g)" on the photos without room light, the evaluation sensor kept
    oracle val_${part}_noenv_fit 200 $scored data.data_dir=data/pas_noenv_val_$part
  done
  row ood_photo data=ood
  row ood_nosensor data=ood data.eval_sensor=null
  row ood_noenv data=ood data.data_dir=data/ood_noenv data.prepare=null
  row ood_noenv_nosensor data=ood data.data_dir=data/ood_noenv data.prepare=null data.eval_sensor=null
  oracle ood_noenv_fit 200 data=ood data.data_dir=data/ood_noenv data.prepare=null  # ~15 min
  # The networks on the photos without room light: those of ROWS="shading_first shading_noenv"
  # ablation there are (shading_noenv trains on this stage's data: run the stage, then the ablation,
  # then the stage again to score it).
  local models="v4: $V4, mean_maps: $REF/mean_maps.safetensors" run
  for run in shading_first shading_noenv; do
    if [ -f $OUT/ablation/$run/checkpoints/last.ckpt ]; then
      models="$models, $run: $OUT/ablation/$run/checkpoints/last.ckpt"
    fi
  done
  for part in procedural scans; do
    $PY evaluate.py data=procedural_and_scans data.data_dir=data/pas_noenv_val_$part data.prepare=null grid_samples=0 \
      hydra.run.dir=$out/eval_val_${part}_noenv "ckpt={$models}"
  done
  $PY evaluate.py data=ood data.data_dir=data/ood_noenv data.prepare=null grid_samples=0 \
    hydra.run.dir=$out/eval_ood_standard_noenv "ckpt={$models}"
}

# v4, the model v5 is measured against, from the history (the release before v5).
V4=$OUT/v4.safetensors
mkdir -p $OUT
[ -f $V4 ] || git show 716491c:src/brdfgan/weights/default.safetensors > $V4
split_shards() {  # SPLIT: its shards' positions in generate.py's plan, comma-separated (only they are made)
  $PY generate.py dataset_spec=procedural_and_scans plan=true | awk -v s=$1 '$2 == s {printf "%s%s", sep, $1; sep=","}'
}
prepare() {  # the validation and test splits' Mitsuba photos (no training split), their two parts apart
  local split
  for split in ${SPLITS:-val test}; do
    if [ -z "$(ls data/procedural_and_scans/$split 2>/dev/null)" ]; then
      $PY generate.py dataset_spec=procedural_and_scans progress=false "shard=[$(split_shards $split)]"
    fi
    [ -d data/procedural_and_scans_${split}_scans ] || $PY -m scripts.source_subsets data/procedural_and_scans --split $split
  done
}
stages=("$@")
[ ${#stages[@]} -gt 0 ] || stages=(final fixres normal_curve evaluate)
for stage in "${stages[@]}"; do
  prepare
  "$stage"
done
