#!/usr/bin/env bash
# Embree's benchmark built with lines added to the shared source: `embree_patch.sh NAME ANCHOR
# INSERT` copies ../shared/bench/embree_bench.c into WORK/NAME with the lines of file INSERT put
# after the one line equal to ANCHOR (failing where there is not exactly one), builds it with
# the shared build script (the same compiler flags; it installs libembree-dev if missing), and
# prints the binary's path. Rebuilt only when the source, the build script, ANCHOR or INSERT
# change. Nothing of Embree's is copied into the repository. Used by embree_robust.sh and
# hit_miss.sh; WORK as in vs_embree.sh (default /tmp/snell-embree).
set -euo pipefail
[ $# -eq 3 ] || { echo "usage: $0 NAME ANCHOR INSERT" >&2; exit 2; }
name=$1 anchor=$2 insert=$3
cd "$(dirname "${BASH_SOURCE[0]}")/.."
TOOLS="${SNELL_SCENES:-$(cd .. && pwd)/shared/scenes}/../bench"
WORK="${WORK:-/tmp/snell-embree}"
out="$WORK/$name"
src="$TOOLS/embree_bench.c"
[ -f "$src" ] || { echo "missing $src" >&2; exit 1; }
mkdir -p "$out/src"
stamp=$( (cat "$src" "$TOOLS/build_embree_bench.sh" "$insert"; echo "$anchor") | sha256sum | cut -c1-16)
if [ ! -x "$out/embree_bench" ] || [ "$(cat "$out/source.stamp" 2>/dev/null)" != "$stamp" ]; then
    [ "$(grep -cxF -- "$anchor" "$src")" = 1 ] || { echo "$src: the line '$anchor' is not there once" >&2; exit 1; }
    cp "$TOOLS/build_embree_bench.sh" "$out/src/"
    awk -v a="$anchor" -v f="$insert" '{ print } $0 == a { while ((getline l < f) > 0) print l }' "$src" \
        > "$out/src/embree_bench.c"
    bash "$out/src/build_embree_bench.sh" "$out" > /dev/null
    echo "$stamp" > "$out/source.stamp"
fi
echo "$out/embree_bench"
