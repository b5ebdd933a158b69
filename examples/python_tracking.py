#!/usr/bin/env python3
"""artex from Python, notebook style: synthesise a short recording with ground truth, then
preprocess, fit and texture it frame by frame, compare with the truth, and finally run the
whole pipeline and read its results as plain dicts and numpy arrays.

    cmake --build build                      # builds the module into build/python
    PYTHONPATH=build/python python3 examples/python_tracking.py [OUT_DIR]

Each "cell" below is independent enough to paste into a notebook.
"""
import os
import sys
import tempfile

import numpy as np

import artex

out = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="artex-example-")
os.makedirs(out, exist_ok=True)

# %% 1. The template: numpy arrays, joints, read/write .glb
template = artex.generate_template(resolution=0, atlas_size=256)  # coarse: ~3k vertices
print(template, "| joints:", ", ".join(template.joint_names[:5]), "...")
print("vertices", template.vertices.shape, "triangles", template.triangles.shape,
      "uvs", template.uvs.shape)
artex.write_glb(os.path.join(out, "template.glb"), template)

# %% 2. Poses and skinning with its Jacobian
pose = artex.example_pose(template)
skinning = artex.Skinning(template)
posed, jacobian = skinning.apply_with_jacobian(pose)
print("posed", posed.shape, "Jacobian", jacobian.shape, "(3V x 58)")

# %% 3. One synthetic frame, fitted: the one-line check of an installation
scan = artex.synthetic_scan(template, pose)
fitter = artex.EMFitter(template, {"fitting": {"max_fit_vertices": 800}})
print("fit of a synthetic scan:", fitter.fit_frame(scan))

# %% 4. A synthetic recording with ground truth (virtual Kinect)
sequence = os.path.join(out, "walk")
if not os.path.exists(sequence):
    artex.synthesize_sequence(sequence, {
        "motion": "walk", "frames": 5, "seed": 1, "subject_resolution": 0,
        "texture_size": 256, "color_width": 200, "color_height": 254,
        "depth_width": 320, "depth_height": 240, "background_frames": 5})
recording = artex.SequenceReader(sequence)
print(f"{len(recording)} frames, depth {recording.read_frame(0).depth.shape} uint16, "
      f"ground truth: {recording.has_ground_truth}")

# %% 5. Frame by frame: preprocessing, fitting, texturing
config = {"fitting": {"max_fit_vertices": 800}, "texture": {"atlas_size": 256}}
preprocessor = artex.Preprocessor(recording.calibration, config)
preprocessor.train(recording.background_frames())
fitter = artex.EMFitter(template, config)
texturer = artex.Texturer(template, config)
for i in range(len(recording)):
    frame = recording.read_frame(i)
    scan, stats = preprocessor.process(frame)
    summary = fitter.fit_frame(scan)
    texturer.add_frame(i, frame.color, recording.calibration.color, fitter.posed_vertices())
    truth_pose, _ = recording.read_ground_truth(i)
    joints_mm = 1000 * np.linalg.norm(
        skinning.posed_joint_centers(fitter.pose) - skinning.posed_joint_centers(truth_pose),
        axis=1).mean()
    print(f"frame {i}: {len(scan)} scan points, {summary.iterations} EM iterations, "
          f"{summary.termination}, joint error {joints_mm:.1f} mm")
atlas = texturer.atlas()  # H x W x 3 RGB
print("atlas", atlas.shape, "textured triangles",
      int((np.asarray(texturer.triangle_frames) >= 0).sum()))

# %% 6. The whole pipeline (as `artex track`) and its results as dicts / numpy
run_dir = os.path.join(out, "run")
result = artex.run_pipeline(sequence, run_dir, config)
print("pipeline: mean vertex error %.1f mm over %d frames" %
      (result["mean_vertex_error_mm"], len(result["frames"])))
run = artex.read_run(run_dir)
print("run files:", ", ".join(run["files"]))
print("poses.csv:", run["poses"]["vectors"].shape)
