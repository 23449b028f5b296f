"""The paper's experiments: device figures, the quick reproduction, photon counting."""

import json

import numpy as np
import pytest

from analytic.scenes.common import Illumination
from analytic.waveforms import make_waveform
from validation.cli import main
from validation.runs.paper import SPEED_OF_LIGHT, device_figures, poisson_cases


def test_device_figures_follow_the_stated_mapping():
    from scipy.integrate import quad

    unit = SPEED_OF_LIGHT / (750e6 * 0.1)
    figures = device_figures(period=0.1, unit_m=unit)
    assert figures["sampling_hz"] == pytest.approx(750e6)
    assert figures["bandwidth_hz"] == pytest.approx(375e6)
    waveform = make_waveform(Illumination(waveform="butterworth"), 0.1)
    area = quad(lambda t: float(waveform.intensity(np.array([t]))[0]), 0, waveform.duration,
                limit=200)[0]
    assert figures["pulse_energy_per_w_sr"] == pytest.approx(4 * np.pi * area * unit / SPEED_OF_LIGHT,
                                                             rel=1e-6)


@pytest.mark.slow      # 6 s; reproduce --quick also runs in docs/paper.md's slow snippet
def test_reproduce_quick_writes_report_with_every_claim(tmp_path):
    status = main(["reproduce", "--out", str(tmp_path / "q"), "--quick", "--quiet"])
    assert status == 0
    report = (tmp_path / "q" / "report.md").read_text()
    results = json.loads((tmp_path / "q" / "results.json").read_text())
    claims = {c["claim"].split(" (")[0].replace(" at every", " at every (T, W)")
              for c in results["claims"]}
    assert claims == {"reconstruction possible with impulsive illumination",
                      "conditioning improves as W grows and T shrinks",
                      "low-pass beats impulsive at every (T, W)"}
    assert "375" in report and (tmp_path / "q" / "panels_paper_I1.png").exists()
    assert (tmp_path / "q" / "conditioning_paper_I10000.png").exists()
    # the report embeds every figure it made, and links nothing that does not exist
    import re
    linked = set(re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report))
    made = {p.name for p in (tmp_path / "q").glob("*.png")}
    assert linked == made


def test_photon_counting_comparison_counts_whole_photons_with_one_detector():
    rows = poisson_cases(pixels=8, periods=(0.1,), extents=(1.0,), progress=False)
    assert {r["illumination"] for r in rows} == {"impulsive", "low-pass"}
    impulsive, low_pass = sorted(rows, key=lambda r: r["illumination"] != "impulsive")
    # One detector: the photon ratio is the ratio of the pulses' energies (Σ_n κ_n = ∫ s when the
    # bins cover the response), up to the clipped Butterworth undershoot.
    energy = {name: make_waveform(Illumination(waveform=name), 0.1).energy for name in ("square", "butterworth")}
    ratio = low_pass["expected_photons"] / impulsive["expected_photons"]
    assert ratio == pytest.approx(energy["butterworth"] / energy["square"], rel=1e-2)
    assert all(np.isfinite(r["psnr"]) for r in rows)
