#!/usr/bin/python3
"""The machine's speed against `artex track`'s frame rate (docs/realtime-later-rounds.md, "The
machine's speed against the frame rate"): rounds of a fixed reference workload followed by the
pipelined 60-frame walk with ground truth, for one build or two alternating, over some minutes.

  bench/track_phase.py [--artex build/experiments/artex] [--baseline OTHER/artex]
                       [--minutes 30] [--work /tmp/artex-rt-bench] [--color-size 640x480]

The reference is the same pure-Python loop in two processes at once, one per core of the
2-core machine; its time (the slower process's seconds) tells how fast the machine runs at
that moment, which a virtual machine that reports no steal time does not say otherwise. The
walk is synthesised once into --work (as bench/track_realtime.py does). Prints a table by
reference band, the thirds of the rounds by the reference's time (median frames/s, range, runs
at 30 or more, after the first frame, latency; comparable within one invocation, since the
machine's speed differs from day to day),
the correlation of the reference's time with the frame rate and, with --baseline, how often
and by how much the first build was the faster of a round.
"""
import argparse
import math
import os
import statistics
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from track_realtime import parse_size, synth, track  # noqa: E402

REFERENCE = "s = 0\nfor i in range(6000000):\n    s += i * i\n"


def reference_seconds():
    """Seconds of the slower of two concurrent processes running REFERENCE."""
    start = time.monotonic()
    procs = [subprocess.Popen([sys.executable, "-c", REFERENCE]) for _ in range(2)]
    ends = []
    for p in procs:
        p.wait()
        ends.append(time.monotonic() - start)
    return max(ends)


def walk_figures(artex, seq, out, config):
    """frames/s, frames/s after the first frame and median latency of one pipelined run."""
    rt = track(artex, seq, out, config, ["pipeline.concurrency=pipelined"])["realtime"]
    return rt["frames_per_second"], rt["steady_frames_per_second"], rt["latency_median_ms"]


def band_table(rows, labels):
    """Rows by the reference's time in thirds of the rounds (the machine's speed differs from
    day to day, so fixed bands would put every round of a fast day in one), then all."""
    refs = sorted(r["reference"] for r in rows)
    cuts = [refs[len(refs) // 3], refs[2 * len(refs) // 3]]
    bands = [(0.0, cuts[0]), (cuts[0], cuts[1]), (cuts[1], float("inf"))]
    print("reference s    rounds  " + "  ".join("%-44s" % l for l in labels))
    for lo, hi in bands + [(0.0, float("inf"))]:
        sel = [r for r in rows if lo <= r["reference"] < hi]
        if not sel:
            continue
        times = [r["reference"] for r in sel]
        name = ("all" if (lo, hi) == (0.0, float("inf"))
                else "%.2f-%.2f" % (min(times), max(times)))
        cells = []
        for label in labels:
            fps = [r[label][0] for r in sel]
            steady = [r[label][1] for r in sel]
            latency = [r[label][2] for r in sel]
            cells.append("%.1f (%.1f-%.1f), >=30 %d, >1 %.1f, lat %.0f ms" % (
                statistics.median(fps), min(fps), max(fps), sum(f >= 30 for f in fps),
                statistics.median(steady), statistics.median(latency)))
        print("%-14s %6d  %s" % (name, len(sel), "  ".join("%-44s" % c for c in cells)))


def sign_test(wins, losses):
    """Two-sided sign test: the probability of a split at least this uneven by chance."""
    n = wins + losses
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(max(wins, losses), n + 1)) / 2.0 ** n
    return min(1.0, 2.0 * tail)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--artex", default="build/experiments/artex")
    ap.add_argument("--baseline", default="", help="a second artex binary, alternating")
    ap.add_argument("--config", default="configs/default.yaml")
    ap.add_argument("--baseline-config", default="",
                    help="its configuration (default: --config)")
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--work", default="/tmp/artex-rt-bench")
    ap.add_argument("--color-size", type=parse_size, default=(640, 480))
    args = ap.parse_args()
    if not args.minutes > 0:
        ap.error("--minutes: expected > 0, found %g" % args.minutes)
    os.makedirs(args.work, exist_ok=True)
    seq = synth(args.artex, args.frames, os.path.join(
        args.work, "walk%d_%dx%d" % ((args.frames,) + args.color_size)), args.color_size)
    builds = [("this", args.artex, args.config)]
    if args.baseline:
        builds.append(("baseline", args.baseline, args.baseline_config or args.config))
    labels = [b[0] for b in builds]
    rows = []
    end = time.monotonic() + 60.0 * args.minutes
    while time.monotonic() < end:
        row = {"reference": reference_seconds()}
        order = builds if len(rows) % 2 == 0 else builds[::-1]
        for label, binary, config in order:
            out = os.path.join(args.work, "phase_" + label)
            row[label] = walk_figures(binary, seq, out, config)
        rows.append(row)
        print("round %d: reference %.2f s, %s" % (len(rows), row["reference"], ", ".join(
            "%s %.1f frames/s" % (l, row[l][0]) for l in labels)), file=sys.stderr)
    band_table(rows, labels)
    refs = [r["reference"] for r in rows]
    fps = [r["this"][0] for r in rows]
    if len(rows) > 2 and statistics.pstdev(refs) > 0 and statistics.pstdev(fps) > 0:
        print("correlation of the reference's time with this build's frames/s: %.2f"
              % statistics.correlation(refs, fps))
    if args.baseline:
        diff = [r["this"][0] - r["baseline"][0] for r in rows]
        faster, slower = sum(d > 0 for d in diff), sum(d < 0 for d in diff)
        print("this build faster in %d of %d rounds (slower in %d), by a median of %+.2f "
              "frames/s; two-sided sign test p = %.3g"
              % (faster, len(diff), slower, statistics.median(diff), sign_test(faster, slower)))


if __name__ == "__main__":
    main()
