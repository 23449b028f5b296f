"""PSNR and SSIM against their definitions, window by window."""

import numpy as np
import pytest

from analytic.inversion import image_metrics


def test_image_metrics_against_definitions_and_window_by_window_ssim(rng):
    truth = rng.random((12, 12))
    estimate = np.clip(truth + 0.1 * rng.standard_normal(truth.shape), 0, 1)
    metrics = image_metrics(estimate, truth, data_range=1.0)
    assert metrics["mse"] == pytest.approx(np.mean((estimate - truth) ** 2))
    assert metrics["psnr"] == pytest.approx(-10 * np.log10(metrics["mse"]))
    values = []
    c1, c2 = 0.01**2, 0.03**2
    for r in range(3, 9):
        for c in range(3, 9):
            a = estimate[r - 3:r + 4, c - 3:c + 4].ravel()
            b = truth[r - 3:r + 4, c - 3:c + 4].ravel()
            cov = np.cov(a, b)
            values.append((2 * a.mean() * b.mean() + c1) * (2 * cov[0, 1] + c2)
                          / ((a.mean()**2 + b.mean()**2 + c1) * (cov[0, 0] + cov[1, 1] + c2)))
    assert metrics["ssim"] == pytest.approx(np.mean(values), rel=1e-10)
    same = image_metrics(truth, truth)
    assert same["mse"] == 0 and same["psnr"] == np.inf and same["ssim"] == pytest.approx(1.0)
    assert image_metrics(truth + 0.1, truth)["psnr"] == pytest.approx(20.0)
