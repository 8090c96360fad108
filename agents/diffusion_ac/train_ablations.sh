#!/usr/bin/env bash
# Table 3 ablations of Diffusion-AC at an equal, short budget (BUDGET transitions each, seed 1),
# plus the full method at the same budget, one after the other. Writes runs/abl-<name>/ and
# copies each checkpoint and training log to agents/diffusion_ac/ablations/<name>-<budget>.*
# Usage: [PYTHON=.venv/bin/python] bash agents/diffusion_ac/train_ablations.sh [BUDGET]  (default 100000)
set -euo pipefail
cd "$(dirname "$0")/../.."
budget=${1:-100000}
tag=$((budget / 1000))k
for name in full no-diffusion no-double-q no-dpsc no-value-guidance; do
    ablation=$name
    [ "$name" = full ] && ablation=none
    run=runs/abl-$name-$tag
    OMP_NUM_THREADS=1 "${PYTHON:-python}" -m cdr_bench train diffusion-ac --run-dir "$run" --seed 1 \
        --total-steps "$budget" --tau-start 0.2 --tau-end 0.05 --ablation "$ablation" \
        --eval-episodes 100 --no-progress > "$run.out" 2>&1
    cp "$run/checkpoint.pt" "agents/diffusion_ac/ablations/$name-$tag.pt"
    cp "$run/log.jsonl" "agents/diffusion_ac/ablations/$name-$tag.log.jsonl"
done
