#!/usr/bin/env bash
# Train the paper's learned baselines at the Diffusion-AC reference budget and ship them.
#
#   PYTHON=.venv/bin/python bash agents/train_baselines.sh [BUDGET] [NAME ...]
#
# BUDGET defaults to 1374560 environment transitions, the length of the Diffusion-AC reference
# run (agents/diffusion_ac/training_log.jsonl.xz); NAME defaults to every baseline. Each baseline
# is trained as in the paper (§5.2): without the DPSC curriculum, on the medium scenario (the same
# condition as the W/O-DPSC ablation of Diffusion-AC), width 128, gamma 0.99, seed 1, with the
# hyper-parameters chosen by the short tuning recorded in agents/BASELINES.md. The run goes to
# runs/baselines/<name>-final/; its checkpoint (weights only), log (xz-compressed, as
# training_log.jsonl.xz), curve and arguments are copied into agents/<dir>/, which is timed with
# cdr-bench latency. Finally the leaderboard build scores the trained baselines (their entries
# have the same names) on the paper suite, each in its own sandboxed process, into
# leaderboard/results/<name>.json|.jsonl.xz - the one committed copy of each evaluation - and
# re-renders the leaderboard and the docs' results tables.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=${1:-1374560}
shift || true
names=("$@")
[ ${#names[@]} -eq 0 ] && names=(ppo maskable-ppo td3 safe-dqn-x rainbow)
py=${PYTHON:-python}
export OMP_NUM_THREADS=1
for name in "${names[@]}"; do
    case $name in
        ppo) dir=ppo; flags=() ;;
        maskable-ppo) dir=maskable_ppo; flags=(--ent-coef 0.01) ;;
        td3) dir=td3; flags=() ;;
        safe-dqn-x) dir=safe_dqn_x; flags=() ;;
        rainbow) dir=rainbow; flags=() ;;
        *) echo "unknown baseline: $name" >&2; exit 2 ;;
    esac
    run=runs/baselines/$name-final
    echo "$(date -u +%T) train $name -> $run (${flags[*]:-default flags})"
    "$py" -m cdr_bench train "$name" --run-dir "$run" --seed 1 --total-steps "$budget" \
        --no-curriculum --scenario medium --no-progress "${flags[@]}" > "$run.out" 2>&1
    ag=agents/$dir
    cp "$run/checkpoint.pt" "$ag/checkpoint.pt"
    "$py" -c 'import sys, pathlib; from cdr_bench.evaluate.results import compress_log, log_text
pathlib.Path(sys.argv[2]).write_bytes(compress_log(log_text(sys.argv[1], "training log")))' \
        "$run/log.jsonl" "$ag/training_log.jsonl.xz"
    rm -f "$ag/training_log.jsonl"
    cp "$run/args.json" "$ag/train_args.json"
    [ -f "$run/curve.png" ] && cp "$run/curve.png" "$ag/curve.png"
    mkdir -p "$ag/analysis"
    "$py" -m cdr_bench latency "$ag" --out "$ag/analysis/latency.json"
    echo "$(date -u +%T) trained $name"
done
echo "$(date -u +%T) evaluate ${names[*]}"
"$py" -m cdr_bench leaderboard build --evaluate "${names[@]}"
echo "$(date -u +%T) done"
