"""Fixtures of the check tests: the small scene, its model and its scene file."""

import pytest

from analytic.operator.matrix_free import forward
from check_cases import small_scene, write_scene_file


@pytest.fixture(scope="module")
def scene():
    return small_scene()


@pytest.fixture(scope="module")
def model(scene):
    return forward(scene)


@pytest.fixture
def scene_file(tmp_path):
    return write_scene_file(tmp_path)
