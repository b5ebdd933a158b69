#!/usr/bin/env python3
"""Plots of an `artex experiment` output folder (docs/experiments.md).

Usage: python3 scripts/plot_results.py OUT [--out-dir DIR] [--dpi N]

Reads OUT/results.csv and the complete runs OUT/runs/<sequence>/<configuration>/ (run.json,
trace.csv, em_trace.csv) and writes into OUT/plots/ (or DIR):
  per_frame_error.png      mean vertex error per frame, one panel per sequence
  vs_<key>.png             metrics against every swept numeric key (e.g. texture.lambda)
  stage_times.png          mean time per frame and stage, per configuration
  convergence.png          EM iterations per frame, and cost against EM iteration
Needs matplotlib (Debian: python3-matplotlib).
"""
import argparse
import csv
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# Metrics drawn against a swept numeric key, in this order when present.
SWEEP_METRICS = [
    ("mean_vertex_error_mm", "mean vertex error (mm)"),
    ("lost_fraction", "lost fraction"),
    ("seam_rms_after", "seam RMS after levelling"),
    ("seam_rms_before", "seam RMS before levelling"),
    ("changed_triangles", "changed triangles / frame"),
    ("mean_em_iterations", "EM iterations / frame"),
]
# Per-frame stages of trace.csv (ms), stacked in this order.
STAGES = [
    ("preprocess_ms", "preprocess"),
    ("icp_ms", "ICP (first frame)"),
    ("estep_ms", "E-step"),
    ("mstep_ms", "M-step"),
    ("texture_pool_ms", "texture pool"),
    ("texture_mrf_ms", "view selection (MRF)"),
    ("texture_sampling_ms", "texel sampling"),
    ("texture_levelling_ms", "seam levelling"),
]


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def to_float(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def load_runs(out):
    """Complete runs: dicts with sequence, combination, overrides, trace rows, em rows."""
    runs = []
    root = os.path.join(out, "runs")
    if not os.path.isdir(root):
        return runs
    for seq in sorted(os.listdir(root)):
        seq_dir = os.path.join(root, seq)
        if seq.startswith(".") or not os.path.isdir(seq_dir):
            continue
        for combo in sorted(os.listdir(seq_dir)):
            d = os.path.join(seq_dir, combo)
            if combo.startswith(".") or not os.path.isfile(os.path.join(d, "DONE")):
                continue
            with open(os.path.join(d, "run.json")) as f:
                info = json.load(f)
            with open(os.path.join(d, "results.json")) as f:
                results = json.load(f)
            runs.append({
                "sequence": seq,
                "combination": combo,
                "overrides": info.get("overrides", {}),
                "metrics": results.get("metrics", {}),
                "trace": read_csv(os.path.join(d, "trace.csv")),
                "em": read_csv(os.path.join(d, "em_trace.csv")),
            })
    return runs


def label(run, keys=None):
    items = [(k, v) for k, v in run["overrides"].items() if keys is None or k in keys]
    return ", ".join(f"{k.split('.')[-1]}={v}" for k, v in items) or "base"


def combinations(runs):
    seen = []
    for r in runs:
        if r["combination"] not in seen:
            seen.append(r["combination"])
    return seen


def save(fig, path, dpi):
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    print(f"plot_results: wrote {path}")


def panel_grid(count, width, height):
    """A figure with `count` panels of width x height inches, at most 3 per row; the panels as a
    flat list (unused cells of the last row hidden)."""
    cols = min(3, count)
    rows = (count + cols - 1) // cols
    fig, grid = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    axes = [ax for row in grid for ax in row]
    for ax in axes[count:]:
        ax.axis("off")
    return fig, axes


def plot_per_frame_error(runs, path, dpi):
    sequences = sorted({r["sequence"] for r in runs})
    has_truth = any(math.isfinite(to_float(row["vertex_error_mm"])) for r in runs for row in r["trace"])
    if not has_truth:
        return
    fig, axes = panel_grid(len(sequences), 4.2, 3.0)
    for ax, seq in zip(axes, sequences):
        for r in (r for r in runs if r["sequence"] == seq):
            rows = [row for row in r["trace"] if row["skipped"] == "0"]
            ax.plot([int(row["frame"]) for row in rows],
                    [to_float(row["vertex_error_mm"]) for row in rows], label=label(r), lw=1.2)
        ax.set_title(seq, fontsize=9)
        ax.set_xlabel("frame")
        ax.set_ylabel("mean vertex error (mm)")
        ax.grid(alpha=0.3)
    axes[len(sequences) - 1].legend(fontsize=7)
    save(fig, path, dpi)


def numeric_keys(runs):
    keys = []
    all_keys = []
    for r in runs:
        for k in r["overrides"]:
            if k not in all_keys:
                all_keys.append(k)
    for k in all_keys:
        values = {r["overrides"].get(k) for r in runs if k in r["overrides"]}
        if len(values) >= 2 and all(math.isfinite(to_float(v)) for v in values):
            keys.append(k)
    return keys, all_keys


def plot_against_key(runs, key, all_keys, path, dpi):
    metrics = [(m, t) for m, t in SWEEP_METRICS if any(m in r["metrics"] for r in runs)]
    if not metrics:
        return
    others = [k for k in all_keys if k != key]
    fig, axes = panel_grid(len(metrics), 3.6, 2.9)
    groups = {}
    for r in runs:
        if key not in r["overrides"]:
            continue
        group = r["sequence"] + ("" if not others else " | " + label(r, others))
        groups.setdefault(group, []).append(r)
    for ax, (metric, title) in zip(axes, metrics):
        for group, members in sorted(groups.items()):
            pts = sorted((to_float(r["overrides"][key]), r["metrics"].get(metric, math.nan)) for r in members)
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", lw=1.2, label=group)
        ax.set_xlabel(key)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axes[len(metrics) - 1].legend(fontsize=7)
    save(fig, path, dpi)


def plot_stage_times(runs, path, dpi):
    combos = combinations(runs)
    means = {}
    for c in combos:
        rows = [row for r in runs if r["combination"] == c for row in r["trace"] if row["skipped"] == "0"]
        means[c] = [sum(to_float(row.get(s, "nan")) for row in rows) / max(1, len(rows)) for s, _ in STAGES]
    fig, ax = plt.subplots(figsize=(9, 0.4 * len(combos) + 1.4))
    labels = []
    for c in combos:
        r = next(r for r in runs if r["combination"] == c)
        labels.append(label(r))
    left = [0.0] * len(combos)
    for i, (_, name) in enumerate(STAGES):
        widths = [means[c][i] if math.isfinite(means[c][i]) else 0.0 for c in combos]
        if not any(widths):
            continue
        ax.barh(range(len(combos)), widths, left=left, label=name)
        left = [l + w for l, w in zip(left, widths)]
    ax.set_yticks(range(len(combos)))
    ax.set_yticklabels(labels, fontsize=7)
    ax.set_xlabel("time per frame (ms), mean over sequences and frames")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.grid(axis="x", alpha=0.3)
    save(fig, path, dpi)


def plot_convergence(runs, path, dpi):
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.3))
    for c in combinations(runs):
        members = [r for r in runs if r["combination"] == c]
        frames = {}
        for r in members:
            for row in r["trace"]:
                if row["skipped"] == "0":
                    frames.setdefault(int(row["frame"]), []).append(int(row["em_iterations"]))
        xs = sorted(frames)
        a.plot(xs, [sum(frames[x]) / len(frames[x]) for x in xs], lw=1.2, label=label(members[0]))
    a.set_xlabel("frame")
    a.set_ylabel("EM iterations (mean over sequences)")
    a.grid(alpha=0.3)
    a.legend(fontsize=7)
    # Cost traces of a few frames of the first run (relative to the frame's first cost).
    first = runs[0]
    by_frame = {}
    for row in first["em"]:
        by_frame.setdefault(int(row["frame"]), []).append(to_float(row["cost"]))
    frames = sorted(by_frame)
    picks = sorted(set(frames[i] for i in [0, 1, len(frames) // 2, len(frames) - 1] if 0 <= i < len(frames)))
    for f in picks:
        costs = by_frame[f]
        c0 = costs[0] if costs and costs[0] > 0 else 1.0
        b.semilogy(range(1, len(costs) + 1), [max(c / c0, 1e-6) for c in costs], marker=".", label=f"frame {f}")
    b.set_xlabel("EM iteration")
    b.set_ylabel("cost / first cost")
    b.set_title(f"{first['sequence']} / {label(first)}", fontsize=8)
    b.grid(alpha=0.3)
    b.legend(fontsize=7)
    save(fig, path, dpi)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="output folder of `artex experiment`")
    parser.add_argument("--out-dir", help="where to write the PNGs (default OUT/plots)")
    parser.add_argument("--dpi", type=int, default=90)
    args = parser.parse_args()
    runs = load_runs(args.out)
    if not runs:
        print(f"plot_results: no complete runs in {args.out}", file=sys.stderr)
        return 1
    plots = args.out_dir or os.path.join(args.out, "plots")
    os.makedirs(plots, exist_ok=True)
    plot_per_frame_error(runs, os.path.join(plots, "per_frame_error.png"), args.dpi)
    keys, all_keys = numeric_keys(runs)
    for k in keys:
        plot_against_key(runs, k, all_keys, os.path.join(plots, f"vs_{k}.png"), args.dpi)
    plot_stage_times(runs, os.path.join(plots, "stage_times.png"), args.dpi)
    plot_convergence(runs, os.path.join(plots, "convergence.png"), args.dpi)
    return 0


if __name__ == "__main__":
    sys.exit(main())
