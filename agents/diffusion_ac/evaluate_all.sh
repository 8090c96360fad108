#!/usr/bin/env bash
# Score the shipped Diffusion-AC checkpoint and its Table-3 ablations with the official scorer,
# then the multimodality analysis (Fig. 9) on the three tactical scenarios and the latency.
#
#   PYTHON=.venv/bin/python bash agents/diffusion_ac/evaluate_all.sh [main] [ablations] [analysis]
#
# With no argument all three parts run. Outputs (all deterministic for a given checkpoint):
#   eval/paper.json(.jsonl)                 checkpoint.pt on the paper suite (1000 episodes each)
#   eval/ablation-<name>.json(.jsonl)       ablations/<name>.pt on the paper suite
#   analysis/multimodal-<scenario>.json/.png (also agents/ppo/analysis/), analysis/latency.json/.md
set -euo pipefail
cd "$(dirname "$0")/../.."
py=${PYTHON:-python}
export OMP_NUM_THREADS=1
ag=agents/diffusion_ac
parts=("$@")
[ ${#parts[@]} -eq 0 ] && parts=(main ablations analysis)
for part in "${parts[@]}"; do
    case $part in
        main)
            "$py" -m cdr_bench evaluate $ag --out $ag/eval/paper.json --no-progress ;;
        ablations)
            for ck in $ag/ablations/*-100k.pt; do
                name=$(basename "$ck" .pt)
                CDR_BENCH_CHECKPOINT=$ck "$py" -m cdr_bench evaluate $ag \
                    --out "$ag/eval/ablation-$name.json" --no-progress
            done ;;
        analysis)
            PYTHON=$py bash $ag/make_multimodal.sh  # Diffusion-AC (and PPO) on the tactical scenarios
            "$py" -m cdr_bench latency $ag --out $ag/analysis/latency.json > $ag/analysis/latency.md ;;
        *) echo "unknown part: $part (expected main, ablations or analysis)" >&2; exit 2 ;;
    esac
done
