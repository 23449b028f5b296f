"""Conditioning summaries on known singular values."""


import numpy as np
import pytest

from analytic.operator.conditioning import conditioning_summary


def test_conditioning_summary_on_known_singular_values():
    from analytic.operator.conditioning import singular_values

    values = np.array([5.0, 1.0, 0.2, 0.05])
    matrix = np.vstack([np.diag(values), np.zeros((3, 4))])  # zero rows add nothing
    assert np.allclose(singular_values(matrix), values)
    summary = conditioning_summary(singular_values(matrix), 4, 7, sigma=0.1)
    assert summary["condition"] == pytest.approx(100.0)
    assert summary["effective_rank"] == 3 and summary["numerical_rank"] == 4
    deficient = conditioning_summary(np.array([2.0, 1e-20]), 2, 2, sigma=0.1)
    assert deficient["condition"] == np.inf and deficient["numerical_rank"] == 1
