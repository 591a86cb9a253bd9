#!/usr/bin/env bash
# Regenerate the shipped surrogates: for each parameter set, collision data from the plant,
# the teacher PINN, PicoPINN and the evaluation. Intermediate outputs (data, checkpoints,
# curves) go to runs/surrogates/<set>; the model files, the evaluation JSON/Markdown and the
# small figures are copied into models/<set>. Seeds are fixed: the same tree gives the same
# files up to float rounding (PyTorch CPU, PICOPIT_THREADS threads; a re-run differed by at most
# 4e-13 in theta, every evaluation figure the same). Usage: models/regenerate.sh [full_size] [half_scale]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
SEED="${SEED:-0}"
# One torch thread: on the shared 2-core machine two threads ran ~1.6x (and, next to one busy
# compile, ~10x) slower than one; unloaded they gain ~15 %. See docs/surrogates.md.
export PICOPIT_THREADS="${PICOPIT_THREADS:-1}"
EPISODES="${EPISODES:-2500}"
SETS=("$@")
[ ${#SETS[@]} -eq 0 ] && SETS=(full_size half_scale)
for set in "${SETS[@]}"; do
    run="runs/surrogates/$set"
    dst="models/$set"
    mkdir -p "$run" "$dst"
    picopit datagen --params "$set" --episodes "$EPISODES" --seed "$SEED" --out "$run/data" --no-progress
    picopit train --data "$run/data" --out "$run/train" --model "$dst/pinn.safetensors" --seed "$SEED" --no-progress
    picopit compress --teacher "$dst/pinn.safetensors" --data "$run/data" --out "$run/compress" \
        --model "$dst/picopinn.safetensors" --seed "$SEED" --no-progress
    picopit eval-surrogates --data "$run/data" --pinn "$dst/pinn.safetensors" \
        --picopinn "$dst/picopinn.safetensors" --out "$run/eval" --json "$dst/eval.json" --no-progress
    cp "$run/data/manifest.json" "$dst/data_manifest.json"
    cp "$run/eval/eval.md" "$dst/eval.md"
    mkdir -p "$dst/figures"
    cp "$run/train/train_curves.png" "$run/compress/cluster_threshold.png" \
       "$run/compress/retrain_curves.png" "$run/eval/eval.png" "$dst/figures/"
done
