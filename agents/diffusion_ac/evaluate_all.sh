#!/usr/bin/env bash
# Score the shipped Diffusion-AC checkpoint and its Table-3 ablations with the official scorer
# (their leaderboard entries, each in its own sandboxed process), then time the agent.
#
#   PYTHON=.venv/bin/python bash agents/diffusion_ac/evaluate_all.sh [main] [ablations] [analysis]
#
# With no argument all three parts run. Outputs (all deterministic for a given checkpoint):
#   main       leaderboard/results/diffusion-ac.json|.jsonl (checkpoint.pt on the paper suite,
#              1000 episodes each) and diffusion-ac.multimodal-<scenario>.json (Fig. 9)
#   ablations  leaderboard/results/diffusion-ac-no-<part>.json|.jsonl.xz and .seed-<k>.* (the
#              Table-3 ablations at the reference budget, ablations/<part>/ and its seeds/, on
#              the paper suite; the complete method is the main entry)
#   analysis   analysis/latency.json (cdr-bench latency), and analysis/sample-target/: the
#              reference-budget run of --diffusion-target sample (sweeps/dac-sample.yaml, staged
#              in sweeps/landed/dac-sample/) on the paper suite (result.json, its per-episode
#              file result.jsonl.xz) and its multimodality on the tactical
#              families (multimodal-<scenario>.json|.png)
# The leaderboard build also re-renders the leaderboard and every results table in the docs
# (README.md, agents/BASELINES.md, agents/diffusion_ac/README.md).
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
            "$py" -m cdr_bench leaderboard build --evaluate diffusion-ac ;;
        ablations)
            "$py" -m cdr_bench leaderboard build --evaluate diffusion-ac-no-diffusion \
                diffusion-ac-no-double-q diffusion-ac-no-dpsc diffusion-ac-no-value-guidance ;;
        analysis)
            "$py" -m cdr_bench latency $ag --out $ag/analysis/latency.json
            st=$ag/analysis/sample-target
            ck=sweeps/landed/dac-sample/ab0ea5d749fdcfa2/checkpoint.pt  # its one trial
            # on the leaderboard's test episodes, as the entry it is compared with
            CDR_BENCH_CHECKPOINT=$ck "$py" -m cdr_bench evaluate $ag --no-progress --force \
                --split test --out $st/result.json
            for sc in head-on crossing overtaking; do
                CDR_BENCH_CHECKPOINT=$ck "$py" -m cdr_bench multimodal $ag --search \
                    --seed 20261127 --scenario tactical/$sc --out $st/multimodal-tactical_$sc.json
            done
            "$py" -m cdr_bench leaderboard render-docs ;;
        *) echo "unknown part: $part (expected main, ablations or analysis)" >&2; exit 2 ;;
    esac
done
