#!/usr/bin/env python3
"""Table and plot of the prediction experiment (configs/experiments/prediction.yaml).

Usage: python3 scripts/plot_prediction.py OUT [-o PNG]

Reads OUT/results.csv (tidy rows: experiment, sequence, fitting.prediction, metric, value) and
OUT/sequences/<name>/synth.yaml for each sequence's speed and frame step, prints a Markdown
table (one row per sequence and predictor) and draws mean vertex error, mean joint error, lost
frames and EM iterations per frame against the per-frame motion (speed x frame step): solid
lines for speed, dashed for dropped frames. Needs matplotlib (Debian: python3-matplotlib).
"""
import argparse
import csv
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PREDICTORS = ["previous", "constant_velocity", "kalman", "particle"]
METRICS = [
    ("mean_vertex_error_mm", "mean vertex error (mm)"),
    ("mean_joint_error_mm", "mean joint error (mm)"),
    ("lost_gt", "lost frames (ground truth); hollow: re-initialised"),
    ("mean_em_iterations", "EM iterations per frame"),
]


def synth_value(out, sequence, key, default):
    path = os.path.join(out, "sequences", sequence, "synth.yaml")
    try:
        with open(path) as f:
            for line in f:
                m = re.search(r"\b%s:\s*([0-9.]+)" % key, line)
                if m:
                    return float(m.group(1))
    except OSError:
        pass
    return default


def synth_motion(out, sequence):
    try:
        with open(os.path.join(out, "sequences", sequence, "synth.yaml")) as f:
            m = re.search(r"\bmotion:\s*(\w+)", f.read())
            return m.group(1) if m else "walk"
    except OSError:
        return "?"


def reinitialisations(out, sequence, predictor):
    """(frames, mean ms) of the tracking frames (all but the first) from the run's frames.csv:
    how many a re-initialisation replaced, and the initialisation time per tracking frame
    (every re-initialisation tried, kept or not); (nan, nan) when the run has no frames.csv."""
    path = os.path.join(out, "runs", sequence, "fitting.prediction=" + predictor, "frames.csv")
    try:
        with open(path) as f:
            tracked = [r for r in csv.DictReader(f) if r.get("frame") != "0"]
    except OSError:
        return float("nan"), float("nan")
    replaced = sum(1 for r in tracked if r.get("reinitialised") == "1")
    init_ms = sum(float(r.get("init_ms") or 0) for r in tracked)
    return replaced, init_ms / max(1, len(tracked))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("-o", "--output", default=None)
    args = ap.parse_args()
    rows = {}
    with open(os.path.join(args.out, "results.csv")) as f:
        for r in csv.DictReader(f):
            key = (r["sequence"], r["fitting.prediction"])
            try:
                rows.setdefault(key, {})[r["metric"]] = float(r["value"])
            except ValueError:
                pass
    sequences = sorted({s for s, _ in rows},
                       key=lambda s: (synth_value(args.out, s, "frame_step", 1),
                                      synth_value(args.out, s, "speed", 1), s))
    for (s, _), m in rows.items():
        m["frames"] = synth_value(args.out, s, "frames", 0)
        m["lost_gt"] = round(m.get("lost_fraction", 0.0) * m["frames"])
        m["reinitialised"], m["init_ms"] = reinitialisations(args.out, s, _)
    print("| sequence | speed | step | predictor | vertex error (mm) | joint error (mm) | "
          "lost (truth) | lost (quality) | re-initialised | EM iterations / frame | fit ms / frame | re-initialisation ms / frame |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for s in sequences:
        speed = synth_value(args.out, s, "speed", 1)
        step = synth_value(args.out, s, "frame_step", 1)
        for p in PREDICTORS:
            m = rows.get((s, p))
            if not m:
                continue
            print("| %s | %g | %g | %s | %.1f | %.1f | %d / %d | %d | %g | %.1f | %.0f | %.0f |" % (
                s, speed, step, p, m.get("mean_vertex_error_mm", float("nan")),
                m.get("mean_joint_error_mm", float("nan")), m["lost_gt"], m.get("frames", 0),
                m.get("lost_frames", 0), m["reinitialised"],
                m.get("mean_em_iterations", float("nan")),
                m.get("fit_ms", float("nan")), m["init_ms"]))
    if not args.output:
        return 0
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    colours = dict(zip(PREDICTORS, ["tab:gray", "tab:blue", "tab:green", "tab:red"]))
    for ax, (metric, label) in zip(axes.flat, METRICS):
        for p in PREDICTORS:
            for motion in sorted({synth_motion(args.out, q) for q in sequences}):
                for dropped in (False, True):
                    style = ("--s" if dropped else "-o") if motion != "walk" else ":^"
                    if dropped and motion == "walk":
                        continue
                    pts = []
                    for q in sequences:
                        if synth_motion(args.out, q) != motion or (q, p) not in rows:
                            continue
                        step = synth_value(args.out, q, "frame_step", 1)
                        speed = synth_value(args.out, q, "speed", 1)
                        if (step > 1) != dropped and not (dropped and step == 1 and speed == 1):
                            continue
                        pts.append((speed * step, rows[(q, p)].get(metric, float("nan"))))
                    pts.sort()
                    if pts:
                        ax.plot([x for x, _ in pts], [y for _, y in pts], style,
                                color=colours[p], alpha=0.6 if dropped else 0.9,
                                label="%s, %s%s" % (p, motion,
                                                    " (frames dropped)" if dropped else ""))
                        if metric == "lost_gt":
                            re = sorted((speed * step, rows[(q, p)]["reinitialised"])
                                        for q in sequences if (q, p) in rows
                                        and synth_motion(args.out, q) == motion
                                        for step in [synth_value(args.out, q, "frame_step", 1)]
                                        for speed in [synth_value(args.out, q, "speed", 1)]
                                        if (step > 1) == dropped or (speed * step == 1))
                            ax.plot([x for x, _ in re], [y for _, y in re], style,
                                    color=colours[p], alpha=0.6 if dropped else 0.9,
                                    markerfacecolor="none")
        ax.set_xlabel("motion per frame (speed x frame step)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Prediction against motion speed (solid, walk dotted) and dropped frames (dashed)")
    fig.tight_layout()
    fig.savefig(args.output, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
