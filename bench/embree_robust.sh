#!/usr/bin/env bash
# Embree's benchmark in Embree's own watertight mode: ../shared/bench/embree_bench.c built with
# one line more, `rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST)` after the scene is made (Embree:
# "uses acceleration structures that allow for robust traversal, and avoids optimizations that
# reduce arithmetic accuracy ... for avoiding artifacts caused by rays shooting through edges of
# neighboring primitives"). The speed issue's targets are against Embree's default mode, whose
# triangle test is not watertight; Snell's always is, and this binary is the comparison with
# the same guarantee. The shared source is patched in WORK/robust at build time, not copied
# into the repository. Prints the binary's path, which paired.sh takes as its A:
#
#   bench/paired.sh "$(bench/embree_robust.sh)" target/release/snell 10 bench WORK/bunny.ply \
#       --rays WORK/bunny
#
# WORK as in vs_embree.sh (default /tmp/snell-embree), which makes the meshes and rays there.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
TOOLS="${SNELL_SCENES:-$(cd .. && pwd)/shared/scenes}/../bench"
WORK="${WORK:-/tmp/snell-embree}"
out="$WORK/robust"
src="$TOOLS/embree_bench.c"
[ -f "$src" ] || { echo "missing $src" >&2; exit 1; }
mkdir -p "$out"
stamp=$(cat "$src" "$TOOLS/build_embree_bench.sh" | sha256sum | cut -c1-16)
if [ ! -x "$out/embree_bench" ] || [ "$(cat "$out/source.stamp" 2>/dev/null)" != "$stamp" ]; then
    anchor='  RTCScene sc = rtcNewScene(dev);'
    [ "$(grep -cxF "$anchor" "$src")" = 1 ] || { echo "$src: the line '$anchor' is not there once; cannot add the flag" >&2; exit 1; }
    # The shared build script, run beside the patched source: the same compiler flags, and it
    # installs libembree-dev if it is missing.
    mkdir -p "$out/src"
    cp "$TOOLS/build_embree_bench.sh" "$out/src/"
    sed "s/^$anchor\$/&\n  rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST);/" "$src" > "$out/src/embree_bench.c"
    [ "$(grep -c RTC_SCENE_FLAG_ROBUST "$out/src/embree_bench.c")" = 1 ] || { echo "the flag was not added" >&2; exit 1; }
    bash "$out/src/build_embree_bench.sh" "$out" > /dev/null
    echo "$stamp" > "$out/source.stamp"
fi
echo "$out/embree_bench"
