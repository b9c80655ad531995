#!/usr/bin/env bash
# Two Snell binaries compared on one workload by running them at the same time, one thread
# each, each pinned to its own CPU (`taskset`), the CPUs swapped every round and which one
# starts first every other pair of rounds: both see the same minute of the machine, whose speed
# drifts by tens of per cent from one minute to the next, so that a change of a few per cent
# shows in the per-round ratios where separate runs bury it.
#
#   bench/paired.sh A B ROUNDS bench MESH [ARGS...]     tracing (`snell bench`): per workload
#   bench/paired.sh A B ROUNDS render SCENE [ARGS...]   rendering (`snell render`): render time
#
# In bench mode A may be Embree's benchmark (`embree_bench`, which vs_embree.sh builds into
# WORK): it runs on the mesh's `.bin` beside the `.ply` (quality high, AVX2, one thread, the
# `--reps` given to Snell), its single rays and 16-ray packets taken for Snell's workloads
# (and its whole any-hit query for the walk alone that Snell times with `--walk-only`).
#
# Each round runs `A ARGS --threads 1` and `B ARGS --threads 1` together (a render as
# common.sh's `render_time` runs it: to a temporary file, -D scenes=SCENES where the scene has
# that default). Prints, per workload, both medians, the geometric mean of the per-round speed
# ratios B/A (above 1: B is faster, for rays per second as for render times), and over pairs of
# rounds (the CPUs swapped between the two, which cancels a difference between the CPUs) the
# median ratio, its range and the pairs B won. ROUNDS is even. Run against itself, a binary
# gives ratios about 1 and wins about half the pairs: that is the method's noise. Needs two CPUs.
[ $# -ge 5 ] || { sed -n '2,20p' "$0" >&2; exit 2; }
[ $(($3 % 2)) = 0 ] && [ "$3" -gt 0 ] || { echo "ROUNDS must be even and positive (the CPUs swap every round)" >&2; exit 2; }
rounds=$3 mode=$4 input=$(readlink -f "$5")
[ -f "$input" ] || { echo "no such file: $5" >&2; exit 1; }
# (common.sh moves to the repository's root: the mesh or scene is found from here first.)
source "$(dirname "$0")/common.sh" "$1" "$2"
a=${bins[0]} b=${bins[1]}
shift 5
set -- "$input" "$@"
[ "$(nproc)" -ge 2 ] || { echo "paired.sh needs two CPUs" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
args=("$@")
case $mode in
    bench | render) ;;
    *) echo "mode must be bench or render, not $mode" >&2; exit 2 ;;
esac

# The repetitions Snell's bench is given, for Embree's.
reps=5
for ((i = 0; i < ${#args[@]} - 1; i++)); do [ "${args[i]}" = --reps ] && reps=${args[i + 1]}; done

# run BIN CPU OUT: one run on CPU, its figures as "workload value" lines in OUT. Called in a
# background subshell, which pins itself (and so what it starts) to CPU.
run() {
    taskset -pc "$2" "$BASHPID" > /dev/null
    if [ "$mode" = render ]; then
        [ "$(basename "$1")" != embree_bench ] || { echo "Embree's benchmark traces rays; it does not render" >&2; return 2; }
        local t
        t=$(render_time "$1" "${args[@]}" --threads 1) || return 1
        echo "render-seconds $t" > "$3"
        return
    fi
    if [ "$(basename "$1")" = embree_bench ]; then
        "$1" "${input%.*}.bin" --quality high --isa avx2 --threads 1 --reps "$reps" > "$tmp/raw$2" 2>&1 || {
            cat "$tmp/raw$2" >&2
            return 1
        }
        python3 bench/embree_results.py < "$tmp/raw$2" > "$3"
        # Snell's `--walk-only` walk is set against Embree's whole any-hit query.
        awk '$1 == "bounce-occluded" { print "bounce-walk", $2 }' "$3" >> "$3"
        return
    fi
    "$1" bench "${args[@]}" --json --threads 1 > "$tmp/raw$2" 2>&1 || {
        cat "$tmp/raw$2" >&2
        return 1
    }
    python3 -c 'import json, sys
for line in sys.stdin:
    d = json.loads(line)
    print(d["workload"], d["mrays_per_s"])' < "$tmp/raw$2" > "$3"
}

for r in $(seq "$rounds"); do
    ca=$((r % 2)) cb=$((1 - r % 2))
    # Which of the two starts first alternates too, every other pair of rounds, so that each
    # starts first on each CPU equally often: the one started second runs each of its
    # workloads a little later, beside another phase of the first. (With A always first, one
    # run of a binary against a rebuild of itself gave B's packets 0.978, slower in all ten
    # pairs; other such runs were even. A balance, not a measured bias.)
    if [ $(((r - 1) / 2 % 2)) = 0 ]; then
        run "$a" $ca "$tmp/a" & pa=$!
        run "$b" $cb "$tmp/b" & pb=$!
    else
        run "$b" $cb "$tmp/b" & pb=$!
        run "$a" $ca "$tmp/a" & pa=$!
    fi
    ok=1
    wait $pa || ok=0
    wait $pb || ok=0
    [ $ok = 1 ] || exit 1
    # Joined by workload (Embree's come in another order than Snell's).
    join <(sort "$tmp/a") <(sort "$tmp/b") >> "$tmp/rounds"
done

python3 - "$tmp/rounds" "$mode" <<'PY'
import collections, math, statistics, sys
rows = collections.defaultdict(list)
for line in open(sys.argv[1]):
    w, x, y = line.split()
    rows[w].append((float(x), float(y)))
for w, v in rows.items():
    # Above 1: B faster (rays per second up, or seconds down).
    q = [y / x if sys.argv[2] == "bench" else x / y for x, y in v]
    g = math.exp(sum(map(math.log, q)) / len(q))
    # Each two rounds swap the CPUs: their ratios' geometric mean cancels a difference in
    # speed between the two CPUs (on the fifty-second session's machine one ran the same
    # render 15-45 % slower than the other, for minutes at a time).
    p = [math.sqrt(q[i] * q[i + 1]) for i in range(0, len(q) - 1, 2)]
    print(f"{w:16s} A {statistics.median(x for x, _ in v):8.3f}  B {statistics.median(y for _, y in v):8.3f}  "
          f"B/A speed: geomean {g:.3f}; pairs of rounds: median {statistics.median(p):.3f} "
          f"({min(p):.3f}-{max(p):.3f}), B faster in {sum(x > 1 for x in p)}/{len(p)}")
PY
