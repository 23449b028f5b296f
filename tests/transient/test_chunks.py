"""Replica layouts, chunk plans and the accumulator, against direct NumPy statistics."""

from __future__ import annotations

import numpy as np
import pytest

from transient.chunks import DEFAULT_REPLICAS, MAX_SAMPLES, ChunkPlan, ReplicaAccumulator, ReplicaLayout


def test_layout_covers_the_requested_samples_in_equal_replicas():
    layout = ReplicaLayout.for_samples(1000)
    assert layout.replicas == DEFAULT_REPLICAS and layout.samples >= 1000
    assert layout.samples - 1000 < layout.replicas
    assert ReplicaLayout.for_samples(2**20).samples == 2**20
    assert ReplicaLayout.for_samples(5).replicas == 5                   # fewer samples than replicas
    assert ReplicaLayout.for_samples(2**40).size <= 2**32 - 1           # more replicas past 2^32 each
    with pytest.raises(ValueError, match="samples"):
        ReplicaLayout.for_samples(1)
    with pytest.raises(ValueError, match="samples"):
        ReplicaLayout.for_samples(MAX_SAMPLES + 1)
    with pytest.raises(ValueError, match="replicas"):
        ReplicaLayout.for_samples(100, replicas=1)


def test_plan_covers_every_sample_once_without_a_list():
    layout = ReplicaLayout(7, 1001)
    plan = ChunkPlan(layout, 600)
    covered = np.zeros(layout.samples, dtype=int)
    for chunk in plan:
        covered[chunk.first:chunk.first + chunk.count] += 1
        rows = chunk.replicas(layout)
        assert rows.start == chunk.first // 1001 and rows.stop - 1 == (chunk.first + chunk.count - 1) // 1001
    assert np.all(covered == 1) and len(plan) == -(-layout.samples // 600)
    largest = ReplicaLayout.for_samples(MAX_SAMPLES)
    huge = ChunkPlan(largest, 2**22)
    assert len(huge) == -(-largest.samples // 2**22) and huge[len(huge) - 1].first + huge[len(huge) - 1].count \
        == largest.samples
    resumed = ChunkPlan(layout, 600, start=1500)
    assert resumed[0].first == 1500 and sum(c.count for c in resumed) == layout.samples - 1500


def _chunk_sums(values, layout, plan):
    """Per-replica sums of per-sample values (S, K, N) for each chunk, as an integrator returns them."""
    replica = np.arange(layout.samples) // layout.size
    for chunk in plan:
        part = slice(chunk.first, chunk.first + chunk.count)
        rows = chunk.replicas(layout)
        sums = np.stack([values[part][replica[part] == r].sum(axis=0) for r in rows])
        yield chunk, sums


def test_accumulator_gives_the_replicas_mean_and_standard_error(rng):
    layout = ReplicaLayout(9, 777)
    values = rng.exponential(1.0, (layout.samples, 2, 3)) * np.array([1.0, 1e-9, 1e9])
    accumulator = ReplicaAccumulator(layout, (2, 3))
    for chunk, sums in _chunk_sums(values, layout, ChunkPlan(layout, 500)):
        accumulator.add(chunk, sums)
    means = values.reshape(9, 777, 2, 3).mean(axis=1)
    assert accumulator.finished and accumulator.dof == 8 and accumulator.samples == layout.samples
    np.testing.assert_allclose(accumulator.replica_means(), means, rtol=1e-13)
    np.testing.assert_allclose(accumulator.mean(), means.mean(axis=0), rtol=1e-13)
    np.testing.assert_allclose(accumulator.stderr(), means.std(axis=0, ddof=1) / 3, rtol=1e-10)


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_standard_error_neither_underflows_nor_overflows(rng, scale):
    """Replica means of 1e-300 have squared deviations of 1e-606: the error must not flush to zero."""
    layout = ReplicaLayout(8, 50)
    values = rng.exponential(1.0, (layout.samples, 1, 2))
    reference, scaled = ReplicaAccumulator(layout, (1, 2)), ReplicaAccumulator(layout, (1, 2))
    for chunk, sums in _chunk_sums(values, layout, ChunkPlan(layout, 64)):
        reference.add(chunk, sums)
        scaled.add(chunk, sums * scale)
    assert np.all(reference.stderr() > 0)
    np.testing.assert_allclose(scaled.stderr() / scale, reference.stderr(), rtol=1e-13)
    np.testing.assert_allclose(scaled.mean() / scale, reference.mean(), rtol=1e-13)


def test_accumulator_does_not_depend_on_arrival_order(rng):
    layout = ReplicaLayout(4, 1000)
    values = rng.normal(5.0, 1.0, (layout.samples, 1, 2))
    chunks = list(_chunk_sums(values, layout, ChunkPlan(layout, 300)))
    ordered, shuffled = ReplicaAccumulator(layout, (1, 2)), ReplicaAccumulator(layout, (1, 2))
    for chunk, sums in chunks:
        ordered.add(chunk, sums)
    for i in rng.permutation(len(chunks)):
        shuffled.add(*chunks[i])
    np.testing.assert_array_equal(shuffled.mean(), ordered.mean())
    np.testing.assert_array_equal(shuffled.stderr(), ordered.stderr())
    with pytest.raises(ValueError, match="already"):
        shuffled.add(*chunks[0])


def test_state_round_trip_and_refusals(rng):
    layout = ReplicaLayout(4, 100)
    accumulator = ReplicaAccumulator(layout, (2, 2))
    chunks = list(_chunk_sums(rng.random((400, 2, 2)), layout, ChunkPlan(layout, 70)))
    for chunk, sums in chunks[:4]:                 # 280 samples: 2 replicas and part of a third
        accumulator.add(chunk, sums)
    state = accumulator.state()
    assert state["done"] == 280 and state["completed"] == 2
    again = ReplicaAccumulator.from_state(layout, (2, 2), state)
    for chunk, sums in chunks[4:]:
        again.add(chunk, sums)
        accumulator.add(chunk, sums)
    np.testing.assert_array_equal(again.stderr(), accumulator.stderr())
    np.testing.assert_array_equal(again.replica_means(), accumulator.replica_means())
    bad = [dict(state, replica_means=state["replica_means"] + np.inf), dict(state, partial=state["partial"] * np.nan),
           dict(state, completed=3), dict(state, done=10**9), dict(state, replica_means=np.zeros((3, 2, 2))),
           dict(state, done=200, completed=2)]
    for broken in bad:
        with pytest.raises(ValueError):
            ReplicaAccumulator.from_state(layout, (2, 2), broken)
