#!/usr/bin/env bash
# The CPU a command uses, counted for the whole machine from /proc/stat (Linux), so that
# processes the command starts and that outlive its own accounting (Ray's daemons, sandboxed
# agents in their own PID namespace) are counted too; run it on an otherwise idle machine.
# Prints the machine's busy share every INTERVAL seconds (default 10) while the command runs,
# then its wall time and busy CPU seconds. The command's own output goes to $CPU_LOAD_OUT
# (default: a temporary file, named at the end).
#
#   bash benchmarks/cpu_load.sh pytest -q                 # the test suite
#   d=$(mktemp -d) && git clone -q . "$d" && bash benchmarks/cpu_load.sh bash "$d/.ci/run"
set -euo pipefail
[ $# -gt 0 ] || { echo "usage: $0 COMMAND [ARG ...]" >&2; exit 2; }
interval=${INTERVAL:-10}
out=${CPU_LOAD_OUT:-$(mktemp)}
hz=$(getconf CLK_TCK)
busy() { awk '/^cpu /{print $2+$3+$4+$7+$8+$9}' /proc/stat; }
total() { awk '/^cpu /{s=0; for (i=2; i<=9; i++) s+=$i; print s}' /proc/stat; }
(
    b0=$(busy); t0=$(total); s=0
    while sleep "$interval"; do
        b1=$(busy); t1=$(total); s=$((s + interval))
        echo "cpu_load: ${s} s: $(( 100 * (b1 - b0) / (t1 - t0 > 0 ? t1 - t0 : 1) )) % busy"
        b0=$b1; t0=$t1
    done
) &
sampler=$!
start_busy=$(busy); start=$(date +%s.%N)
rc=0
"$@" >"$out" 2>&1 || rc=$?
end=$(date +%s.%N); end_busy=$(busy)
kill "$sampler" 2>/dev/null || true
wall=$(awk -v a="$start" -v b="$end" 'BEGIN{printf "%.1f", b - a}')
cpu=$(awk -v a="$start_busy" -v b="$end_busy" -v hz="$hz" 'BEGIN{printf "%.1f", (b - a) / hz}')
echo "cpu_load: exit $rc, wall ${wall} s, busy CPU ${cpu} s (whole machine), output in $out"
exit "$rc"
