"""Sequence reading, preprocessing, frame-by-frame fitting, texturing, the pipeline and the
experiment runner from Python."""
import os

import numpy as np
import pytest

import artex
from conftest import SMALL_CONFIG, SMALL_SEQUENCE


def test_fit_synthetic_scan(coarse_template):
    pose = artex.example_pose(coarse_template)
    scan = artex.synthetic_scan(coarse_template, pose)
    assert 100 < len(scan) < coarse_template.num_vertices
    fitter = artex.EMFitter(coarse_template, SMALL_CONFIG)
    summary = fitter.fit_frame(scan)
    assert summary.ok and summary.frame == 0 and summary.iterations > 0
    assert summary.final_cost < summary.initial_cost
    assert "frame 0" in str(summary) and len(summary.trace) == summary.iterations
    truth = artex.Skinning(coarse_template).apply(pose)
    error_mm = 1000 * np.linalg.norm(fitter.posed_vertices() - truth, axis=1).mean()
    assert error_mm < 20, error_mm
    assert fitter.frames_fitted == 1


def test_sequence_reader(small_sequence):
    seq = artex.SequenceReader(small_sequence)
    assert len(seq) == 3 and seq.has_ground_truth
    frame = seq.read_frame(0)
    assert frame.depth.shape == (240, 320) and frame.depth.dtype == np.uint16
    assert frame.color.shape == (254, 200, 3) and frame.color.dtype == np.uint8
    assert (frame.depth > 0).sum() > 1000
    pose, vertices = seq.read_ground_truth(0)
    assert pose.num_joints == 17 and vertices.shape[1] == 3
    assert seq.calibration.depth.width == 320
    assert len(seq.background_frames()) == 5
    with pytest.raises(IndexError):
        seq.read_frame(3)
    gt = artex.read_poses_csv(os.path.join(small_sequence, "groundtruth", "poses.csv"))
    assert gt["vectors"].shape == (3, 58)
    assert np.allclose(gt["poses"][0].to_vector(), pose.to_vector(), atol=1e-6)


def test_preprocess_fit_texture_frame_by_frame(small_sequence):
    seq = artex.SequenceReader(small_sequence)
    subject, _ = artex.read_glb(seq.ground_truth_subject_path)
    template = artex.generate_template(resolution=0, atlas_size=256)
    pre = artex.Preprocessor(seq.calibration)
    pre.train(seq.background_frames())
    fitter = artex.EMFitter(template, SMALL_CONFIG)
    texturer = artex.Texturer(template, SMALL_CONFIG)
    for i in range(len(seq)):
        frame = seq.read_frame(i)
        scan, stats = pre.process(frame)
        assert len(scan) > 500 and stats["foreground_pixels"] > 0
        assert pre.foreground_mask.shape == (240, 320)
        summary = fitter.fit_frame(scan)
        assert summary.ok, str(summary)
        posed = fitter.posed_vertices()
        tex = texturer.add_frame(i, frame.color, seq.calibration.color, posed)
        assert tex["frame"] == i
        # Same subject mesh as the truth? No (template differs); compare joints instead.
        truth_pose, _ = seq.read_ground_truth(i)
        skin = artex.Skinning(template)
        joint_error = np.linalg.norm(skin.posed_joint_centers(fitter.pose) -
                                     skin.posed_joint_centers(truth_pose), axis=1).mean()
        assert joint_error < 0.1, joint_error
    atlas = texturer.atlas()
    assert atlas.shape == (128, 128, 3)
    assert (np.asarray(texturer.triangle_frames) >= 0).sum() > 0
    assert subject.num_joints == 17


def test_config_errors_name_the_key(coarse_template):
    with pytest.raises(artex.Error, match="no_such_key"):
        artex.EMFitter(coarse_template, {"fitting": {"no_such_key": 1}})
    with pytest.raises(artex.Error):
        artex.check_config("fitting: [1, 2")
    assert "atlas_size" in artex.check_config(SMALL_CONFIG)


def test_pipeline_and_run_folder(small_sequence, tmp_path):
    out = str(tmp_path / "run")
    result = artex.run_pipeline(small_sequence, out, SMALL_CONFIG)
    assert len(result["frames"]) == 3 and result["has_ground_truth"]
    assert result["mean_vertex_error_mm"] < 60
    assert isinstance(result["frames"][0]["fit"], artex.FitSummary)
    run = artex.read_run(out)
    assert "tracked.glb" in run["files"] and run["summary"] is not None
    assert run["poses"]["vectors"].shape == (3, 58)
    assert run["metrics"] is not None
    joints = run["joint_errors"]  # each joint's error; a frame's mean is frames.csv's
    assert len(joints) == 1 + 17 and list(joints["frame"]) == [0, 1, 2]
    per_joint = np.stack([joints[k] for k in joints if k != "frame"])
    assert np.allclose(per_joint.mean(axis=0), run["frames"]["mean_joint_error_mm"], atol=1e-3)


def test_experiment_results(tmp_path):
    exp = tmp_path / "exp.yaml"
    spec = ", ".join(f"{k}: {v}" for k, v in dict(SMALL_SEQUENCE, frames=2).items())
    exp.write_text(
        "name: py\n"
        "base:\n  texture: {atlas_size: 128}\n  fitting: {max_fit_vertices: 800}\n"
        "template: {resolution: 0, atlas_size: 256}\n"
        f"sequences:\n  - {{name: walk, synth: {{{spec}}}}}\n"
        "grid:\n  texture.lambda: [0, 1]\n")
    out = str(tmp_path / "out")
    summary = artex.run_experiment(str(exp), out, jobs=1)
    assert summary["runs_total"] == 2 and summary["runs_failed"] == 0, summary
    results = artex.read_experiment(out)
    assert set(results["runs"]) == {"walk/texture.lambda=0", "walk/texture.lambda=1"} or len(results["runs"]) == 2
    names = {r["metric"] for r in results["rows"]}
    assert "mean_vertex_error_mm" in names
    assert all(isinstance(r["value"], float) for r in results["rows"])
    assert any(m["name"] == "mean_vertex_error_mm" for m in artex.metrics())
