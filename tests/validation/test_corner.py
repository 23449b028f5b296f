"""The corner: outside the one-bounce model, so the harness reports the share of further bounces."""

from validation.runs.corner import check_corner


def test_corner_reports_further_bounces_instead_of_agreement():
    result = check_corner(spp=2**20, seed=2)
    assert result["one_bounce_agrees"]
    assert 0.01 < result["further_bounce_share"] < 0.9
    assert not result["agreement_with_all_bounces"]

