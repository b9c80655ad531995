#!/usr/bin/env python3
"""A render's instructions per camera sample, by stage, from a callgrind profile.

    bench/budget.py CALLGRIND_OUT SAMPLES

Called by bench/budget.sh, which makes the profile. Reads `callgrind_annotate`'s inclusive
listing (each function's instructions with those of everything it calls) and its calling tree
(how often each function was called), and prints per camera sample:

- camera rays: the tile loop without the integrator (film and lens samples, the camera rays'
  packets through the structure, their hits' interactions, the film);
- closest-hit queries (`World::hit_skipping`) and shadow queries (`World::occluded_skipping`),
  with the number per sample and the instructions per query;
- path vertices: the integrator's own work (`Integrator::radiance8`, its queries taken out);
- the rest of the program (loading, building, writing the image).
"""
import re
import subprocess
import sys


def annotate(path, *args):
    cmd = ["callgrind_annotate", "--auto=no", "--threshold=100", *args, path]
    return subprocess.run(cmd, capture_output=True, text=True, check=True).stdout


COST = re.compile(r"^\s*([0-9,]+) \([^)]*\)\s+(\S.*)$")


def function_of(entry):
    """`file:function [object]` -> function."""
    entry = re.sub(r" \[[^\]]*\]$", "", entry)
    return entry.split(":", 1)[1] if ":" in entry else entry


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    path, samples = sys.argv[1], int(sys.argv[2])
    inclusive, total = {}, None
    for line in annotate(path, "--inclusive=yes").splitlines():
        m = COST.match(line)
        if not m:
            continue
        n = int(m.group(1).replace(",", ""))
        if m.group(2).startswith("PROGRAM TOTALS"):
            total = n
            continue
        # A function's code inlined from other files gets entries of its own, each counted
        # within the function's main entry: the largest is the function's whole count.
        f = function_of(m.group(2))
        inclusive[f] = max(inclusive.get(f, 0), n)
    calls = {}
    for line in annotate(path, "--tree=calling").splitlines():
        m = re.match(r"^\s*[0-9,]+ \([^)]*\)\s+>\s+(\S.*) \(([0-9,]+)x\)", line)
        if m:
            f = function_of(m.group(1).strip())
            calls[f] = calls.get(f, 0) + int(m.group(2).replace(",", ""))
    if total is None:
        sys.exit(f"{path}: no PROGRAM TOTALS in callgrind_annotate's output")

    def incl(pattern):
        return sum(n for f, n in inclusive.items() if re.search(pattern, f))

    def called(pattern):
        return sum(n for f, n in calls.items() if re.search(pattern, f))

    tiles = incl(r"^snell_core::render::render_with_aovs::\{\{closure\}\}$")
    integrator = incl(r"::radiance8$")
    closest, n_closest = incl(r"World<A>::hit_skipping$"), called(r"World<A>::hit_skipping$")
    shadow, n_shadow = incl(r"World<A>::occluded_skipping$"), called(r"World<A>::occluded_skipping$")
    if tiles == 0 or integrator == 0:
        sys.exit(
            f"{path}: no render tiles or no integrator in the profile: a build without symbols, or one "
            "whose `render_with_aovs` closure or `Integrator::radiance8` was inlined into its caller"
        )
    rows = [
        ("camera rays and film", tiles - integrator, None),
        ("closest-hit queries", closest, n_closest),
        ("shadow queries", shadow, n_shadow),
        ("path vertices (the integrator's own work)", integrator - closest - shadow, None),
        ("the rest (loading, building, writing)", total - tiles, None),
    ]
    print(f"instructions per camera sample: {total / samples:,.0f} ({total:,} over {samples:,} samples)")
    for name, n, count in rows:
        extra = ""
        if count:
            extra = f"   ({count / samples:.2f} per sample, {n / count:,.0f} each)"
        print(f"  {name:<44} {n / samples:8,.0f}  {100 * n / total:5.1f} %{extra}")


if __name__ == "__main__":
    main()
