#!/usr/bin/env bash
# The built sdist and wheel work without the repository: build both, install the wheel (base
# dependencies only) into a fresh venv outside the checkout and, from a folder outside it, list
# the scenarios, evaluate the packaged reference agent `mvp` on 20 episodes of `high` and step
# the PettingZoo environment once. It needs only a Python with pip (the `build` package goes into
# a venv of its own), so CI starts it before the dev environment is installed; the builds and the
# installs fetch from the package index.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
start=$(date +%s)
say() { echo "wheel_smoke: $* ($(( $(date +%s) - start )) s)"; }
tmp=$(mktemp -d "${TMPDIR:-/tmp}/cdr-bench-wheel.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
case "$tmp/" in "$repo"/*) echo "wheel_smoke: $tmp is inside the checkout" >&2; exit 1 ;; esac

# The sdist, then the wheel built from it (each in an isolated build environment), from a copy
# of the tracked files: the build writes its metadata into the tree it builds, and CI installs
# the checkout itself at the same time.
mkdir "$tmp/src"
git ls-files -z | tar --null -T - -cf - | tar -xf - -C "$tmp/src"
python3 -m venv "$tmp/build-venv"
"$tmp/build-venv/bin/python" -m pip install -q build >"$tmp/build.log" 2>&1 \
    && "$tmp/build-venv/bin/python" -m build --outdir "$tmp/dist" "$tmp/src" >>"$tmp/build.log" 2>&1 \
    || { cat "$tmp/build.log"; exit 1; }
sdist=$(ls "$tmp"/dist/cdr_bench-*.tar.gz)
wheel=$(ls "$tmp"/dist/cdr_bench-*-py3-none-any.whl)

# Every scenario of scenarios/ and the built-in agents are in the sdist (where they are in the
# repository) and in the wheel (below cdr_bench/_data/, byte for byte); neither holds a link.
python3 - "$sdist" "$wheel" <<'PY'
import sys, tarfile, zipfile
from pathlib import Path

sdist, wheel = sys.argv[1:]
shipped = sorted(p.as_posix() for p in Path("scenarios").rglob("*.yaml"))
shipped += [f"agents/{n}/agent.py" for n in ("direct", "mvp", "random")]
with tarfile.open(sdist) as t:
    members = t.getmembers()
    top = members[0].name.split("/")[0]
    assert not [m.name for m in members if m.issym() or m.islnk()], "a link in the sdist"
    missing = set(shipped) - {m.name.removeprefix(top + "/") for m in members}
    assert not missing, f"not in the sdist: {sorted(missing)}"
with zipfile.ZipFile(wheel) as z:
    for f in shipped:
        data = z.read(f"cdr_bench/_data/{f}")  # KeyError: not in the wheel
        assert data == Path(f).read_bytes(), f"{f} differs in the wheel"
print(f"wheel_smoke: the sdist and the wheel hold the {len(shipped)} shipped files")
PY
say "built $(basename "$sdist") and $(basename "$wheel")"

# A venv of its own (no pip inside: this pip installs into it; no byte-compiling: faster).
python3 -m venv --without-pip "$tmp/venv"
"$tmp/build-venv/bin/python" -m pip --python "$tmp/venv/bin/python" install -q --no-compile "$wheel"
say "installed the wheel and its base dependencies"

mkdir "$tmp/run"
(
    cd "$tmp/run"
    unset PYTHONPATH PYTHONHOME VIRTUAL_ENV CDR_BENCH_SCENARIOS
    export PATH="$tmp/venv/bin:$PATH"
    python -c "import cdr_bench, sys; assert cdr_bench.__file__.startswith(sys.prefix)"
    cdr-bench scenarios list >list.txt
    grep -q "^high " list.txt && grep -q "^tactical/head-on " list.txt
    say "listed $(wc -l <list.txt) scenarios"
    cdr-bench evaluate mvp --scenario high --episodes 20 --out "$PWD/r.json" --no-progress
    say "evaluated the packaged mvp"
    python - <<'PY'
import json

import cdr_bench

r = json.load(open("r.json"))
assert r["agent"]["name"] == "mvp", r["agent"]
assert [(s["id"], s["episodes"]) for s in r["scenarios"]] == [("high", 20)], r["scenarios"]
env = cdr_bench.parallel_env(scenario="high")
obs, infos = env.reset(seed=0)
actions = {a: int(env.action_space(a).sample(obs[a]["action_mask"])) for a in env.agents}
obs, rewards, terminations, truncations, infos = env.step(actions)
assert set(rewards) == set(actions), rewards
print(f"wheel_smoke: parallel_env(scenario='high'): reset and one step of {len(actions)} agent(s)")
PY
)
say "passed"
