"""Exports from Python: exact animated glb, BVH, textured OBJ/PLY."""
import os

import numpy as np

import artex


def _poses(template, n=10):
    poses = []
    for i in range(n):
        pose = artex.example_pose(template, bend_deg=4.0 * i)
        # a twist of the right forearm, which glTF's plain LBS cannot express
        rotations = pose.joint_rotations
        c, s = np.cos(0.08 * i), np.sin(0.08 * i)
        rotations[template.find_joint("r_elbow")] = rotations[template.find_joint("r_elbow")] @ np.array(
            [[c, -s, 0], [s, c, 0], [0, 0, 1]])
        pose.joint_rotations = rotations
        poses.append(pose)
    return poses


def test_exact_glb_residual(coarse_template, tmp_path):
    poses = _poses(coarse_template)
    exact = artex.write_animated_glb(str(tmp_path / "exact.glb"), coarse_template, poses, 30.0)
    plain = artex.write_animated_glb(str(tmp_path / "plain.glb"), coarse_template, poses, 30.0,
                                     exact=False)
    assert exact["morph_targets"] == 10 and plain["morph_targets"] == 0
    assert exact["max_residual_mm"] <= 0.5
    assert plain["max_residual_mm"] > 1.0
    assert exact["bytes"] > plain["bytes"]
    back, _ = artex.read_glb(str(tmp_path / "exact.glb"))
    assert back.num_vertices == coarse_template.num_vertices


def test_bvh_round_trip(coarse_template, tmp_path):
    poses = _poses(coarse_template, 5)
    path = str(tmp_path / "motion.bvh")
    artex.write_bvh(path, coarse_template, poses, 30.0)
    clip = artex.read_bvh_joint_positions(path)
    assert abs(clip["frame_time"] - 1 / 30) < 1e-6 and len(clip["positions"]) == 5
    skinning = artex.Skinning(coarse_template)
    for f, pose in enumerate(poses):
        centres = skinning.posed_joint_centers(pose)
        for j, name in enumerate(coarse_template.joint_names):
            b = clip["names"].index(name)
            assert np.linalg.norm(clip["positions"][f][b] / 100.0 - centres[j]) < 1e-5


def test_textured_obj_and_zup_ply(coarse_template, tmp_path):
    posed = artex.Skinning(coarse_template).apply(artex.example_pose(coarse_template))
    obj = str(tmp_path / "mesh.obj")
    artex.write_textured_mesh(obj, coarse_template, posed, texture_file="texture.png")
    text = open(obj).read()
    assert "mtllib mesh.obj".replace(".obj", ".mtl") in text and "\nvt " in text
    assert "map_Kd texture.png" in open(str(tmp_path / "mesh.mtl")).read()
    first = [float(x) for x in text.split("\nv ")[1].split("\n")[0].split()]
    assert np.allclose(first, posed[0], atol=1e-6)
    ply = str(tmp_path / "mesh.ply")
    artex.write_textured_mesh(ply, coarse_template, posed, texture_file="texture.png", up="z")
    header = open(ply, "rb").read(400).decode("latin-1")
    assert "comment TextureFile texture.png" in header and "property float s" in header
    assert "Z up" in header
