#!/usr/bin/env bash
# How much do the surrogates' accuracies move with the training seed? For each SEED given,
# train a teacher and compress a PicoPINN from it exactly as models/regenerate.sh does (same
# data, the seed in place of 0), evaluate both on the test split, and print the ratios
# PicoPINN / teacher side by side (docs/surrogates.md, "Seed scatter").
#
#   scripts/seed_scatter.sh [--set full_size] [--data DIR] [--out DIR] SEED...
#
# The data folder is the shipped models' (runs/surrogates/<set>/data, made by
# models/regenerate.sh); DATA and OUT are relative to the repository's root. Seed 0 is the shipped pair: its evaluation is read from
# models/<set>/eval.json instead of being trained again. One torch thread per run; about
# 10 min per seed at full size on the 2-core VM. Each seed also writes
# OUT/models_s<SEED>/<set>/{pinn,picopinn}.safetensors, a models folder for the closed loop
# (the other set linked to the shipped models until a run for it fills it in):
#   ./target/release/examples/episodes '{"preset":"picopinn","clock":"simulated","models_dir":"OUT/models_s1"}' 0 2048
# PYTHON and PICOPIT override the interpreter and the command line (default: the .venv's).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
SET=full_size
DATA=""
OUT=runs/seed-scatter
SEEDS=()
while [ $# -gt 0 ]; do
    case "$1" in
        --set|--data|--out)
            [ $# -ge 2 ] || { echo "seed_scatter.sh: $1 needs a value" >&2; exit 2; }
            case "$1" in --set) SET="$2" ;; --data) DATA="$2" ;; --out) OUT="$2" ;; esac
            shift 2 ;;
        -h|--help) sed -n 2,16p "$0"; exit 0 ;;
        -*) echo "seed_scatter.sh: unknown option $1" >&2; exit 2 ;;
        *) [[ "$1" =~ ^[0-9]+$ ]] || { echo "seed_scatter.sh: a seed is a non-negative integer, got '$1'" >&2; exit 2; }
           SEEDS+=("$((10#$1))"); shift ;;
    esac
done
[ ${#SEEDS[@]} -gt 0 ] || { echo "usage: scripts/seed_scatter.sh [--set SET] [--data DIR] [--out DIR] SEED..." >&2; exit 2; }
case "$SET" in full_size) OTHER=half_scale ;; half_scale) OTHER=full_size ;;
    *) echo "seed_scatter.sh: --set is full_size or half_scale, got '$SET'" >&2; exit 2 ;; esac
DATA="${DATA:-runs/surrogates/$SET/data}"
PYTHON="${PYTHON:-.venv/bin/python}"
PICOPIT="${PICOPIT:-.venv/bin/picopit}"
if [[ " ${SEEDS[*]} " =~ \ [1-9][0-9]*\  ]]; then  # some seed to train
    [ -f "$DATA/manifest.json" ] || { echo "seed_scatter.sh: no datagen folder at $DATA (run models/regenerate.sh $SET first)" >&2; exit 2; }
    [ -x "$PICOPIT" ] || { echo "seed_scatter.sh: $PICOPIT missing (run scripts/setup.sh)" >&2; exit 2; }
fi
export PICOPIT_THREADS="${PICOPIT_THREADS:-1}"
EVALS=()
for seed in "${SEEDS[@]}"; do
    if [ "$seed" = 0 ]; then
        EVALS+=("models/$SET/eval.json")
        continue
    fi
    run="$OUT/$SET/s$seed"
    dst="$OUT/models_s$seed"
    # The other set links to the shipped models unless a run for it filled it already; a link
    # left for this set by such a run is replaced, never written through into models/.
    [ -L "$dst/$SET" ] && rm "$dst/$SET"
    mkdir -p "$run" "$dst/$SET"
    [ -e "$dst/$OTHER" ] || ln -s "$(pwd)/models/$OTHER" "$dst/$OTHER"
    "$PICOPIT" train --data "$DATA" --out "$run/train" --model "$dst/$SET/pinn.safetensors" --seed "$seed" --no-progress
    "$PICOPIT" compress --teacher "$dst/$SET/pinn.safetensors" --data "$DATA" --out "$run/compress" \
        --model "$dst/$SET/picopinn.safetensors" --seed "$seed" --no-progress
    "$PICOPIT" eval-surrogates --data "$DATA" --pinn "$dst/$SET/pinn.safetensors" \
        --picopinn "$dst/$SET/picopinn.safetensors" --out "$run/eval" --json "$run/eval.json" --no-progress
    EVALS+=("$run/eval.json")
done
"$PYTHON" - "${SEEDS[@]}" -- "${EVALS[@]}" <<'EOF'
import json, sys
args = sys.argv[1:]
cut = args.index("--")
seeds, files = args[:cut], args[cut + 1:]
rows = [("one-step heading (mrad)", "heading_rmse_rad", 1e3, "{:.3f}"),
        ("2 s rollout heading (rad)", "rollout_heading_rmse_rad", 1, "{:.4f}"),
        ("2 s rollout position (m)", "rollout_position_rmse_m", 1, "{:.3f}"),
        ("speed error at 2 s (m/s)", "rollout_final_speed_rmse_mps", 1, "{:.3f}")]
print("| seed | " + " | ".join(f"{r[0]}: teacher / PicoPINN (ratio)" for r in rows) + " |")
print("|---" * (len(rows) + 1) + "|")
for seed, f in zip(seeds, files):
    try:
        with open(f) as fh:
            m = json.load(fh)["models"]
        m["pinn"], m["picopinn"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        sys.exit(f"seed_scatter.sh: {f}: not an eval-surrogates JSON with models.pinn and models.picopinn ({e!r})")
    cells = []
    for _, key, scale, fmt in rows:
        t, p = m["pinn"].get(key), m["picopinn"].get(key)
        cells.append("–" if t is None or p is None
                     else f"{fmt.format(t * scale)} / {fmt.format(p * scale)} ({p / t:.2f}×)")
    print(f"| {seed} | " + " | ".join(cells) + " |")
EOF
