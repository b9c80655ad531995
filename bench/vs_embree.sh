#!/usr/bin/env bash
# Ray throughput against Embree 3 on the same rays, measured in one run (the speed issue's
# tracing targets): for each mesh (bunny, displaced icosphere, dragon), Embree's benchmark
# (quality high and medium, AVX2, 2 threads, single rays and packets), then each Snell binary
# (`snell bench --rays`, the default accelerator), then Embree again.
#
#   bench/vs_embree.sh [SNELL_BINARY ...]
#
# Default binary: target/release/snell (brought up to date first). WORK (default /tmp/snell-embree)
# keeps embree_bench, the meshes as both programs read them and Embree's dumped rays; they are
# made on the first run with ../shared/bench (build_embree_bench.sh installs libembree-dev if
# it is missing; mesh_tools.py needs numpy). Prints per mesh and binary the ratio to the mean of
# Embree's two runs (above 1: Snell is faster), the build time against Embree MEDIUM's, bytes
# per triangle, and the hit counts, which must be Embree's.
source "$(dirname "$0")/common.sh" "$@"
set -- "${bins[@]}"
TOOLS="$SCENES/../bench"
WORK="${WORK:-/tmp/snell-embree}"
REPS="${REPS:-5}"
mkdir -p "$WORK"
# WORK's contents belong to the tools that made them: when ../shared/bench changes, they are
# made again.
stamp=$(cat "$TOOLS/build_embree_bench.sh" "$TOOLS/embree_bench.c" "$TOOLS/mesh_tools.py" | sha256sum | cut -c1-16)
if [ "$(cat "$WORK/tools.stamp" 2>/dev/null)" != "$stamp" ]; then
    rm -f "$WORK/embree_bench" "$WORK"/*.bin "$WORK"/*.ply "$WORK"/*_primary.f32 "$WORK"/*_bounce.f32
fi
[ -x "$WORK/embree_bench" ] || bash "$TOOLS/build_embree_bench.sh" "$WORK" >&2
echo "$stamp" > "$WORK/tools.stamp"

for mesh in bunny ico dragon; do
    if [ ! -f "$WORK/$mesh.bin" ]; then
        case $mesh in
            bunny) python3 "$TOOLS/mesh_tools.py" convert "$SCENES/stanford/bunny.ply" --out "$WORK/bunny" ;;
            dragon) python3 "$TOOLS/mesh_tools.py" convert "$SCENES/stanford/dragon_vrip.ply" --out "$WORK/dragon" ;;
            ico) python3 "$TOOLS/mesh_tools.py" icosphere --subdiv 6 --displace --out "$WORK/ico" ;;
        esac >&2
    fi
    if [ ! -f "$WORK/${mesh}_bounce.f32" ]; then
        "$WORK/embree_bench" "$WORK/$mesh.bin" --quality high --threads 2 --isa avx2 --no-packets --reps 1 \
            --dump-rays "$WORK/$mesh" > /dev/null
    fi
    embree() { "$WORK/embree_bench" "$WORK/$mesh.bin" --quality high,medium --threads 2 --isa avx2 --reps "$REPS" | grep '^RESULT'; }
    out="$WORK/run_$mesh"
    embree > "$out.e1"
    k=0
    for bin in "$@"; do
        "$bin" bench "$WORK/$mesh.ply" --rays "$WORK/$mesh" --threads 2 --reps "$REPS" --json > "$out.s$k"
        k=$((k + 1))
    done
    embree > "$out.e2"
    python3 - "$mesh" "$out" "$@" <<'PY'
import json, sys
mesh, out, bins = sys.argv[1], sys.argv[2], sys.argv[3:]

def embree(path):
    d = {}
    for line in open(path):
        kv = dict(x.split("=", 1) for x in line.split()[1:])
        d[(kv["quality"], kv["api"], kv["kind"])] = kv
    return d

e1, e2 = embree(out + ".e1"), embree(out + ".e2")
mean = lambda key, field: (float(e1[key][field]) + float(e2[key][field])) / 2
print(f"== {mesh}: Embree high/medium, run before and after")
rows = [("primary", ("high", "intersect1", "primary")),
        ("bounce", ("high", "intersect1", "diffuse_bounce")),
        ("bounce-occluded", ("high", "occluded1", "diffuse_bounce")),
        ("primary-packets", ("high", "intersect16", "primary"))]
for k, b in enumerate(bins):
    s = {j["workload"]: j for j in map(json.loads, open(f"{out}.s{k}"))}
    p = s["primary"]
    build = mean(("medium", "build", "bvh"), "med_ms")
    print(f"   {b}: build {p['build_ms']:.1f} ms = {p['build_ms'] / build:.2f}x Embree MEDIUM's {build:.1f} ms; "
          f"{p['accel_bytes'] / p['tris']:.1f} bytes/triangle")
    for name, key in rows:
        em = mean(key, "mrays_med")
        label = "16-ray packets" if name == "primary-packets" else name
        print(f"     {label:16} {s[name]['mrays_per_s']:7.2f} Mrays/s vs Embree {float(e1[key]['mrays_med']):6.2f} / "
              f"{float(e2[key]['mrays_med']):6.2f}: {s[name]['mrays_per_s'] / em:.2f}x   hits {s[name]['hits']}")
    want = (int(e1[("high", "intersect1", "primary")]["extra"]), int(e1[("high", "occluded1", "diffuse_bounce")]["checksum"]))
    got = (s["primary"]["hits"], s["bounce"]["hits"])
    print(f"     hits (primary, bounce): {got}, Embree {want}" + ("" if got == want else "  <-- DIFFERENT"))
PY
done
