#!/usr/bin/env bash
# Ray throughput against Embree 3 on the same rays, measured in one run (the speed issue's
# tracing targets): for each mesh (bunny, the displaced icosphere at subdivision 6 and at the
# issue's subdivision 8, dragon, and Spot, one more closed mesh; MESHES picks some of bunny ico
# ico8 dragon spot), Embree's benchmark
# (quality high and medium, AVX2, 2 threads, single rays and packets), then each Snell binary
# (`snell bench --rays`, the default accelerator), then Embree again; ROUNDS (default 1) times
# Snell then Embree, on a machine whose speed drifts from one run to the next.
#
#   bench/vs_embree.sh [SNELL_BINARY ...]
#
# Default binary: target/release/snell (brought up to date first). WORK (default /tmp/snell-embree)
# keeps embree_bench, the meshes as both programs read them and Embree's dumped rays; they are
# made on the first run with ../shared/bench (build_embree_bench.sh installs libembree-dev if
# it is missing; mesh_tools.py needs numpy). Prints per mesh and binary the median over rounds
# with its range, the ratio to the median of Embree's runs (above 1: Snell is faster), the build
# time against Embree MEDIUM's, bytes per triangle, and the hit counts, which must be Embree's.
source "$(dirname "$0")/common.sh" "$@"
set -- "${bins[@]}"
TOOLS="$SCENES/../bench"
WORK="${WORK:-/tmp/snell-embree}"
REPS="${REPS:-5}"
ROUNDS="${ROUNDS:-1}"
MESHES="${MESHES:-$bench_meshes}"
for mesh in $MESHES; do
    [[ " $bench_meshes " == *" $mesh "* ]] || { echo "unknown mesh $mesh (MESHES: some of $bench_meshes)" >&2; exit 2; }
done
mkdir -p "$WORK"
# WORK's contents belong to the tools that made them: when ../shared/bench changes, they are
# made again.
stamp=$(cat "$TOOLS/build_embree_bench.sh" "$TOOLS/embree_bench.c" "$TOOLS/mesh_tools.py" | sha256sum | cut -c1-16)
if [ "$(cat "$WORK/tools.stamp" 2>/dev/null)" != "$stamp" ]; then
    rm -f "$WORK/embree_bench" "$WORK"/*.bin "$WORK"/*.ply "$WORK"/*_primary.f32 "$WORK"/*_bounce.f32
fi
[ -x "$WORK/embree_bench" ] || bash "$TOOLS/build_embree_bench.sh" "$WORK" >&2
echo "$stamp" > "$WORK/tools.stamp"

for mesh in $MESHES; do
    make_mesh "$mesh"
    if [ ! -f "$WORK/${mesh}_bounce.f32" ]; then
        "$WORK/embree_bench" "$WORK/$mesh.bin" --quality high --threads 2 --isa avx2 --no-packets --reps 1 \
            --dump-rays "$WORK/$mesh" > /dev/null
    fi
    embree() { "$WORK/embree_bench" "$WORK/$mesh.bin" --quality high,medium --threads 2 --isa avx2 --reps "$REPS" | grep '^RESULT'; }
    out="$WORK/run_$mesh"
    rm -f "$out".e* "$out".s*
    # ROUNDS rounds of Embree, then each Snell binary; Embree once more at the end. On a
    # machine whose speed drifts from one run to the next, more rounds give steadier medians.
    embree > "$out.e0"
    for round in $(seq 1 "$ROUNDS"); do
        # The binaries take turns at going first: on this machine the first one after Embree
        # ran up to 20 % faster than the one after it, whichever it was (forty-eighth session).
        for j in $(seq 0 $(($# - 1))); do
            k=$(((j + round - 1) % $#))
            bin=${bins[$k]}
            "$bin" bench "$WORK/$mesh.ply" --rays "$WORK/$mesh" --threads 2 --reps "$REPS" --json > "$out.s$k.$round"
        done
        embree > "$out.e$round"
    done
    python3 - "$mesh" "$out" "$ROUNDS" "$@" <<'PY'
import json, statistics, sys
sys.path.insert(0, "bench")
from embree_results import WORKLOADS, results
mesh, out, rounds, bins = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]

runs = [results(open(f"{out}.e{r}")) for r in range(rounds + 1)]
med = statistics.median
embree_of = lambda key, field: [float(e[key][field]) for e in runs]
spread = lambda xs: f"{min(xs):.2f}" if len(xs) == 1 else f"{min(xs):.2f}-{max(xs):.2f}"
print(f"== {mesh}: Embree high/medium, {rounds + 1} runs around {rounds} round(s) of Snell (medians)")
rows = [(name, ("high", *key)) for name, key in WORKLOADS.items()]
for k, b in enumerate(bins):
    s = [{j["workload"]: j for j in map(json.loads, open(f"{out}.s{k}.{r}"))} for r in range(1, rounds + 1)]
    build = med(embree_of(("medium", "build", "bvh"), "med_ms"))
    ours = med([x["primary"]["build_ms"] for x in s])
    print(f"   {b}: build {ours:.1f} ms = {ours / build:.2f}x Embree MEDIUM's {build:.1f} ms; "
          f"{s[0]['primary']['accel_bytes'] / s[0]['primary']['tris']:.1f} bytes/triangle")
    for name, key in rows:
        em, sn = embree_of(key, "mrays_med"), [x[name]["mrays_per_s"] for x in s]
        label = "16-ray packets" if name == "primary-packets" else name
        print(f"     {label:16} {med(sn):7.2f} Mrays/s ({spread(sn)}) vs Embree {med(em):6.2f} ({spread(em)}): "
              f"{med(sn) / med(em):.2f}x   hits {s[0][name]['hits']}")
    want = (int(runs[0][("high", "intersect1", "primary")]["extra"]), int(runs[0][("high", "occluded1", "diffuse_bounce")]["checksum"]))
    got = {(x["primary"]["hits"], x["bounce"]["hits"]) for x in s}
    print(f"     hits (primary, bounce): {sorted(got)}, Embree {want}" + ("" if got == {want} else "  <-- DIFFERENT: settle each such ray with bench/exact_hit.py"))
PY
done
