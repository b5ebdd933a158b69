#!/usr/bin/python3
"""The first frame's multi-hypothesis initialisation over many first frames (docs/fitting.md,
"Initialisation: how often the first frame is wrong"): `artex track` of one frame, started at
several frames of several virtual-Kinect sequences (with ground truth) and at every frame of
real recordings (without), so that every run is a fresh initialisation.

  bench/init_eval.py [--artex build/experiments/artex] [--baseline OTHER/artex]
                     [--variant NAME:key=value,key=value ...] [--set key=value ...]
                     [--real FOLDER ...] [--starts 0,12,24,36,48] [--work /tmp/artex-init-eval]
                     [--verbose]

Arms: this build, --baseline (another build, its own configs/default.yaml beside it), and each
--variant (this build with those --set values; e.g. --variant p0:fitting.init.em_prune_margin=0).
The arms alternate init by init, so they share the machine's load. Sequences are synthesised
once into --work: six 60-frame walks, turns, arm raises, bends and punches with subjects from
1.6 to 1.9 m (`artex synth`, colour 640x480). Texturing is off (the initialisation only).

Per arm: init_ms (median, mean), on the synthetic frames the mean vertex and joint error, how
many first frames are wrong (mean joint error above --wrong-mm, 100 mm by default: the facing
turned round or a limb reversed, which the depth alone often explains as well) and how many of
those the fit quality still labels good; on real frames the labels and mean inlier / support
fractions; and how many initialisations gave the first arm's poses.csv byte for byte (a change
meant to be bit-identical shows all). --verbose prints every initialisation with its worst
joint (from the run's joint_errors.csv). Writes WORK/init_eval.json.
"""
import argparse
import csv
import json
import os
import statistics
import subprocess
import sys

SEQUENCES = [  # name, artex synth flags
    ("walk_s1", ["--motion", "walk", "--seed", "1"]),
    ("walk_s2_160", ["--motion", "walk", "--seed", "2", "--subject-height", "1.6"]),
    ("turn_s3", ["--motion", "turn", "--seed", "3"]),
    ("arm_raise_s4_190", ["--motion", "arm_raise", "--seed", "4", "--subject-height", "1.9",
                          "--subject-girth", "1.3"]),
    ("bend_s5", ["--motion", "bend", "--seed", "5"]),
    ("punch_kick_s6_180", ["--motion", "punch_kick", "--seed", "6", "--subject-height", "1.8"]),
]


def synth(artex, work, name, flags):
    out = os.path.join(work, name)
    if not os.path.exists(os.path.join(out, "calibration.yaml")):
        subprocess.run([artex, "synth", "--frames", "60", "--color-width", "640",
                        "--color-height", "480", "-o", out] + flags,
                       check=True, capture_output=True, text=True)
    return out


def frame_count(folder):
    """Frames of a TUM folder (depth.txt lines that are not comments)."""
    with open(os.path.join(folder, "depth.txt")) as f:
        return sum(1 for line in f if line.strip() and not line.startswith("#"))


def run_one(binary, config, folder, start, sets, out):
    cmd = [binary, "track", folder, "-o", out, "-q", "--set", "pipeline.first_frame=%d" % start,
           "--set", "pipeline.max_frames=1", "--set", "pipeline.texture=false",
           "--set", "pipeline.export_glb=false"]
    if config:
        cmd[3:3] = ["-c", config]
    for s in sets:
        cmd += ["--set", s]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("artex track failed: " + " ".join(cmd) + "\n" + r.stderr[-2000:])
    with open(os.path.join(out, "frames.csv")) as f:
        row = next(csv.DictReader(f))
    with open(os.path.join(out, "poses.csv"), "rb") as f:
        poses = f.read()

    worst = ("", float("nan"))  # the joint farthest from its true centre
    errors = os.path.join(out, "joint_errors.csv")
    if os.path.exists(errors):
        with open(errors) as f:
            joints = next(csv.DictReader(f), {})
        named = [(k, float(v)) for k, v in joints.items() if k != "frame" and v != "nan"]
        if named:
            worst = max(named, key=lambda kv: kv[1])

    def number(key):
        return float(row[key]) if row[key] not in ("", "nan") else float("nan")

    return {"init_ms": number("init_ms"), "label": row["quality"],
            "inliers": number("inlier_fraction"), "support": number("support_fraction"),
            "vertex_mm": number("mean_vertex_error_mm"), "joint_mm": number("mean_joint_error_mm"),
            "worst_joint": worst[0], "worst_joint_mm": worst[1], "poses": poses}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--artex", default="build/experiments/artex")
    ap.add_argument("--config", default="configs/default.yaml")
    ap.add_argument("--baseline", default="", help="a second artex binary, run alternately")
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME:key=value,key=value: this build with these settings, as an arm")
    ap.add_argument("--set", action="append", default=[], help="extra --set for every arm")
    ap.add_argument("--real", action="append", default=[],
                    help="a real recording (TUM folder): every frame is a first frame")
    ap.add_argument("--starts", default="0,12,24,36,48",
                    help="start frames in each synthetic sequence (comma-separated, < 60)")
    ap.add_argument("--wrong-mm", type=float, default=100.0,
                    help="a synthetic first frame is wrong above this mean joint error (mm)")
    ap.add_argument("--work", default="/tmp/artex-init-eval")
    ap.add_argument("--verbose", action="store_true", help="one line per initialisation")
    args = ap.parse_args()
    try:
        starts = [int(s) for s in args.starts.split(",")]
    except ValueError:
        ap.error("--starts: expected comma-separated frame numbers, found " + args.starts)
    if not starts or min(starts) < 0 or max(starts) >= 60:
        ap.error("--starts: expected frame numbers in [0, 60), found " + args.starts)
    arms = [("this", args.artex, args.config, [])]
    if args.baseline:
        arms.append(("baseline", args.baseline, os.path.join(
            os.path.dirname(os.path.abspath(args.baseline)), "..", "..", "configs",
            "default.yaml"), []))
    for v in args.variant:
        name, _, sets = v.partition(":")
        if not name or not sets:
            ap.error("--variant: expected NAME:key=value[,key=value], found " + v)
        arms.append((name, args.artex, args.config, sets.split(",")))
    os.makedirs(args.work, exist_ok=True)
    jobs = []
    for name, flags in SEQUENCES:
        folder = synth(args.artex, args.work, name, flags)
        jobs += [(name, folder, s, True) for s in starts]
    for folder in args.real:
        if not os.path.exists(os.path.join(folder, "depth.txt")):
            ap.error("--real: expected a TUM folder with depth.txt, found " + folder)
        name = os.path.basename(os.path.normpath(folder))
        jobs += [(name, folder, s, False) for s in range(frame_count(folder))]
    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    results = {arm[0]: [] for arm in arms}
    for i, (name, folder, start, synthetic) in enumerate(jobs):
        order = arms if i % 2 == 0 else arms[::-1]
        for label, binary, config, sets in order:
            r = run_one(binary, config, folder, start, args.set + sets,
                        os.path.join(args.work, "run_" + label))
            r.update(sequence=name, start=start, synthetic=synthetic)
            results[label].append(r)
            if args.verbose:
                print("%-10s %-18s %3d %6.0f ms %-9s inliers %.3f support %.3f vertex %6.2f "
                      "joint %7.2f (worst %s %.0f)"
                      % (label, name, start, r["init_ms"], r["label"], r["inliers"], r["support"],
                         r["vertex_mm"], r["joint_mm"], r["worst_joint"] or "-",
                         r["worst_joint_mm"]), flush=True)
    print("load before: " + uptime)
    print("load after:  " + subprocess.run(["uptime"], capture_output=True,
                                           text=True).stdout.strip())
    first = arms[0][0]
    print("%-10s %8s %8s | %9s %9s %7s %9s | %6s %9s %8s %8s | %9s"
          % ("arm", "init med", "mean ms", "vertex mm", "joint mm", "wrong", "wrong ok",
             "real", "good/dbt", "inliers", "support", "as " + first))
    for label, rows in results.items():
        syn = [r for r in rows if r["synthetic"]]
        real = [r for r in rows if not r["synthetic"]]
        wrong = [r for r in syn if r["joint_mm"] > args.wrong_mm]
        same = sum(a["poses"] == b["poses"] for a, b in zip(rows, results[first]))
        print("%-10s %8.0f %8.0f | %9.2f %9.2f %3d/%-3d %9d | %6d %4d/%-4d %8.4f %8.4f | %5d/%-3d"
              % (label, statistics.median(r["init_ms"] for r in rows),
                 statistics.mean(r["init_ms"] for r in rows),
                 statistics.mean(r["vertex_mm"] for r in syn) if syn else float("nan"),
                 statistics.mean(r["joint_mm"] for r in syn) if syn else float("nan"),
                 len(wrong), len(syn), sum(r["label"] == "good" for r in wrong), len(real),
                 sum(r["label"] == "good" for r in real),
                 sum(r["label"] == "doubtful" for r in real),
                 statistics.mean(r["inliers"] for r in real) if real else float("nan"),
                 statistics.mean(r["support"] for r in real) if real else float("nan"),
                 same, len(rows)))
    if len(arms) > 1:
        ratios = [a["init_ms"] / b["init_ms"] for a, b in zip(results[arms[1][0]], results[first])
                  if b["init_ms"] > 0]
        print("init_ms %s / %s per initialisation: median %.3f"
              % (arms[1][0], first, statistics.median(ratios)))
    for rows in results.values():
        for r in rows:
            del r["poses"]
    with open(os.path.join(args.work, "init_eval.json"), "w") as f:
        json.dump({"load": uptime, "arms": [a[0] for a in arms], "results": results}, f, indent=1)


if __name__ == "__main__":
    main()
