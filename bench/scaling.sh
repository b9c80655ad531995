#!/usr/bin/env bash
# Two threads against one (the speed issue's scaling target, 1.9x for tracing and rendering),
# measured so that both sides share the machine's drift:
# - tracing: `snell bench MESH --threads 1,2` (the two thread counts alternated round by round
#   inside one process) on the bunny, the displaced icosphere (subdivision 6 and 8), the dragon and Spot;
# - building: `snell bench MESH --threads 1` and `--threads 2` as processes of their own,
#   alternated ROUNDS times (a build of 10 ms, timed while another thread count's pool is alive
#   in the same process, came out 20-60 % slower on two threads than alone: 12-15 against
#   9-10 ms on the bunny);
# - rendering: `snell render SCENE --threads 1` then `--threads 2`, ROUNDS (default 3) times, on
#   the Cornell box, the bunny and dragon under a constant environment and the bunny under an HDR
#   map, 256x256, 64 spp.
# First, what the machine itself gives two threads in this hour (bench/machine_scaling.c: loops of
# arithmetic and of dependent loads, nothing of Snell's), where a C compiler is installed.
#
#   bench/scaling.sh [SNELL_BINARY]
#
# Default binary: target/release/snell (brought up to date first). WORK (default
# /tmp/snell-embree, shared with vs_embree.sh) keeps the icospheres (mesh_tools.py needs numpy).
# Prints per workload the median one- and two-thread figures and their ratio.
source "$(dirname "$0")/common.sh" "$@"
bin="${bins[0]}"
WORK="${WORK:-/tmp/snell-embree}"
REPS="${REPS:-9}"
SPP="${SPP:-64}"
ROUNDS="${ROUNDS:-3}"
mkdir -p "$WORK"
make_mesh ico
make_mesh ico8

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

if command -v cc >/dev/null && cc -O2 -pthread -o "$tmp/machine_scaling" bench/machine_scaling.c; then
    echo "== the machine: the same loop on one thread, then on two at once, alternated ($REPS rounds)"
    "$tmp/machine_scaling" "$REPS"
fi

for mesh in "$SCENES/stanford/bunny.ply" "$WORK/ico.ply" "$WORK/ico8.ply" "$SCENES/stanford/dragon_vrip.ply" "$SCENES/misc/spot.obj"; do
    [ -f "$mesh" ] || { echo "missing $mesh" >&2; exit 1; }
    "$bin" bench "$mesh" --threads 1,2 --reps "$REPS" --json > "$tmp/bench.json"
    # The build: each thread count in a process of its own (a tiny ray workload, as only the
    # build time is read), the two alternated.
    : > "$tmp/build.json"
    for round in $(seq 1 "$ROUNDS"); do
        for threads in 1 2; do
            "$bin" bench "$mesh" --threads "$threads" --reps "$REPS" --width 16 --height 16 --json \
                >> "$tmp/build.json"
        done
    done
    python3 - "$mesh" "$tmp/bench.json" "$tmp/build.json" "$ROUNDS" <<'PY'
import json, os, statistics, sys
rows = [json.loads(line) for line in open(sys.argv[2])]
by = {(r["threads"], r["workload"]): r for r in rows}
print(f"== tracing {os.path.basename(sys.argv[1])}: 1 and 2 threads alternated, medians")
for w in ["primary", "primary-packets", "bounce", "bounce-occluded"]:
    one, two = by[(1, w)]["mrays_per_s"], by[(2, w)]["mrays_per_s"]
    print(f"   {w:<16} {one:7.2f} -> {two:7.2f} Mrays/s: {two / one:.2f}x")
builds = [b for b in map(json.loads, open(sys.argv[3])) if b["workload"] == "primary"]
one = statistics.median(b["build_ms"] for b in builds if b["threads"] == 1)
two = statistics.median(b["build_ms"] for b in builds if b["threads"] == 2)
print(f"   {'build':<16} {one:7.1f} -> {two:7.1f} ms:      {one / two:.2f}x   (separate processes, {sys.argv[4]} rounds)")
PY
done

for scene in "${render_scenes[@]}"; do
    [ -f "$scene" ] || { echo "missing $scene" >&2; exit 1; }
    declare -A times=()
    for round in $(seq 1 "$ROUNDS"); do
        for threads in 1 2; do
            t=$(render_time "$bin" "$scene" --spp "$SPP" --threads "$threads")
            times[$threads]="${times[$threads]:-} $t"
        done
    done
    one=$(echo ${times[1]} | tr ' ' '\n' | median)
    two=$(echo ${times[2]} | tr ' ' '\n' | median)
    echo "== rendering $(basename "$scene") at $SPP spp, 1 then 2 threads, $ROUNDS rounds"
    echo "   1 thread:${times[1]} s; 2 threads:${times[2]} s; medians $one -> $two s: $(awk -v a="$one" -v b="$two" 'BEGIN {printf "%.2f", a / b}')x"
    unset times
done
