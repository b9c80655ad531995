#!/usr/bin/env bash
# Embree's benchmark in Embree's own watertight mode: ../shared/bench/embree_bench.c built with
# one line more, `rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST)` after the scene is made (Embree:
# "uses acceleration structures that allow for robust traversal, and avoids optimizations that
# reduce arithmetic accuracy ... for avoiding artifacts caused by rays shooting through edges of
# neighboring primitives"). The speed issue's targets are against Embree's default mode, whose
# triangle test is not watertight; Snell's always is, and this binary is the comparison with
# the same guarantee. Built in WORK/robust by embree_patch.sh; prints the binary's path, which
# paired.sh takes as its A:
#
#   bench/paired.sh "$(bench/embree_robust.sh)" target/release/snell 10 bench WORK/bunny.ply \
#       --rays WORK/bunny
#
# WORK as in vs_embree.sh (default /tmp/snell-embree), which makes the meshes and rays there.
set -euo pipefail
here=$(dirname "${BASH_SOURCE[0]}")
insert=$(mktemp)
trap 'rm -f "$insert"' EXIT
echo '  rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST);' > "$insert"
"$here/embree_patch.sh" robust '  RTCScene sc = rtcNewScene(dev);' "$insert"
