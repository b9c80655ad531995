#!/usr/bin/env bash
# Where a mesh's bounce rays lose or gain against Embree: on the rays that miss the mesh, or on
# those that hit it. `hit_miss.sh MESH [SNELL] [ROUNDS]` splits WORK/MESH_bounce.f32 (made by
# vs_embree.sh) into the rays that hit the mesh and those that miss it, as Mitsuba's
# `ray_test` finds them (`pip install mitsuba numpy`; its LLVM variant, as for vs_mitsuba.sh),
# and runs paired.sh's bounce and any-hit workloads on each set: Snell's `bench --rays`
# against Embree's benchmark built to trace its bounce rays from a file (EB_BOUNCE_FILE;
# embree_patch.sh, in WORK/replay). Only the `bounce` and `bounce-occluded` rows are printed:
# the primary rays are the sets' first thousand, a stand-in that `snell bench --rays` needs.
# SNELL defaults to target/release/snell (brought up to date first, as in the other scripts),
# ROUNDS to 6. WORK as in vs_embree.sh (default /tmp/snell-embree; a relative WORK is taken
# from the repository's root, where common.sh moves).
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: $0 MESH [SNELL] [ROUNDS]" >&2; exit 2; }
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
mesh=$1 rounds=${3:-6}
# The Snell binary made absolute, or target/release/snell brought up to date (common.sh).
source "$here/common.sh" ${2:+"$2"}
snell=${bins[0]}
WORK="${WORK:-/tmp/snell-embree}"
for f in "$WORK/$mesh.ply" "$WORK/$mesh.bin" "$WORK/${mesh}_bounce.f32" "$WORK/${mesh}_primary.f32"; do
    [ -f "$f" ] || { echo "missing $f (run bench/vs_embree.sh with this WORK first)" >&2; exit 1; }
done
insert=$(mktemp)
trap 'rm -f "$insert"' EXIT
cat > "$insert" <<'C'
    if (getenv("EB_BOUNCE_FILE")) {
      FILE *bf = fopen(getenv("EB_BOUNCE_FILE"), "rb");
      if (!bf || fseek(bf, 0, SEEK_END) != 0) { fprintf(stderr, "cannot read EB_BOUNCE_FILE\n"); return 1; }
      long sz = ftell(bf);
      rewind(bf);
      free(g_bounce);
      g_bounce = aligned_alloc(64, (size_t)(sz + 63) / 64 * 64 + 64);
      g_nbounce = (int)(sz / (long)sizeof(Ray));
      if (fread(g_bounce, sizeof(Ray), (size_t)g_nbounce, bf) != (size_t)g_nbounce) { fprintf(stderr, "short read\n"); return 1; }
      fclose(bf);
    }
C
embree=$("$here/embree_patch.sh" replay '    make_bounce();' "$insert")
split="$WORK/split"
mkdir -p "$split"
python3 - "$WORK/$mesh" "$split/$mesh" <<'PY'
import sys
import mitsuba as mi
import numpy as np
mi.set_variant("llvm_ad_rgb")  # vectorised: every ray of the file in one query
src, out = sys.argv[1], sys.argv[2]
scene = mi.load_dict({"type": "scene", "mesh": {"type": "ply", "filename": src + ".ply"}})
r = np.fromfile(src + "_bounce.f32", dtype=np.float32).reshape(-1, 6)
hit = np.array(scene.ray_test(mi.Ray3f(mi.Point3f(*r[:, :3].T), mi.Vector3f(*r[:, 3:].T))), dtype=bool)
primary = np.fromfile(src + "_primary.f32", dtype=np.float32)[: 6 * 1000]
for name, sel in (("miss", ~hit), ("hit", hit)):
    r[sel].tofile(f"{out}_{name}_bounce.f32")
    primary.tofile(f"{out}_{name}_primary.f32")
print(f"{len(r)} bounce rays: {hit.sum()} hit the mesh, {(~hit).sum()} miss it", file=sys.stderr)
PY
for set in miss hit; do
    echo "== $mesh, the bounce rays that $set the mesh (A: Embree, B: Snell)"
    EB_BOUNCE_FILE="$split/${mesh}_${set}_bounce.f32" "$here/paired.sh" "$embree" "$snell" "$rounds" bench \
        "$WORK/$mesh.ply" --rays "$split/${mesh}_$set" --reps 5 | grep -E '^bounce'
done
