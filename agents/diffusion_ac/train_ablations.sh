#!/usr/bin/env bash
# Table 3 ablations of Diffusion-AC at an equal, short budget (BUDGET transitions each, seed 1),
# plus the full method at the same budget, one after the other: the 100k runs of cdr-bench 0.3
# (ablations/<name>-100k.*, kept for the history and the fast-policy tests). The leaderboard's
# Table 3 is trained at the reference budget, three seeds each, by sweeps/table3.yaml. Writes runs/abl-<name>/ and
# copies each checkpoint and training log to agents/diffusion_ac/ablations/<name>-<budget>.*
# Usage: [PYTHON=.venv/bin/python] bash agents/diffusion_ac/train_ablations.sh [BUDGET [NAME ...]]
# (default 100000 and all five)
set -euo pipefail
cd "$(dirname "$0")/../.."
budget=${1:-100000}
tag=$((budget / 1000))k
names=("${@:2}")
[ ${#names[@]} -eq 0 ] && names=(full no-diffusion no-double-q no-dpsc no-value-guidance)
for name in "${names[@]}"; do
    ablation=$name
    extra=()
    [ "$name" = full ] && ablation=none
    # Table 3: "W/O DPSC ... trained from the outset using the most challenging, high-density
    # scenarios and the full set of penalties".
    [ "$name" = no-dpsc ] && extra=(--scenario high)
    run=runs/abl-$name-$tag
    OMP_NUM_THREADS=1 "${PYTHON:-python}" -m cdr_bench train diffusion-ac --run-dir "$run" --seed 1 \
        --total-steps "$budget" --tau-start 0.2 --tau-end 0.05 --ablation "$ablation" \
        --eval-episodes 100 --no-progress "${extra[@]}" > "$run.out" 2>&1
    cp "$run/checkpoint.pt" "agents/diffusion_ac/ablations/$name-$tag.pt"
    gzip -9nc "$run/log.jsonl" > "agents/diffusion_ac/ablations/$name-$tag.log.jsonl.gz"
done
