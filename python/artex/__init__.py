"""artex: articulated 3D human tracking with on-the-fly texturing from RGB-D.

The C++ core (``artex._artex``) gives the template, poses, skinning with its Jacobian,
recording readers, preprocessing, the EM fitter, the texturer, the pipeline and the
experiment runner; this package adds plain-Python readers of the files artex writes
(run folders, experiment results, pose tables) returning dicts and numpy arrays.

Conventions: positions are N x 3 float64 arrays in metres, triangles F x 3 int32, colour
images H x W x 3 uint8 RGB, depth images H x W uint16 (0 = missing). Errors raise
``artex.Error``. Options are given as dicts nested like ``configs/default.yaml``
(e.g. ``{"fitting": {"max_iterations": 10}}``) or as YAML text. See docs/python.md.
"""

import csv
import json
import os

import numpy as np

from ._artex import *  # noqa: F401,F403  (the C++ classes and functions)
from ._artex import Pose, Scan, vertex_normals

__all__ = [name for name in dir() if not name.startswith("_")]


def read_csv_columns(path):
    """A CSV file with a header as a dict of column name -> numpy array (numbers where every
    entry parses as a float, else an array of strings)."""
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    if not rows:
        return {}
    header, body = rows[0], rows[1:]
    columns = {}
    for i, name in enumerate(header):
        values = [r[i] if i < len(r) else "" for r in body]
        try:
            columns[name] = np.array([float(v) for v in values])
        except ValueError:
            columns[name] = np.array(values)
    return columns


def read_poses_csv(path, num_joints=17):
    """A pose table (poses.csv of a run, groundtruth/poses.csv of a sequence).

    Returns a dict: 'frames' (N int array), 'columns' (names), 'vectors' (N x P array, the
    Pose.to_vector layout) and 'poses' (list of artex.Pose)."""
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r and r[0].strip() and not r[0].startswith("#")]
    columns = []
    if rows and rows[0][0].strip() == "frame":
        columns, rows = rows[0], rows[1:]
    has_frame = bool(columns)
    values = np.array([[float(v) for v in r] for r in rows], dtype=float).reshape(len(rows), -1)
    if has_frame:
        frames, vectors = values[:, 0].astype(int), values[:, 1:]
        columns = columns[1:]
    else:
        frames, vectors = np.arange(len(rows)), values
    poses = [Pose.from_vector(v, num_joints) for v in vectors]
    return {"frames": frames, "columns": columns, "vectors": vectors, "poses": poses}


def _read_json(path):
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def read_run(run_dir, num_joints=17):
    """The results of one `artex track` / pipeline run folder as plain structures:
    'summary' and 'metrics' (dicts from summary.json / metrics.json, None when absent),
    'poses' (read_poses_csv), 'frames' (frames.csv as columns), 'joint_errors' (joint_errors.csv
    as columns: frame and each joint's error in mm, with ground truth), 'results' (results.json
    of experiment runs), 'trace' (trace.csv columns), 'config' (config.yaml text) and 'files'."""
    def path(name):
        return os.path.join(run_dir, name)

    out = {
        "summary": _read_json(path("summary.json")),
        "metrics": _read_json(path("metrics.json")),
        "results": _read_json(path("results.json")),
        "poses": read_poses_csv(path("poses.csv"), num_joints) if os.path.exists(path("poses.csv")) else None,
        "frames": read_csv_columns(path("frames.csv")) if os.path.exists(path("frames.csv")) else None,
        "joint_errors": read_csv_columns(path("joint_errors.csv"))
        if os.path.exists(path("joint_errors.csv")) else None,
        "trace": read_csv_columns(path("trace.csv")) if os.path.exists(path("trace.csv")) else None,
        "config": open(path("config.yaml")).read() if os.path.exists(path("config.yaml")) else None,
        "files": sorted(os.listdir(run_dir)),
    }
    return out


def read_experiment(out_dir):
    """The results of `artex experiment` (or run_experiment): 'rows' (results.csv, one dict
    per run x metric with 'value' a float), 'runs' (dict "sequence/combination" -> the run's
    results.json) and 'summary' (summary.md text)."""
    rows = []
    results_csv = os.path.join(out_dir, "results.csv")
    if os.path.exists(results_csv):
        with open(results_csv, newline="") as f:
            for r in csv.DictReader(f):
                r["value"] = float(r["value"])
                rows.append(r)
    runs = {}
    runs_dir = os.path.join(out_dir, "runs")
    if os.path.isdir(runs_dir):
        for seq in sorted(os.listdir(runs_dir)):
            for comb in sorted(os.listdir(os.path.join(runs_dir, seq))):
                res = _read_json(os.path.join(runs_dir, seq, comb, "results.json"))
                if res is not None:
                    runs[seq + "/" + comb] = res
    summary_md = os.path.join(out_dir, "summary.md")
    summary = open(summary_md).read() if os.path.exists(summary_md) else None
    return {"rows": rows, "runs": runs, "summary": summary}


def example_pose(template, bend_deg=20.0):
    """A pose with bent elbows and knees (rest position, facing +Z), for tests and examples."""
    pose = Pose(template.num_joints)
    rotations = pose.joint_rotations
    angle = np.radians(bend_deg)
    c, s = np.cos(angle), np.sin(angle)
    about_x = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    for name in ("l_elbow", "r_elbow", "l_knee", "r_knee"):
        j = template.find_joint(name)
        if j >= 0:
            rotations[j] = about_x if "knee" in name else about_x.T
    pose.joint_rotations = rotations
    return pose


def synthetic_scan(template, pose, camera_center=(0.0, 1.0, 2.5), stride=1):
    """A Scan of the template posed at `pose` as a depth camera at camera_center would see
    it: the posed vertices whose normals face the camera (every stride-th), normals flipped
    towards it like a real depth mesh's. A noise-free frame for trying the fitter."""
    posed = Skinning(template).apply(pose)  # noqa: F405
    normals = vertex_normals(posed, template.triangles)
    to_camera = np.asarray(camera_center, dtype=float)[None, :] - posed
    visible = np.einsum("ij,ij->i", normals, to_camera) > 0
    idx = np.nonzero(visible)[0][::stride]
    return Scan(posed[idx].copy(), normals[idx].copy())
