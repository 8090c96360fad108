#!/usr/bin/env bash
# First-action multimodality (cdr-bench multimodal, docs/model.md §10.4) of every seed of the
# Diffusion-AC and PPO (sampled) entries on the tactical families, for the comparison of the two
# over seeds (episodes paired across entries by their episode seed).
#
#   PYTHON=.venv/bin/python bash sweeps/multimodal_seeds.sh [entry ...]
#
# Entries: diffusion-ac, ppo-sampled (both when none is named). Each seed k's checkpoint is the
# one its submission names (seed 1: the entry's checkpoint, k > 1: agents/<agent>/seeds/<k>/).
# Episodes: the leaderboard's test set (base seed 20261127, docs/model.md §10.1.2), the first
# EPISODES of each family (100), SAMPLES first actions each (50), with the family search.
# Outputs, beside the entries' results (the naming of <entry>.seed-<k>.json): the JSON of
# `cdr-bench multimodal`, compact and xz-compressed (its heat map is not kept),
#   leaderboard/results/<entry>.seed-<k>.multimodal-tactical_<family>.json.xz
# which the leaderboard's multimodality claim reads (cdr_bench/leaderboard/claims.py).
# Runs one process at a time; a finished file is kept unless FORCE=1.
set -euo pipefail
cd "$(dirname "$0")/.."
py=${PYTHON:-python}
export OMP_NUM_THREADS=1
episodes=${EPISODES:-100}
samples=${SAMPLES:-50}
seeds=${SEEDS:-1 2 3}
entries=("$@")
[ ${#entries[@]} -eq 0 ] && entries=(diffusion-ac ppo-sampled)
for entry in "${entries[@]}"; do
    case $entry in
        diffusion-ac) ag=agents/diffusion_ac; ck=agents/diffusion_ac ;;
        ppo-sampled) ag=agents/ppo_sampled; ck=agents/ppo ;;
        *) echo "unknown entry: $entry (expected diffusion-ac or ppo-sampled)" >&2; exit 2 ;;
    esac
    for k in $seeds; do
        if [ "$k" = 1 ]; then cp=$ck/checkpoint.pt; else cp=$ck/seeds/$k/checkpoint.pt; fi
        for sc in head-on crossing overtaking; do
            out=leaderboard/results/$entry.seed-$k.multimodal-tactical_$sc.json
            if [ -f "$out.xz" ] && [ "${FORCE:-0}" != 1 ]; then
                echo "$out.xz: done"
                continue
            fi
            CDR_BENCH_CHECKPOINT=$cp "$py" -m cdr_bench multimodal $ag --search \
                --seed 20261127 --episodes "$episodes" --samples "$samples" \
                --scenario tactical/$sc --out "$out"
            "$py" - "$out" <<'PY'
import json, lzma, sys
from pathlib import Path

out = Path(sys.argv[1])
text = json.dumps(json.loads(out.read_text()), separators=(",", ":"), sort_keys=True)
Path(f"{out}.xz.tmp").write_bytes(lzma.compress(text.encode(), preset=9 | lzma.PRESET_EXTREME))
Path(f"{out}.xz.tmp").replace(f"{out}.xz")
out.unlink()
out.with_suffix(".png").unlink(missing_ok=True)
PY
        done
    done
done
