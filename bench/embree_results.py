#!/usr/bin/env python3
"""Embree's benchmark output (`embree_bench`'s `RESULT key=value ...` lines) and which of its
measurements stand against which of `snell bench`'s workloads; vs_embree.sh and paired.sh read
it through here.

    python3 bench/embree_results.py < EMBREE_OUTPUT

prints one `workload Mrays/s` line per Snell workload (quality high, median of the repetitions).
"""
import sys

# Snell's workload: Embree's (api, kind) for the same rays.
WORKLOADS = {
    "primary": ("intersect1", "primary"),
    "bounce": ("intersect1", "diffuse_bounce"),
    "bounce-occluded": ("occluded1", "diffuse_bounce"),
    "primary-packets": ("intersect16", "primary"),
}


def results(lines):
    """The RESULT lines' fields by (quality, api, kind); other lines are passed over."""
    d = {}
    for line in lines:
        if line.startswith("RESULT"):
            kv = dict(x.split("=", 1) for x in line.split()[1:])
            d[(kv["quality"], kv["api"], kv["kind"])] = kv
    return d


if __name__ == "__main__":
    r = results(sys.stdin)
    for name, (api, kind) in WORKLOADS.items():
        if ("high", api, kind) in r:
            print(name, r[("high", api, kind)]["mrays_med"])
