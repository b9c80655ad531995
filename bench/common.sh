# Sourced by the comparison scripts with their arguments (`source bench/common.sh "$@"`): makes
# the Snell binaries given absolute (target/release/snell, brought up to date, where none is
# given) into `bins`, moves to the repository's root, and sets SCENES to the shared test data
# (SNELL_SCENES, default ../shared/scenes beside the checkout).
set -euo pipefail
bins=()
for b in "$@"; do bins+=("$(readlink -f "$b")"); done
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if [ ${#bins[@]} -eq 0 ]; then
    # Built every time (a no-op when up to date), so that an edit is never measured stale.
    cargo build --release -q
    bins=("$PWD/target/release/snell")
fi
SCENES="${SNELL_SCENES:-$(cd .. && pwd)/shared/scenes}"

# The scenes the rendering comparisons use: the measured Cornell box, the bunny and dragon under
# a constant environment, and the bunny under an HDR map (not a target of the issues). The bench
# scenes find the shared data through their `scenes` parameter.
render_scenes=("$SCENES/cornell-box/cbox-rgb.xml" bench/scenes/bunny-env.xml bench/scenes/dragon-env.xml bench/scenes/bunny-envmap.xml)

# The meshes the tracing comparisons measure, by name (the speed issue's icosphere is ico8).
bench_meshes="bunny ico ico8 dragon spot"

# make_mesh NAME: NAME.bin (Embree's benchmark reads it) and NAME.ply (`snell bench` reads it)
# in WORK, made with ../shared/bench/mesh_tools.py unless they are there; fails on a name not in
# `bench_meshes`.
make_mesh() {
    local tools="$SCENES/../bench"
    [ -f "$WORK/$1.bin" ] && [ -f "$WORK/$1.ply" ] && return 0
    case $1 in
        bunny) python3 "$tools/mesh_tools.py" convert "$SCENES/stanford/bunny.ply" --out "$WORK/bunny" ;;
        dragon) python3 "$tools/mesh_tools.py" convert "$SCENES/stanford/dragon_vrip.ply" --out "$WORK/dragon" ;;
        spot) python3 "$tools/mesh_tools.py" convert "$SCENES/misc/spot.obj" --out "$WORK/spot" ;;
        ico) python3 "$tools/mesh_tools.py" icosphere --subdiv 6 --displace --out "$WORK/ico" ;;
        ico8) python3 "$tools/mesh_tools.py" icosphere --subdiv 8 --displace --out "$WORK/ico8" ;;
        *) echo "unknown mesh $1 (one of: $bench_meshes)" >&2; return 2 ;;
    esac >&2
}

# The median of the numbers on standard input, one per line.
median() { sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }

# uses_scenes SCENE: whether a Mitsuba scene finds the shared meshes through a `scenes`
# parameter (bench/scenes/*.xml), which then gets SCENES (`snell render -D scenes=...`,
# `mi.load_file(..., scenes=...)`).
uses_scenes() { grep -q '<default name="scenes"' "$1"; }

# render_time BIN SCENE [ARGS...]: renders SCENE with BIN (to a temporary EXR) and prints the
# render time in seconds from its summary line; fails if there is none.
render_time() {
    local bin=$1 scene=$2 define=() out t
    shift 2
    uses_scenes "$scene" && define=(-D "scenes=$SCENES")
    out=$(mktemp --suffix .exr)
    t=$("$bin" render "$scene" "${define[@]}" -o "$out" "$@" 2>&1 | sed -n 's/.*render \([0-9.]*\) s.*/\1/p')
    rm -f "$out"
    [ -n "$t" ] || { echo "$bin failed on $scene" >&2; return 1; }
    echo "$t"
}
