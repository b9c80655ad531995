#!/usr/bin/env bash
# Samples per second against Mitsuba 3 (`llvm_ad_rgb`), measured in one run (issue 4's and the
# speed issue's rendering targets): for each scene, ROUNDS (default 2) rounds of Mitsuba (three
# timed renders after a warm-up) and each Snell binary once, then Mitsuba again; all at 256x256,
# 64 spp, the scene's depth, 2 threads (every core of the machine). On a machine whose speed
# drifts from run to run, more rounds give steadier medians.
#
#   bench/vs_mitsuba.sh [SNELL_BINARY ...]
#
# Default binary: target/release/snell (brought up to date first). SNELL_SCENES: the shared test data
# (default ../shared/scenes). Prints per scene the times and the ratio of Mitsuba's median time
# to each binary's median (above 1: Snell renders more samples per second).
# MITSUBA_ISA=avx2 holds Mitsuba's compiled kernels to AVX2's eight lanes (bench/mitsuba_time.py).
source "$(dirname "$0")/common.sh" "$@"
set -- "${bins[@]}"
SPP="${SPP:-64}"
ROUNDS="${ROUNDS:-2}"
python3 -c "import mitsuba" 2>/dev/null || { echo "Mitsuba 3 is not installed: pip install mitsuba" >&2; exit 1; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

for scene in "${render_scenes[@]}"; do
    [ -f "$scene" ] || { echo "missing $scene" >&2; exit 1; }
    # The bench scenes find the shared meshes through their `scenes` parameter.
    define=()
    uses_scenes "$scene" && define=("scenes=$SCENES")
    mitsuba="$tmp/mitsuba"
    : > "$mitsuba"
    declare -A times=()
    for round in $(seq 1 "$ROUNDS"); do
        python3 bench/mitsuba_time.py "$scene" "$SPP" 3 "${define[@]}" >> "$mitsuba"
        # The binaries take turns at going first (see vs_embree.sh).
        for j in $(seq 0 $(($# - 1))); do
            bin=${bins[$(((j + round - 1) % $#))]}
            t=$(render_time "$bin" "$scene" --spp "$SPP")
            times[$bin]="${times[$bin]:-} $t"
        done
    done
    python3 bench/mitsuba_time.py "$scene" "$SPP" 3 "${define[@]}" >> "$mitsuba"
    m=$(median < "$mitsuba")
    echo "== $(basename "$scene") at $SPP spp: Mitsuba${MITSUBA_ISA:+ (kernels held to $MITSUBA_ISA)} $(sort -n "$mitsuba" | head -1)-$(sort -n "$mitsuba" | tail -1) s (median $m)"
    for bin in "$@"; do
        s=$(echo ${times[$bin]} | tr ' ' '\n' | median)
        echo "   $bin:${times[$bin]} s (median $s): $(awk -v m="$m" -v s="$s" 'BEGIN {printf "%.2f", m / s}')x Mitsuba"
    done
    unset times
done
