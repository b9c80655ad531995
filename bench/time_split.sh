#!/usr/bin/env bash
# Where the render time goes, Snell's and Mitsuba 3's (`llvm_ad_rgb`) side by side: the share
# of each program's samples (`perf record`) spent tracing rays, and the rest (shading, sampling,
# the film). On each of the rendering comparisons' scenes (256x256, 64 spp, 2 threads):
# - Mitsuba: `bench/mitsuba_time.py` (a warm-up render, then RUNS timed ones) under perf; tracing
#   is its Embree library, the rest its JIT-compiled kernels (samples elsewhere, such as the
#   scene's loading and the kernels' compilation, are left out of both);
# - Snell: RUNS renders under perf; tracing is the accelerators' walks and the object and
#   triangle tests (`accel::`, `Tri4`, `World::hit_*`, `World::occluded*`, their closures),
#   the rest everything else in the binary but the scene's loading and the structures' build
#   (the hits' interaction counts as the rest, as Mitsuba's kernels work theirs out from
#   Embree's hit).
# Multiplying a share by the median render time (`bench/vs_mitsuba.sh`) gives seconds.
#
#   bench/time_split.sh [SNELL_BINARY]
#
# Needs perf and Mitsuba (as vs_mitsuba.sh). SNELL_SCENES as there; RUNS (default 3).
source "$(dirname "$0")/common.sh" "$@"
bin="${bins[0]}"
RUNS="${RUNS:-3}"
SPP="${SPP:-64}"
command -v perf >/dev/null || { echo "perf is not installed" >&2; exit 1; }
python3 -c "import mitsuba" 2>/dev/null || { echo "Mitsuba 3 is not installed: pip install mitsuba" >&2; exit 1; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# share PERF_DATA SORT TRACING BASE [EXCLUDED]: of the samples whose SORT key matches BASE but not
# EXCLUDED, the per cent that match TRACING and the per cent that do not.
share() {
    perf report -i "$1" --sort "$2" --stdio 2>/dev/null | grep -v '^#' |
        awk -v t="$3" -v a="$4" -v x="${5:-^$}" '$1 ~ /%$/ { p = $1 + 0; if ($0 ~ a && $0 !~ x) { all += p; if ($0 ~ t) tr += p } }
            END { if (all > 0) printf "%.1f %% tracing, %.1f %% the rest (%.1f %% of all samples)\n", 100 * tr / all, 100 * (all - tr) / all, all; else print "no samples" }'
}

for scene in "${render_scenes[@]}"; do
    define=()
    uses_scenes "$scene" && define=("scenes=$SCENES")
    echo "== $(basename "$scene") at $SPP spp"
    perf record -q -o "$tmp/mitsuba.data" -- python3 bench/mitsuba_time.py "$scene" "$SPP" "$RUNS" "${define[@]}" \
        > "$tmp/mitsuba.times" 2>/dev/null
    echo "   Mitsuba ($(median < "$tmp/mitsuba.times") s median): $(share "$tmp/mitsuba.data" dso 'libembree' 'libembree|\[JIT\]')"
    snell_define=()
    [ ${#define[@]} -gt 0 ] && snell_define=(-D "${define[0]}")
    : > "$tmp/snell.times"
    # RUNS renders in one recording; the arguments go in as positional parameters, so that
    # paths with spaces stay whole.
    perf record -q -o "$tmp/snell.data" -- bash -c 'runs=$1 times=$2; shift 2
        for i in $(seq "$runs"); do
            "$@" 2>&1 | sed -n "s/.*render \([0-9.]*\) s.*/\1/p" >> "$times"
        done' _ "$RUNS" "$tmp/snell.times" "$bin" render "$scene" "${snell_define[@]}" --spp "$SPP" --threads 2 \
        -o "$tmp/x.exr" >/dev/null 2>&1
    # The binary's own samples, less the scene's loading and the structures' build.
    echo "   Snell ($(median < "$tmp/snell.times") s median): $(share "$tmp/snell.data" dso,sym \
        'accel::|Tri4|World<A>::hit_|World<A>::occluded|closest_in_object|any_in_object|TriData' \
        "^ *[0-9.]+% +$(basename "$bin") " 'Builder|bin_refs|merge_bins|collapse|sah_sweep|snell_io|validate|triangle_boxes|pack|relabel')"
done
