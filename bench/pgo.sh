#!/usr/bin/env bash
# Builds `snell` with profile-guided optimisation (PGO): an instrumented build runs a training
# workload, LLVM merges the counts it wrote, and a second build optimises with them (branch
# layout, inlining, hot and cold code). Same source, same results: only the machine code's
# layout and inlining change.
#
#   bench/pgo.sh        # prints the path of the optimised binary, target/pgo/release/snell
#
# The training workload deliberately leaves out the benchmarks' own scenes and meshes (the
# Cornell box, the bunny, the dragon, the icosphere), so that what bench/vs_mitsuba.sh and
# bench/vs_embree.sh measure with this binary is not a workload it was trained on. It renders
# the built-in default scene (Whitted and path tracing), the repository's TOML scenes but
# bunnies.toml, Veach's MIS scene, the teapot under an HDR environment map, and Spot and
# Suzanne as bare meshes (clay on a floor under an area light), and runs `snell bench` with its
# own camera and bounce rays on the teapot and on a reduced dragon (dragon_vrip_res2.ply, a
# different mesh from the measured dragon_vrip.ply).
#
# Needs the toolchain's llvm-profdata (`rustup component add llvm-tools-preview`, done here
# when missing) and the shared test data (SNELL_SCENES, default ../shared/scenes). Takes about
# seven minutes on two cores: both builds compile every dependency.
set -euo pipefail
cd "$(dirname "$0")/.."
SCENES="${SNELL_SCENES:-$(cd .. && pwd)/shared/scenes}"
[ -d "$SCENES" ] || { echo "no shared test data at $SCENES (set SNELL_SCENES)" >&2; exit 1; }

profdata() { find "$(rustc --print sysroot)" -name llvm-profdata -type f 2>/dev/null | head -1; }
if [ -z "$(profdata)" ]; then
    rustup component add llvm-tools-preview >&2
fi
PROFDATA=$(profdata)
[ -n "$PROFDATA" ] || { echo "llvm-profdata not found (rustup component add llvm-tools-preview)" >&2; exit 1; }

root=$PWD/target/pgo
raw=$root/profiles
rm -rf "$raw"
mkdir -p "$raw"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

echo "pgo: instrumented build" >&2
RUSTFLAGS="-Cprofile-generate=$raw" cargo build --release -q -p snell --target-dir "$root/gen"
gen=$root/gen/release/snell

# The teapot under an HDR environment (an importance-sampled map, rough plastic, a Mitsuba
# scene).
cat > "$tmp/teapot-env.xml" <<EOF
<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="6"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="35"/>
        <transform name="to_world"><lookat origin="0, 30, 60" target="0, 5, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
        <film type="hdrfilm"><integer name="width" value="160"/><integer name="height" value="120"/></film>
    </sensor>
    <emitter type="envmap"><string name="filename" value="$SCENES/envmaps/spiaggia_di_mondello_1k.hdr"/></emitter>
    <shape type="obj">
        <string name="filename" value="$SCENES/teapot/teapot.obj"/>
        <bsdf type="roughplastic"><float name="alpha" value="0.2"/></bsdf>
    </shape>
</scene>
EOF

echo "pgo: training" >&2
# A training run that fails stops the script with snell's own message.
run() {
    "$gen" "$@" > "$tmp/run.log" 2>&1 || { cat "$tmp/run.log" >&2; echo "pgo: training run failed: snell $*" >&2; exit 1; }
}
run render -o "$tmp/default.png" --spp 4 --width 256 --height 256
run render -o "$tmp/default-path.png" --spp 32 --width 256 --height 256 --integrator path
for s in scenes/*.toml; do
    # bunnies.toml instances the bunny, one of the benchmarks' meshes.
    [ "$(basename "$s")" = bunnies.toml ] && continue
    run render "$s" -o "$tmp/$(basename "$s" .toml).png" --spp 4 --width 160 --height 120
done
run render "$SCENES/veach-mis/veach_mis.xml" -o "$tmp/veach.exr" --spp 8 --width 192 --height 128
run render "$tmp/teapot-env.xml" -o "$tmp/teapot.exr"
for m in misc/spot.obj misc/suzanne.obj; do
    run render "$SCENES/$m" -o "$tmp/mesh.exr" --spp 16 --width 128 --height 128
done
run bench "$SCENES/teapot/teapot_mitsuba.ply" --reps 1 --width 512 --height 512
run bench "$SCENES/stanford/dragon_vrip_res2.ply" --reps 1 --width 512 --height 512

echo "pgo: optimised build" >&2
"$PROFDATA" merge -o "$root/snell.profdata" "$raw"
RUSTFLAGS="-Cprofile-use=$root/snell.profdata" cargo build --release -q -p snell --target-dir "$root"
echo "$root/release/snell"
