#!/usr/bin/env python3
"""Compares two experiments' results.csv row by row, timing metrics aside.

usage: compare_results.py A/results.csv B/results.csv [TIMING_METRIC ...]
Exit 0 when both hold the same non-timing rows (same values), 1 otherwise (differences listed).
The timing metrics default to the ones artex marks as wall-clock dependent (docs/experiments.md).
"""
import csv
import sys

TIMING = {"preprocess_ms", "estep_ms", "mstep_ms", "fit_ms", "texture_ms", "texture_mrf_ms",
          "texture_levelling_ms", "frame_ms"}


def load(path, timing):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        sys.exit(f"{path}: empty")
    header = rows[0]
    metric = header.index("metric")
    table = {}
    for r in rows[1:]:
        if r[metric] in timing:
            continue
        key = tuple(r[:metric + 1])
        if key in table:
            sys.exit(f"{path}: duplicated row {key}")
        table[key] = r[metric + 1]
    return table


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    timing = set(sys.argv[3:]) or TIMING
    a, b = load(sys.argv[1], timing), load(sys.argv[2], timing)
    diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    print(f"compare_results: {len(a)} and {len(b)} rows (timing metrics aside), {len(diff)} differ")
    for k in diff[:20]:
        print("  ", ",".join(k), a.get(k, "(missing)"), b.get(k, "(missing)"))
    return 1 if diff or not a else 0


if __name__ == "__main__":
    sys.exit(main())
