#!/usr/bin/env bash
# A render's instructions per camera sample, by stage (camera rays, closest-hit queries, shadow
# queries, the path tracer's own work), counted by callgrind: the same count every
# run, so two binaries can be compared where the machine's speed drifts too much for timing to
# show a few per cent. Each binary renders SCENE at 64x64 (SPP, default 64, samples per pixel)
# on one thread under `valgrind --tool=callgrind`, and bench/budget.py splits the count.
#
#   bench/budget.sh SCENE [SNELL_BINARY ...]
#
# Default binary: target/release/snell (brought up to date first). A scene with a `scenes`
# default (bench/scenes/*.xml) gets SNELL_SCENES's shared data, as in vs_mitsuba.sh.
# Valgrind's CPU has no AVX-512, so the binary runs its AVX2 walks (where the CPU has AVX-512,
# renders take the AVX-512 walks for single meshes): the counts are of that code. A render of
# 64x64 at 64 spp takes about ten seconds under callgrind on the Cornell box.
[ $# -ge 1 ] || { sed -n '2,14p' "$0" >&2; exit 2; }
scene=$(readlink -f "$1")
shift
[ -f "$scene" ] || { echo "no such file: $scene" >&2; exit 1; }
source "$(dirname "$0")/common.sh" "$@"
command -v valgrind >/dev/null || { echo "valgrind is not installed" >&2; exit 1; }
SPP="${SPP:-64}"
RES=64

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
define=()
uses_scenes "$scene" && define=(-D "scenes=$SCENES")
for bin in "${bins[@]}"; do
    echo "== $bin: $(basename "$scene"), ${RES}x${RES} at $SPP spp, one thread"
    valgrind --tool=callgrind --callgrind-out-file="$tmp/cg.out" "$bin" render "$scene" "${define[@]}" \
        --width $RES --height $RES --spp "$SPP" --threads 1 -o "$tmp/out.exr" > "$tmp/log" 2>&1 ||
        { cat "$tmp/log" >&2; exit 1; }
    python3 bench/budget.py "$tmp/cg.out" $((RES * RES * SPP))
done
