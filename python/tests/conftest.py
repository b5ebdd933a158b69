"""Shared fixtures of the artex pytest suite: a coarse template and one small synthetic
sequence (3 frames, 320 x 240 depth, as tests/experiments/runner_test.cc), made once."""
import os

import pytest

import artex

SMALL_SEQUENCE = {
    "motion": "walk", "frames": 3, "seed": 1, "subject_resolution": 0, "texture_size": 256,
    "color_width": 200, "color_height": 254, "depth_width": 320, "depth_height": 240,
    "background_frames": 5,
}
# Pipeline options for small inputs (coarse template, small atlas).
SMALL_CONFIG = {"texture": {"atlas_size": 128}, "fitting": {"max_fit_vertices": 800}}


@pytest.fixture(scope="session")
def coarse_template():
    return artex.generate_template(resolution=0, atlas_size=256)


@pytest.fixture(scope="session")
def small_sequence(tmp_path_factory):
    folder = str(tmp_path_factory.mktemp("seq") / "walk")
    artex.synthesize_sequence(folder, SMALL_SEQUENCE)
    return folder


@pytest.fixture(scope="session")
def source_dir():
    return os.environ.get("ARTEX_SOURCE_DIR",
                          os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
