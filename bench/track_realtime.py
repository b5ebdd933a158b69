#!/usr/bin/python3
"""Whole `artex track` on a virtual-Kinect walk, side by side in one run (docs/realtime.md):
sequential vs pipelined (frames/s, latency median/p95, CPU utilisation, peak RSS, accuracy),
live replay at the recording's 30 Hz (frames dropped), and peak RSS against sequence length.

  bench/track_realtime.py [--artex build/experiments/artex] [--baseline OTHER/artex]
                          [--frames 60] [--long 300] [--work /tmp/artex-rt-bench]
                          [--color-size 640x480] [--repeat 3] [--set key=value ...]

--baseline: every run is also made with a second build (e.g. the previous version), the two
alternating run by run, so the two columns of a row share the machine's load.
--repeat N: the whole list of runs N times over (still alternating run by run); the table shows
each figure's median over the N, a second table their ranges. This machine's speed drifts by
10-20 % within minutes, more than many changes are worth: one invocation decides little.

Sequences are synthesised once into --work (artex synth --motion walk --seed 1: depth 640x480,
colour at the virtual Kinect's default 800x1016, or --color-size WxH, e.g. 640x480 as the
Kinect v1 and the real recordings deliver it).
"pipelined, no ground truth": the same walk without its groundtruth/ folder, as a sensor or a
real recording delivers it (no errors evaluated, no PSNR: those columns show nan).
Columns: fps over the frame loop (first read to last output) and after the first frame, latency,
CPU, drops, peak RSS, errors, and "wall s": the whole process from start to exit as a user waits
for it (/usr/bin/time: start-up, the default template, writing the outputs included).
Checks that the pipelined runs' poses.csv, labels.png and texture.png are the sequential run's
byte for byte (with and without ground truth: the evaluation does not touch the results).
Prints one table and writes WORK/results.json (results_WxH.json with --color-size). The machine
is shared: `uptime` is printed
before and after, and every figure of one table comes from the same invocation.
"""
import argparse
import hashlib
import json
import os
import re
import subprocess
import sys


def sh(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True)


def synth(artex, frames, out, color_size):
    if not os.path.exists(os.path.join(out, "calibration.yaml")):
        cmd = [artex, "synth", "--motion", "walk", "--frames", str(frames), "--seed", "1"]
        if color_size:
            cmd += ["--color-width", str(color_size[0]), "--color-height", str(color_size[1])]
        sh(cmd + ["-o", out])
    return out


def without_ground_truth(seq):
    """A sibling of the sequence folder without its groundtruth/ (links to the rest): the same
    frames as a sensor or a real recording delivers them, with nothing to evaluate."""
    out = seq.rstrip("/") + "_no_truth"
    os.makedirs(out, exist_ok=True)
    for name in os.listdir(seq):
        if name != "groundtruth" and not os.path.lexists(os.path.join(out, name)):
            os.symlink(os.path.abspath(os.path.join(seq, name)), os.path.join(out, name))
    return out


def parse_size(text):
    m = re.fullmatch(r"(\d+)x(\d+)", text)
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise argparse.ArgumentTypeError("expected WIDTHxHEIGHT (e.g. 640x480), found " + text)
    return int(m.group(1)), int(m.group(2))


# The results compared byte for byte between runs (SHA-256): with the same frames tracked and
# textured, the pipelined runs must give the sequential run's, with or without ground truth.
OUTPUTS = ("poses.csv", "labels.png", "texture.png")


def track(artex, seq, out, config, sets):
    cmd = ["/usr/bin/time", "-v", artex, "track", seq, "-c", config, "-o", out, "-q"]
    for s in sets:
        cmd += ["--set", s]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("artex track failed: " + " ".join(cmd) + "\n" + r.stderr[-2000:])
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    cpu = re.search(r"Percent of CPU this job got: (\d+)%", r.stderr).group(1)
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", r.stderr).group(1)
    parts = [float(p) for p in wall.split(":")]
    wall_s = sum(p * 60 ** (len(parts) - 1 - i) for i, p in enumerate(parts))
    with open(os.path.join(out, "realtime.json")) as f:
        rt = json.load(f)
    with open(os.path.join(out, "metrics.json")) as f:
        metrics = json.load(f)
    outputs = {}
    for name in OUTPUTS:
        with open(os.path.join(out, name), "rb") as f:
            outputs[name] = hashlib.sha256(f.read()).hexdigest()
    return {"rss_mb": rss / 1024.0, "process_cpu_percent": int(cpu), "process_wall_s": wall_s,
            "realtime": rt, "metrics": metrics, "outputs": outputs}


def median_result(reps):
    """One result whose numbers are the medians over the repetitions (of the same run): every
    numeric field of realtime.json and metrics.json, the stages' figures, RSS and CPU."""
    if len(reps) == 1:
        return reps[0]

    def median(values):
        values = sorted(values)
        n = len(values)
        return values[n // 2] if n % 2 else 0.5 * (values[n // 2 - 1] + values[n // 2])

    def merge(items):
        first = items[0]
        if isinstance(first, bool) or first is None or isinstance(first, str):
            return first
        if isinstance(first, (int, float)):
            numbers = [x for x in items if isinstance(x, (int, float))]
            return median(numbers) if len(numbers) == len(items) else first
        if isinstance(first, dict):
            return {k: merge([x.get(k) for x in items]) for k in first}
        if isinstance(first, list) and all(isinstance(x, list) and len(x) == len(first)
                                           for x in items):
            return [merge([x[i] for x in items]) for i in range(len(first))]
        return first

    return merge(reps)


def uptime():
    return sh(["uptime"]).stdout.strip()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--artex", default="build/experiments/artex")
    ap.add_argument("--config", default="configs/default.yaml")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--long", type=int, default=300, help="frames of the RSS comparison (0: skip)")
    ap.add_argument("--work", default="/tmp/artex-rt-bench")
    ap.add_argument("--set", action="append", default=[], help="extra --set for every run")
    ap.add_argument("--no-live", action="store_true")
    ap.add_argument("--repeat", type=int, default=1,
                    help="make every run this many times (alternating); report medians and ranges")
    ap.add_argument("--color-size", type=parse_size, default=None,
                    help="colour camera WIDTHxHEIGHT of the synthesised walks (default: the "
                         "virtual Kinect's 800x1016)")
    ap.add_argument("--baseline", default="", help="a second artex binary, run alternately")
    ap.add_argument("--baseline-config", default="",
                    help="its configuration (default: configs/default.yaml of its source tree, "
                         "two levels above the binary's folder)")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat: expected >= 1, found %d" % args.repeat)
    os.makedirs(args.work, exist_ok=True)
    suffix = "_%dx%d" % args.color_size if args.color_size else ""
    seq = synth(args.artex, args.frames, os.path.join(args.work, "walk%d%s" % (args.frames, suffix)),
                args.color_size)
    # (name, sequence, --set values, checked byte for byte against the sequential run: the
    # same frames of the same walk; live runs drop frames, the long run is another walk)
    runs = [
        ("sequential", seq, ["pipeline.concurrency=sequential"], False),
        ("pipelined", seq, ["pipeline.concurrency=pipelined"], True),
        ("pipelined, no ground truth", without_ground_truth(seq),
         ["pipeline.concurrency=pipelined"], True),
    ]
    if not args.no_live:
        runs.append(("pipelined live 30 Hz", seq, ["pipeline.live=true"], False))
    if args.long > 0:
        long_seq = synth(args.artex, args.long,
                         os.path.join(args.work, "walk%d%s" % (args.long, suffix)), args.color_size)
        runs.append(("pipelined %d frames" % args.long, long_seq,
                     ["pipeline.concurrency=pipelined"], False))
        if not args.no_live:
            runs.append(("pipelined live 30 Hz, %d frames" % args.long, long_seq,
                         ["pipeline.live=true"], False))
    before = uptime()
    binaries = [("", args.artex, args.config)]
    if args.baseline:
        config = args.baseline_config or os.path.join(
            os.path.dirname(os.path.abspath(args.baseline)), "..", "..", "configs", "default.yaml")
        binaries.append(("baseline ", args.baseline, config))
    repetitions = {}
    for rep in range(args.repeat):
        for name, s, sets, _ in runs:
            # Every other repetition the baseline goes first: a run that follows another on a
            # warm machine (caches, frequency) is not always the same build's.
            for label, binary, config in (binaries if rep % 2 == 0 else binaries[::-1]):
                out = os.path.join(args.work,
                                   "run_" + re.sub(r"[^a-z0-9]+", "_", label + name) + suffix +
                                   ("_%d" % rep if args.repeat > 1 else ""))
                r = track(binary, s, out, config, sets + args.set)
                repetitions.setdefault(label + name, []).append(r)
    results = {key: median_result(reps) for key, reps in repetitions.items()}
    after = uptime()
    with open(os.path.join(seq, "calibration.yaml")) as f:
        calibration = f.read()
    color = re.search(r"color:\s*\n\s*width: (\d+).*\n\s*height: (\d+)", calibration)
    color_size = "%sx%s" % color.groups() if color else "unknown"
    print("colour camera: " + color_size + " (depth 640x480)")
    print("load before: " + before)
    print("load after:  " + after)
    head = ("%-34s %7s %7s %8s %8s %6s %5s %8s %8s %7s %7s %7s"
            % ("run", "fps", "fps>1", "lat med", "lat p95", "CPU", "drop", "drop>1", "RSS MB",
               "err mm", "PSNR", "wall s"))
    print(head)
    for name, r in results.items():
        rt, m = r["realtime"], r["metrics"]
        print("%-34s %7.1f %7.1f %8.0f %8.0f %5.0f%% %5d %8d %8.0f %7.3f %7.3f %7.2f"
              % (name, rt["frames_per_second"], rt["steady_frames_per_second"],
                 rt["latency_median_ms"] or 0, rt["latency_p95_ms"] or 0,
                 100 * rt["cpu_utilisation"], rt["frames_dropped"],
                 rt["frames_dropped_after_first"], r["rss_mb"],
                 m["mean_vertex_error_mm"] or float("nan"),
                 m["mean_novel_view_psnr_db"] or float("nan"), r["process_wall_s"]))
    if args.repeat > 1:
        print("ranges over the %d repetitions (min-max):" % args.repeat)

        def span(reps, field, fmt):
            values = sorted(r["realtime"][field] or 0 for r in reps)
            return (fmt + "-" + fmt) % (values[0], values[-1])

        for key, reps in repetitions.items():
            walls = sorted(r["process_wall_s"] for r in reps)
            print("  %-32s fps %s, fps>1 %s, lat med %s ms, drop %s, wall %.2f-%.2f s"
                  % (key, span(reps, "frames_per_second", "%.1f"),
                     span(reps, "steady_frames_per_second", "%.1f"),
                     span(reps, "latency_median_ms", "%.0f"),
                     span(reps, "frames_dropped", "%d"), walls[0], walls[-1]))
    # Byte for byte against the same build's sequential run.
    print("outputs (%s) the same as the sequential run's, in every repetition:" % ", ".join(OUTPUTS))
    for label, _, _ in binaries:
        reference = repetitions.get(label + "sequential", [])
        expected = {tuple(sorted(r["outputs"].items())) for r in reference}
        for name, _, _, compared in runs:
            if not compared:
                continue
            reps = repetitions[label + name]
            same = len(expected) == 1 and all(
                tuple(sorted(r["outputs"].items())) in expected for r in reps)
            print("  %-32s %s" % (label + name, "yes" if same else "NO"))
    # Stages by name (the two builds may have different stages: the pool stage is newer).
    print("stage busy ms/frame:")
    for name, r in results.items():
        print("  %-32s %s" % (name, ", ".join("%s %.1f" % (s["name"], s["ms_per_frame"])
                                              for s in r["realtime"]["stages"])))
    print("stage CPU ms/frame (sequential: the process's, pipelined: the stage thread's "
          "without oneTBB workers):")
    for name, r in results.items():
        print("  %-32s %s" % (name, ", ".join("%s %.1f" % (s["name"],
                                                           s.get("cpu_ms_per_frame", float("nan")))
                                              for s in r["realtime"]["stages"])))
    with open(os.path.join(args.work, "results%s.json" % suffix), "w") as f:
        json.dump({"uptime_before": before, "uptime_after": after, "color_size": color_size,
                   "repeat": args.repeat, "runs": results,
                   "repetitions": repetitions if args.repeat > 1 else {}}, f, indent=2)


if __name__ == "__main__":
    main()
