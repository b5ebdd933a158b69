"""Template, poses, skinning and .glb I/O from Python."""
import numpy as np
import pytest

import artex


def test_template_arrays(coarse_template):
    t = coarse_template
    assert t.num_joints == 17
    assert t.vertices.shape == (t.num_vertices, 3) and t.vertices.dtype == np.float64
    assert t.triangles.shape == (t.num_triangles, 3)
    assert t.triangles.min() >= 0 and t.triangles.max() < t.num_vertices
    assert t.has_uvs and t.uvs.min() >= 0 and t.uvs.max() <= 1
    assert t.joint_names[0] == "pelvis" and t.find_joint("r_knee") == 15
    assert t.joint_centers.shape == (17, 3)
    assert np.all((t.lbs_weight >= 0) & (t.lbs_weight <= 1))
    t.validate()


def test_invalid_template_raises(coarse_template):
    bad = artex.Template()
    bad.vertices = coarse_template.vertices
    bad.triangles = coarse_template.triangles
    with pytest.raises(artex.Error):
        bad.validate()


def test_glb_round_trip(coarse_template, tmp_path):
    path = str(tmp_path / "t.glb")
    texture = np.zeros((16, 32, 3), np.uint8)
    texture[:, :, 0] = 200
    artex.write_glb(path, coarse_template, texture)
    back, tex = artex.read_glb(path)
    assert back.num_vertices == coarse_template.num_vertices
    assert np.abs(back.vertices - coarse_template.vertices).max() < 1e-6  # float storage
    assert np.array_equal(back.triangles, coarse_template.triangles)
    assert tex.shape == (16, 32, 3) and tex[0, 0, 0] == 200 and tex[0, 0, 2] == 0
    with pytest.raises(artex.Error):
        artex.read_glb(str(tmp_path / "missing.glb"))


def test_pose_vector_round_trip(coarse_template):
    pose = artex.example_pose(coarse_template)
    v = pose.to_vector()
    assert v.shape == (pose.num_parameters,) == (58,)
    back = artex.Pose.from_vector(v, 17)
    assert np.allclose(back.to_vector(), v)
    delta = np.linspace(-0.05, 0.05, 58)
    moved = pose.retracted(delta)
    assert np.allclose(pose.local_coordinates(moved), delta, atol=1e-9)
    with pytest.raises(artex.Error):
        artex.Pose.from_vector(v[:10], 17)


def test_skinning_jacobian_matches_finite_differences(coarse_template):
    skinning = artex.Skinning(coarse_template)
    pose = artex.example_pose(coarse_template)
    posed, jac = skinning.apply_with_jacobian(pose)
    assert posed.shape == (coarse_template.num_vertices, 3)
    assert jac.shape == (3 * coarse_template.num_vertices, 58)
    assert np.allclose(posed, skinning.apply(pose))
    h = 1e-6
    for column in (0, 2, 5, 7 + 3 * 6, 7 + 3 * 15 + 1):
        delta = np.zeros(58)
        delta[column] = h
        numeric = (skinning.apply(pose.retracted(delta)) - skinning.apply(pose.retracted(-delta))) / (2 * h)
        assert np.abs(numeric.reshape(-1) - jac[:, column]).max() < 1e-5, column
    rest = skinning.apply(artex.Pose(17))
    assert np.allclose(rest, coarse_template.vertices)
    assert skinning.posed_joint_centers(artex.Pose(17)).shape == (17, 3)


def test_default_template_is_the_generated_one_from_the_cache(tmp_path):
    cache = tmp_path / "cache"
    first = artex.default_template(cache_dir=str(cache))  # generated, then written
    files = list(cache.glob("template-*.bin"))
    assert len(files) == 1 and files[0].stat().st_size > 100000
    second = artex.default_template(cache_dir=str(cache))  # read back
    generated = artex.generate_template()
    for t in (first, second):
        assert np.array_equal(t.vertices, generated.vertices)
        assert np.array_equal(t.lbs_weight, generated.lbs_weight)
        assert np.array_equal(t.uvs, generated.uvs)
        assert np.array_equal(t.joint_centers, generated.joint_centers)
    off = tmp_path / "off"
    artex.default_template(cache=False, cache_dir=str(off))
    assert not off.exists()
    files[0].write_bytes(b"ARTEXTPL damaged")
    with pytest.warns(RuntimeWarning, match="checksum|truncated|header"):
        artex.default_template(cache_dir=str(cache))
    assert files[0].stat().st_size > 100000
