"""Our relay-wall renderer against the exact third-bounce model (each sample serves every pair)."""

import numpy as np
import pytest
from render_checks import agreement

from analytic.scenes.relay_wall import RelayWallScene, Scan, default_relay_wall_scene
from analytic.scenes.common import Illumination, Sampling
from analytic.operator.system import system_matrix
from analytic.operator.window import pairs_range


def _covering(scene, period=0.02):
    low, high = pairs_range(*scene.geometry())
    return scene.replace(sampling=Sampling(bin_width_opl=period, start_opl=low - period,
                                           count=int((high - low) / period) + 3))


def _loaded(scene, **estimator):
    from transient.backend import select_variant

    select_variant()
    import mitsuba as mi

    from transient.mitsuba_scene import relay_wall_scene_dict

    return mi.load_dict(relay_wall_scene_dict(scene, **estimator))


def _render(scene, spp, seed, **estimator):
    from transient.chunks import ReplicaLayout

    loaded = _loaded(scene, **estimator)
    layout = ReplicaLayout.for_samples(spp)
    sums = loaded.integrator().render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout, first=0,
                                                               count=layout.samples)
    return sums / layout.size * scene.intensity


def _model(scene):
    return (system_matrix(scene) @ scene.reflectance.ravel()).reshape(scene.sensor_count, -1)


def _agrees(replicas, reference):
    return agreement(replicas.mean(axis=0), replicas.std(axis=0, ddof=1) / np.sqrt(len(replicas)), reference,
                     dof=len(replicas) - 1, replicas=replicas)




def _near_wall_single(distance):
    """A 0.6 x 0.5 m rectangle ``distance`` in front of a 1 m wall, lit right below it, read on a 3 x 3 grid;
    the laser and the sensor below the rectangle's plane, so that it blocks neither's line to the wall."""
    below = (-0.5, 0.0, 0.5 * distance)
    return RelayWallScene(pixels=4, reflectance=np.linspace(0.2, 1.0, 16).reshape(4, 4), center=(0.05, 0.0, distance),
                          u=(0.6, 0.0, 0.0), v=(0.0, -0.5, 0.0), wall_size=(1.0, 1.0), laser_position=below,
                          sensor_position=below, scan=Scan(type="single", grid=(3, 3), laser_point=(0.1, 0.05, 0.0)))


# 2 cm from the wall: l's g_l varies 1e3-fold (its solid angle), and a read point's weight would peak 1.3e3 x
# its mean with l's points alone: every read point over 16 gets its own technique (10 in all).
NEAR_WALL_SINGLE = _near_wall_single(0.02)

CASES = {
    "confocal": default_relay_wall_scene(pixels=8, scan=Scan(type="confocal", grid=(3, 3))),
    "single, tilted, Butterworth": RelayWallScene(
        pixels=6, reflectance=np.linspace(0, 1, 36).reshape(6, 6), center=(0.2, 0.1, 1.1),
        u=(0.7, 0.0, 0.3), v=(0.0, -0.8, 0.0), scan=Scan(type="single", grid=(3, 2), laser_point=(0.3, -0.2, 0.0)),
        illumination=Illumination(waveform="butterworth", order=2, cutoff=8.0), intensity=5.0),
    "exhaustive, legs counted, near the wall": RelayWallScene(
        pixels=4, center=(0.1, 0.0, 0.15), u=(0.3, 0.0, 0.0), v=(0.0, -0.3, 0.0),
        scan=Scan(type="exhaustive", grid=(2, 2), laser_grid=(2, 1), account_first_and_last_bounces=True)),
    "single, 15 cm from the wall, l's solid angle": _near_wall_single(0.15),
    "single, 2 cm from the wall, MIS": NEAR_WALL_SINGLE,
}


@pytest.mark.parametrize("name", list(CASES))
def test_render_agrees_with_the_model(name):
    scene = _covering(CASES[name])
    replicas = _render(scene, 2**18, seed=3)
    chi2, max_z, bins, passes = _agrees(replicas, _model(scene))
    assert passes and bins > 50, (chi2, max_z, bins)


def test_a_wrong_model_fails():
    """A model without the wall's cosine at s must be told apart (the check has power)."""
    scene = _covering(CASES["confocal"])
    replicas = _render(scene, 2**18, seed=4)
    rectangle, pairs = scene.geometry()
    from analytic.geometry import PointPairs
    from analytic.operator.system import rectangle_matrix
    from analytic.waveforms import make_waveform

    wrong_pairs = PointPairs(pairs.sources, pairs.sensors, source_normals=pairs.source_normals,
                             scales=pairs.scales)
    wrong = (rectangle_matrix(rectangle, wrong_pairs, scene.sampling, make_waveform(scene.illumination, 0.02))
             @ scene.reflectance.ravel()).reshape(scene.sensor_count, -1)
    *_, passes = _agrees(replicas, wrong)
    assert not passes


def _hidden_frame(scene, points):
    """World points in the hidden rectangle's frame, from the scene's own vectors (not the plugin's)."""
    u, v = np.asarray(scene.u, float), np.asarray(scene.v, float)
    corner = np.asarray(scene.center, float) - 0.5 * u - 0.5 * v
    normal = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
    offset = np.asarray(points, float) - corner
    return np.stack([offset @ (u / np.linalg.norm(u)), offset @ (v / np.linalg.norm(v)), offset @ normal], axis=-1)


def test_mis_plan_of_a_near_wall_single_scan_and_its_balance_weights_sum_to_one():
    """l's solid angle first, peaked read points' own; Σ_t share_t p_t / p = 1 with each p_t in closed form."""
    from transient.plane_sampling import AREA, SOLID_ANGLE, mixture_density

    import mitsuba as mi

    scene = NEAR_WALL_SINGLE
    integrator = _loaded(scene).integrator()
    plan = integrator.plan
    width, height = np.linalg.norm(scene.u), np.linalg.norm(scene.v)
    assert plan[0].kind == SOLID_ANGLE and np.allclose(plan[0].point, _hidden_frame(scene, scene.laser_points[0]))
    reads = _hidden_frame(scene, scene.read_points)
    assert len(plan) == 10 and all(t.kind == SOLID_ANGLE and np.min(np.abs(reads - t.point).sum(axis=1)) < 1e-12
                                 for t in plan[1:])
    assert np.isclose(sum(t.share for t in plan), 1.0)
    rng = np.random.default_rng(5)
    x, y = rng.uniform(0, width, 1000), rng.uniform(0, height, 1000)
    density = np.array(mixture_density(plan, [mi.Float64(t.share) for t in plan], mi.Float64(x), mi.Float64(y),
                                       width, height))
    parts = []
    for t in plan:     # h / (Ω d³), Ω of the rectangle seen from the point by a fine midpoint rule
        if t.kind == AREA:
            parts.append(np.full_like(x, t.share / (width * height)))
            continue
        px, py, h = t.point
        cx, cy = np.meshgrid((np.arange(800) + 0.5) / 800 * width, (np.arange(800) + 0.5) / 800 * height)
        omega = np.sum(h / ((cx - px) ** 2 + (cy - py) ** 2 + h * h) ** 1.5) * width * height / 800**2
        parts.append(t.share * h / (((x - px) ** 2 + (y - py) ** 2 + h * h) ** 1.5 * omega))
    weights = np.array(parts) / density
    assert np.allclose(weights.sum(axis=0), 1.0, rtol=2e-4)


def test_mis_and_area_agree_and_mis_has_the_smaller_error():
    """Both strategies agree with the model on the near-wall single scan; MIS's replicas scatter less."""
    scene = _covering(NEAR_WALL_SINGLE)
    model = _model(scene)
    spread = {}
    for strategy in ("mis", "area"):
        replicas = _render(scene, 2**18, seed=6, strategy=strategy)
        chi2, max_z, bins, passes = _agrees(replicas, model)
        assert passes and bins > 50, (strategy, chi2, max_z, bins)
        spread[strategy] = float(np.sum(replicas.var(axis=0, ddof=1)))
    assert spread["mis"] < 0.5 * spread["area"], spread


def test_mis_without_the_balance_heuristic_fails(monkeypatch):
    """Weighting each point by its own technique's density alone (no balance heuristic) is biased: caught."""
    import transient.nlos as nlos
    from transient.plane_sampling import mixture_density

    def own_density_only(plan, shares, x, y, width, height):
        return mixture_density(plan[:1], [1.0], x, y, width, height)      # l's density for every point

    scene = _covering(NEAR_WALL_SINGLE)
    monkeypatch.setattr(nlos, "mixture_density", own_density_only)
    replicas = _render(scene, 2**18, seed=7)
    *_, passes = _agrees(replicas, _model(scene))
    assert not passes


def test_unknown_strategy_is_refused():
    with pytest.raises(RuntimeError, match="strategy must be one of"):
        _loaded(CASES["confocal"], strategy="solid_angle")


def test_texture_density_follows_the_reflectance_the_plugin_reads():
    """The density of each texel is ρ + 1 % of the mean ρ over their sum, per texel area, with ρ looked up at the
    texel's centre as the kernel looks it up (so the texture's rows are not read upside down)."""
    import mitsuba as mi

    from transient.nlos_sampling import FLOOR

    scene = CASES["confocal"]
    loaded = _loaded(scene)
    integrator = loaded.integrator()
    hidden = integrator._hidden_shape(loaded)
    density = integrator._pixel_density(hidden)
    assert (density.height, density.width) == scene.reflectance.shape
    u, v = np.meshgrid((np.arange(density.width) + 0.5) / density.width,
                       (np.arange(density.height) + 0.5) / density.height)
    reflectance = np.array(integrator._reflectance(hidden, mi.Float64(u.ravel()), mi.Float64(v.ravel())))
    weights = reflectance + FLOOR * reflectance.mean()
    area = np.linalg.norm(scene.u) * np.linalg.norm(scene.v)
    assert np.allclose(np.array(density._density), weights / weights.sum() * weights.size / area, rtol=1e-6)
    assert np.ptp(reflectance) > 0.1                   # a texture with contrast: a flipped lookup would differ


def test_texture_density_with_the_wrong_weights_fails(monkeypatch):
    """Points drawn by the texture but weighted as if uniform (1 / area) are biased: caught."""
    import transient.nlos as nlos

    class Uniform(nlos.PixelDensity):
        def sample(self, u, v):
            u, v, density = super().sample(u, v)
            return u, v, density * 0.0 + float(np.mean(np.array(self._density)))

    scene = _covering(CASES["confocal"])
    monkeypatch.setattr(nlos, "PixelDensity", Uniform)
    replicas = _render(scene, 2**18, seed=8)
    *_, passes = _agrees(replicas, _model(scene))
    assert not passes


@pytest.mark.parametrize("sampler", ["sobol", "stratified"])
@pytest.mark.parametrize("case", ["near the wall (MIS)", "confocal (the texture's density)"])
def test_chunks_add_up_to_the_whole_render_and_share_one_kernel(case, sampler):
    """Sample g's numbers depend on (seed, g) only; seeds, offsets and technique blocks are opaque."""
    import drjit as dr

    from transient.chunks import ReplicaLayout

    scene = NEAR_WALL_SINGLE if case.startswith("near") else CASES["confocal"]
    loaded = _loaded(_covering(scene), sampler=sampler)
    integrator = loaded.integrator()
    layout = ReplicaLayout.for_samples(2**14)                  # 32 replicas of 512 samples

    def chunk(first, count, seed=2):
        return integrator.render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout, first=first, count=count)

    whole = chunk(0, layout.samples)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        head, tail = chunk(0, 1000), chunk(1000, layout.samples - 1000)     # cut inside replica 1
        chunk(700, 3000, seed=9)
        launches = [k for k in dr.kernel_history()
                    if k["type"] == dr.KernelType.JIT and k["size"] in (1000, layout.samples - 1000, 3000)]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    combined = np.zeros_like(whole)
    combined[:2] += head
    combined[1:] += tail
    assert np.allclose(combined, whole, rtol=1e-12, atol=1e-15 * np.abs(whole).max())
    assert len(launches) == 3 and len({k["hash"] for k in launches}) == 1


def test_each_thread_adds_to_its_own_copy_of_the_histogram_and_the_copies_sum_to_the_one_thread_render():
    """Replicas longer than a block get a histogram copy per thread, blocks alternating between them; the copies
    sum to the one-thread render."""
    import drjit as dr
    import mitsuba as mi

    from transient.chunks import ReplicaLayout
    from transient.common import block_copy, thread_copies

    loaded = _loaded(_covering(CASES["confocal"]))          # selects the variant
    threads = dr.thread_count()
    for count in (1000, 2**17):
        # our reading of drjit-core's LLVM launch (LLVMThreadState::launch): about count / threads lanes per
        # block up to 2 x 16384 x threads lanes, 16384 beyond; consecutive blocks must add to different copies
        block = 16384 if count > 2 * 16384 * threads else -(-count // threads)
        lanes = np.arange(count)
        copies = np.array(block_copy(dr.arange(mi.UInt32, count), count, 2))
        assert np.array_equal(copies, (lanes // block) % 2)

    integrator = loaded.integrator()
    layout = ReplicaLayout.for_samples(2**20)                # 32 replicas of 32768: longer than a block
    cells = layout.histogram_rows * integrator.pairs * integrator.bins

    def chunk():
        return integrator.render_chunk_per_unit_intensity(loaded, seed=4, layout=layout, first=0, count=2**17)

    dr.set_thread_count(2)
    try:
        assert thread_copies(cells, layout.size) == 2
        assert thread_copies(cells, ReplicaLayout.for_samples(2**19).size) == 1     # replicas of one block
        two = chunk()
        dr.set_thread_count(1)
        assert thread_copies(cells, layout.size) == 1
        one = chunk()
    finally:
        dr.set_thread_count(threads)
    assert np.abs(one).max() > 0
    assert np.allclose(two, one, rtol=1e-12, atol=1e-15 * np.abs(one).max())


def test_render_loaded_refuses_a_capture_it_cannot_scale():
    """transient_opl_nlos holds no laser intensity: render_loaded names what to call instead."""
    from transient.render import render_loaded

    with pytest.raises(ValueError, match="per unit laser intensity"):
        render_loaded(_loaded(CASES["confocal"]), spp=64)


def test_default_chunks_shrink_with_the_pairs_so_that_checkpoints_stay_frequent():
    """Every sample serves every pair: a chunk is sized in (sample, pair) evaluations, 2^26 on a CPU."""
    from transient.render import DEFAULT_CHUNK, DEFAULT_CHUNK_GPU, default_chunk

    assert default_chunk(1, False) == default_chunk(16, False) == DEFAULT_CHUNK
    assert default_chunk(64, False) == DEFAULT_CHUNK // 4 and default_chunk(1024, False) == 2**16
    assert default_chunk(100, False) == 2**19          # a power of two at or below 2^26 / 100
    assert default_chunk(2**20, False) == 64 and default_chunk(2**40, False) == 1
    assert default_chunk(1024, True) == DEFAULT_CHUNK_GPU // 64


def test_a_pulse_in_a_one_bin_window_is_integrated_as_the_pulse():
    """One bin caps every pulse at one tap; the deposit must still weigh each path by ∫_bin s, not by 1."""
    scene = _covering(CASES["confocal"]).replace(illumination=Illumination(waveform="gaussian", fwhm=0.05))
    low, _ = pairs_range(*scene.geometry())
    scene = scene.replace(sampling=Sampling(bin_width_opl=0.01, start_opl=low + 0.2, count=1))
    replicas = _render(scene, 2**18, seed=8)
    chi2, max_z, bins, passes = _agrees(replicas, _model(scene))
    assert passes and bins == scene.sensor_count, (chi2, max_z, bins)


def test_a_pairs_weight_is_the_models_attenuation_formula(monkeypatch):
    """One definition of a_k: the relay-wall renderer weighs each pair with attenuation_formula (in Dr.Jit), not
    a re-derivation of it; doubling the formula there doubles every scan's render, sample for sample."""
    for name in ("confocal", "single, tilted, Butterworth", "exhaustive, legs counted, near the wall"):
        scene = _covering(CASES[name])
        before = _render(scene, 2**10, seed=5)
        import transient.nlos as nlos            # after a render: the plugins load once a variant is set

        formula = nlos.attenuation_of_distances
        monkeypatch.setattr(nlos, "attenuation_of_distances", lambda *values: 2.0 * formula(*values))
        doubled = _render(scene, 2**10, seed=5)
        monkeypatch.undo()
        assert before.max() > 0 and np.allclose(doubled, 2.0 * before, rtol=1e-12, atol=0.0), name
