"""validation.check.report: report.md, metrics.json (docs/design.md section 5's keys) and the figures, with a fit
or without one."""

from __future__ import annotations

import json

import numpy as np
import pytest

from analytic.operator.matrix_free import forward
from check_cases import noisy_replicas, one_bin_scene, run_check
from transient.render import render
from validation.check import check_transient, write_check_report

# Synthetic replicas are few (6) and independent from bin to bin: the limits' fallback to independent
# bins, and its warning, are what tests/validation/test_compare.py tests; here they are expected.
pytestmark = pytest.mark.filterwarnings("ignore::validation.judging.compare.CorrelationWarning")


def test_check_command_exit_status_and_report(tmp_path, scene_file, scene, model, rng):
    paths = []
    for r, replica in enumerate(noisy_replicas(model, rng)):
        paths.append(tmp_path / f"replica_{r}.npy")
        np.save(paths[-1], replica)
    assert run_check(scene_file, "--data", *paths, "--out", tmp_path / "good") == 0
    metrics = json.loads((tmp_path / "good" / "metrics.json").read_text())
    assert metrics["agrees"] is True and metrics["agrees_after_fit"] is True
    assert set(metrics["fit"]) >= {"scale", "scale_stderr", "offset_opl", "offset_stderr"}
    assert {"chi2_per_dof", "max_abs_z"} <= set(metrics)
    report = (tmp_path / "good" / "report.md").read_text()
    assert "(check_transients.png)" in report and "(check_z.png)" in report
    assert (tmp_path / "good" / "check_transients.png").is_file() and (tmp_path / "good" / "check_z.png").is_file()

    sigma = 0.0025 * model + 1e-6
    np.save(tmp_path / "quarter.npy", 0.25 * model + sigma * rng.standard_normal(model.shape))
    np.save(tmp_path / "sigma.npy", sigma)
    assert run_check(scene_file, "--data", tmp_path / "quarter.npy", "--stderr", tmp_path / "sigma.npy",
                     "--out", tmp_path / "quarter") == 1
    assert json.loads((tmp_path / "quarter" / "metrics.json").read_text())["agrees_after_fit"] is True

    assert run_check(scene_file, "--data", tmp_path / "quarter.npy", "--shape-only",
                     "--out", tmp_path / "shape") == 1
    assert "shape only" in (tmp_path / "shape" / "report.md").read_text()
    assert not (tmp_path / "shape" / "check_z.png").exists()


def test_report_of_a_render_check(tmp_path, scene, model):
    """write_check_report on its own: metrics.json written atomically with the section 5 keys."""
    single = render(scene, spp=2**18, seed=3, progress=False)
    result = check_transient(scene, single.mean, stderr=single.stderr, model=model)
    metrics = write_check_report(tmp_path, result, scene_name="small", data_paths=["render"])
    assert json.loads((tmp_path / "metrics.json").read_text()) == json.loads(json.dumps(metrics))


def test_the_report_of_a_result_without_a_fit(tmp_path, rng):
    scene = one_bin_scene()
    model = forward(scene)
    result = check_transient(scene, noisy_replicas(model, rng), model=model)
    metrics = write_check_report(tmp_path, result, scene_name="one bin")
    assert metrics["fit"] is None
    assert "cannot fit them" in (tmp_path / "report.md").read_text()
