#!/usr/bin/env bash
# Multimodality (§5.4, Fig. 9): the successful first actions of Diffusion-AC - and of PPO, if its
# checkpoint is there - on the three tactical scenarios, 1000 samples each. Writes
# <agent>/analysis/multimodal-<scenario>.json and the .png heat maps beside them.
# Usage (from the repository root): [PYTHON=.venv/bin/python] bash agents/diffusion_ac/make_multimodal.sh
set -euo pipefail
cd "$(dirname "$0")/../.."

SCENARIOS=(head-on crossing overtaking)
AGENTS=(agents/diffusion_ac)
if [[ -f agents/ppo/checkpoint.pt ]]; then
  AGENTS+=(agents/ppo)
else
  echo "agents/ppo/checkpoint.pt not found: PPO skipped" >&2
fi

for agent in "${AGENTS[@]}"; do
  for s in "${SCENARIOS[@]}"; do
    "${PYTHON:-python}" -m cdr_bench multimodal "$agent" --scenario "tactical/$s" --samples 1000 \
      --out "$agent/analysis/multimodal-$s.json"
  done
done
