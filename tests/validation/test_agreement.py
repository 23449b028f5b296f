"""The cross-check's verdict as a report: one paragraph and a JSON record that say what was judged and how."""

from __future__ import annotations

import json

from validation.judging.agreement import INDEPENDENT, SIGN_FLIP, null_note
from validation.judging.compare import compare_transients


def test_the_summary_and_the_record_name_the_verdict_the_null_and_the_worst_bin(rng):
    model = rng.uniform(1.0, 2.0, size=(3, 40))
    stderr = 0.01 * model
    rendered = model + stderr * rng.standard_normal(model.shape)
    rendered[1, 7] += 10 * stderr[1, 7]
    result = compare_transients(rendered, stderr, model)
    text = result.summary()
    assert text.startswith("DISAGREE") and "(k = 1, bin 7, z = +" in text
    assert "assume independent bins" in text
    record = json.loads(json.dumps(result.as_dict()))
    assert record["agrees"] is False and record["null"] == INDEPENDENT
    assert record["worst"][0][:2] == [1, 7] and record["bins"] == model.size


def test_the_null_note_says_what_the_limits_assume():
    assert "whatever the correlation" in null_note(SIGN_FLIP, 32, 2**14, 1e-3)
    assert "no replicas given" in null_note(INDEPENDENT, None, 0, 1e-3)
    assert "8 replicas are too few" in null_note(INDEPENDENT, 8, 0, 1e-3)
