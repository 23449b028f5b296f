"""Reconstruction: the Laplacian, the two solvers, the λ rules, metrics and the CLI.

Every accuracy claim is checked against an independent computation: the
stencil written out pixel by pixel, numpy.linalg.lstsq on the stacked
system [A; √λ D] (no DCT, no SVD of ours), brute-force searches over λ with
that dense solver, and SSIM window by window with numpy.cov.
"""

import argparse
import json

import numpy as np
import pytest

from analytic.laplacian import dct2, idct2, laplacian_eigenvalues, neumann_laplacian
from analytic.reconstruct import (
    RankDeficiencyWarning,
    image_metrics,
    reconstruct,
    reconstruct_rules,
)
from analytic.scene import Illumination, Sampling, Scene, SceneError, sensor_grid
from analytic.system import system_matrix


def _stencil_laplacian(pixels):
    """D written out pixel by pixel: reflecting ghost pixels equal their mirror."""
    size = pixels * pixels
    matrix = np.zeros((size, size))
    for r in range(pixels):
        for c in range(pixels):
            p = r * pixels + c
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                rr, cc = r + dr, c + dc
                if 0 <= rr < pixels and 0 <= cc < pixels:
                    matrix[p, rr * pixels + cc] += 1.0
                else:
                    matrix[p, p] += 1.0  # ghost pixel = the pixel itself
                matrix[p, p] -= 1.0
    return matrix


def _dense_solution(matrix, y, pixels, lam):
    """Independent reference: lstsq on the stacked [A; √λ D] in pixel variables."""
    stacked = np.vstack([matrix, np.sqrt(lam) * _stencil_laplacian(pixels)])
    rhs = np.concatenate([y, np.zeros(pixels * pixels)])
    return np.linalg.lstsq(stacked, rhs, rcond=None)[0]


def _synthetic_problem(rng, *, pixels=6, rows=60, decay=1e-3, noise=0.02):
    """A dense A with known singular values (geometric from 1 to ``decay``) and noisy data."""
    n = pixels * pixels
    k = min(rows, n)
    u, _ = np.linalg.qr(rng.standard_normal((rows, k)))
    v, _ = np.linalg.qr(rng.standard_normal((n, k)))
    matrix = u @ np.diag(np.geomspace(1.0, decay, k)) @ v.T
    x, yy = np.meshgrid(np.linspace(0, 1, pixels), np.linspace(0, 1, pixels))
    truth = 0.5 + 0.3 * np.sin(2 * x) * np.cos(3 * yy)
    y = matrix @ truth.ravel() + noise * rng.standard_normal(rows)
    return matrix, y, truth


@pytest.fixture(scope="module")
def small_scene():
    """A well-posed scene: M = 8, a 6 x 6 array of extent 2 m, 2 cm bins."""
    pixels = 8
    x, y = np.meshgrid((np.arange(pixels) + 0.5) / pixels, (np.arange(pixels) + 0.5) / pixels)
    image = 0.4 + 0.2 * np.cos(np.pi * x) * np.sin(np.pi * y) + 0.1 * x
    scene = Scene(pixels=pixels, reflectance=image, source=(0.5, 0.5, 1.0),
                  sensors=sensor_grid((6, 6), 2.0, (0.5, 0.5, 1.0)),
                  sampling=Sampling(bin_width_opl=0.02, start_opl=1.9, count=100), name="small")
    return scene, system_matrix(scene)


# --------------------------------------------------------------------- the Laplacian

def test_neumann_laplacian_is_the_reflecting_stencil_and_the_dct_diagonalises_it(rng):
    pixels = 7
    stencil = _stencil_laplacian(pixels)
    assert np.array_equal(neumann_laplacian(pixels).toarray(), stencil)
    assert np.allclose(stencil @ np.ones(pixels**2), 0.0)  # constants are its null space
    assert np.linalg.matrix_rank(stencil) == pixels**2 - 1
    image = rng.random((pixels, pixels))
    spectral = idct2(-laplacian_eigenvalues(pixels) * dct2(image))
    assert np.allclose(spectral.ravel(), stencil @ image.ravel(), atol=1e-13)
    assert np.allclose(np.sort(laplacian_eigenvalues(pixels).ravel()),
                       np.sort(-np.linalg.eigvalsh(stencil)), atol=1e-12)


# --------------------------------------------------------------------- the solvers

@pytest.mark.parametrize("lam", [1e-8, 1e-3, 1.0, 1e3])
def test_svd_solver_equals_dense_stacked_least_squares(rng, lam):
    matrix, y, _ = _synthetic_problem(rng, rows=30)  # 30 rows for 36 unknowns: rank-deficient
    with pytest.warns(RankDeficiencyWarning):
        result = reconstruct(matrix, y, 6, rule=lam, method="svd")
    reference = _dense_solution(matrix, y, 6, lam)
    assert np.max(np.abs(result.image.ravel() - reference)) <= 1e-8 * np.max(np.abs(reference))
    assert result.residual_norm == pytest.approx(np.linalg.norm(matrix @ reference - y), rel=1e-8)


def test_both_solvers_agree_on_a_scene_matrix(small_scene, rng):
    scene, matrix = small_scene
    y = matrix @ scene.reflectance.ravel() + 1e-4 * rng.standard_normal(matrix.shape[0])
    lam = 1e-9
    svd = reconstruct(matrix, y, scene.pixels, rule=lam, method="svd")
    lsqr = reconstruct(matrix, y, scene.pixels, rule=lam, method="lsqr")
    reference = _dense_solution(matrix.toarray(), y, scene.pixels, lam)
    assert np.max(np.abs(svd.image.ravel() - reference)) < 1e-8 * np.max(np.abs(reference))
    assert np.max(np.abs(lsqr.image.ravel() - reference)) < 1e-6 * np.max(np.abs(reference))


def test_smooth_image_is_recovered_exactly_from_noiseless_well_posed_data(small_scene):
    scene, matrix = small_scene
    y = matrix @ scene.reflectance.ravel()
    result = reconstruct(matrix, y, scene.pixels, rule=1e-16)
    assert result.rank == scene.pixels**2  # 3600 rows, full column rank: no warning
    assert np.max(np.abs(result.image - scene.reflectance)) < 1e-6


# --------------------------------------------------------------------- the λ rules

def _brute_force(matrix, y, pixels, grid):
    solutions = np.array([_dense_solution(matrix, y, pixels, lam) for lam in grid])
    residuals = np.sum((solutions @ matrix.T - y) ** 2, axis=1)
    stencil = _stencil_laplacian(pixels)
    seminorms = np.sum((solutions @ stencil.T) ** 2, axis=1)
    return solutions, residuals, seminorms


def test_oracle_gcv_and_discrepancy_match_brute_force_searches(rng):
    matrix, y, truth = _synthetic_problem(rng)
    m, sigma = len(y), 0.02
    grid = np.geomspace(1e-8, 1e1, 91)
    solutions, residuals, _ = _brute_force(matrix, y, 6, grid)
    stacked = [np.vstack([matrix, np.sqrt(lam) * _stencil_laplacian(6)]) for lam in grid]
    # H = A (stacked⁺)[:, :m], from lstsq on identity right-hand sides
    traces = np.array([np.trace(matrix @ np.linalg.lstsq(s, np.eye(m + 36)[:, :m], rcond=None)[0])
                       for s in stacked])
    gcv = residuals / (m - traces) ** 2
    errors = np.sum((solutions - truth.ravel()) ** 2, axis=1)
    oracle, gcv_result, discrepancy = reconstruct_rules(
        matrix, y, 6, rules=("oracle", "gcv", "discrepancy"), truth=truth, sigma=sigma,
        lambdas=grid)
    for result, values in ((oracle, errors), (gcv_result, gcv)):
        best = int(np.argmin(values))
        assert 0 < best < len(grid) - 1  # an interior optimum, so the test means something
        assert grid[best - 1] <= result.lam <= grid[best + 1]
        assert np.allclose(result.criterion, values, rtol=1e-7)
    refined = _dense_solution(matrix, y, 6, oracle.lam)
    assert np.sum((refined - truth.ravel()) ** 2) <= errors.min() * (1 + 1e-9)
    # discrepancy: bisection in log λ with the dense solver
    low, high = np.log(grid[0]), np.log(grid[-1])
    for _ in range(60):
        middle = 0.5 * (low + high)
        f = _dense_solution(matrix, y, 6, np.exp(middle))
        low, high = (middle, high) if np.sum((matrix @ f - y) ** 2) < m * sigma**2 else (low, middle)
    assert discrepancy.lam == pytest.approx(np.exp(low), rel=1e-6)
    assert discrepancy.residual_norm**2 == pytest.approx(m * sigma**2, rel=1e-8)


def test_lcurve_corner_matches_finite_differences_of_brute_force_curve(rng):
    matrix, y, _ = _synthetic_problem(rng, noise=0.05)
    grid = np.geomspace(1e-7, 1e2, 181)
    _, residuals, seminorms = _brute_force(matrix, y, 6, grid)
    t, x, z = np.log(grid), np.log(residuals), np.log(seminorms)
    xt, zt = np.gradient(x, t), np.gradient(z, t)
    curvature = (xt * np.gradient(zt, t) - np.gradient(xt, t) * zt) / (xt**2 + zt**2) ** 1.5
    interior = [i for i in range(2, len(grid) - 2)
                if curvature[i] > curvature[i - 1] and curvature[i] >= curvature[i + 1]]
    corner = grid[max(interior, key=lambda i: curvature[i])]
    result = reconstruct(matrix, y, 6, rule="lcurve", lambdas=grid)
    assert np.allclose(result.criterion[5:-5], curvature[5:-5], rtol=2e-2, atol=1e-3)
    assert abs(np.log(result.lam / corner)) < 2 * (t[1] - t[0])


def test_lsqr_sweep_chooses_the_same_lambdas_as_the_closed_forms(rng):
    # lsqr picks on the grid (GCV's trace by a 4-probe Hutchinson estimate), the
    # svd route refines between grid points: they must agree to about a grid step.
    matrix, y, truth = _synthetic_problem(rng, rows=200)
    grid = np.geomspace(1e-8, 1e1, 40)
    step = np.log(grid[1] / grid[0])
    kwargs = dict(truth=truth, sigma=0.02, lambdas=grid)
    svd = reconstruct_rules(matrix, y, 6, method="svd", **kwargs)
    lsqr = reconstruct_rules(matrix, y, 6, method="lsqr", **kwargs)
    for exact, iterative in zip(svd, lsqr):
        allowed = 3 * step if exact.rule == "gcv" else 1.01 * step
        assert abs(np.log(iterative.lam / exact.lam)) <= allowed, exact.rule
        assert iterative.method == "lsqr" and np.all(np.isfinite(iterative.image))


def test_rule_arguments_are_validated(rng):
    matrix, y, _ = _synthetic_problem(rng)
    with pytest.raises(ValueError, match="truth"):
        reconstruct(matrix, y, 6, rule="oracle")
    with pytest.raises(ValueError, match="sigma"):
        reconstruct(matrix, y, 6, rule="discrepancy")
    with pytest.raises(ValueError, match="rule"):
        reconstruct(matrix, y, 6, rule="best")
    with pytest.raises(ValueError, match="rule"):
        reconstruct(matrix, y, 6, rule=-1.0)
    with pytest.raises(ValueError, match="method"):
        reconstruct(matrix, y, 6, method="cholesky")
    with pytest.raises(ValueError, match="data"):
        reconstruct(matrix, y[:-1], 6)


# --------------------------------------------------------------------- rank deficiency

def test_collinear_sensors_warn_and_give_the_mirror_symmetric_answer(rng):
    # Source and sensors on the line y = 0.5: an image and its mirror across
    # that line give the same data, so A is rank-deficient, and the unique
    # regularised answer (the Laplacian is mirror-invariant) is mirror-symmetric.
    pixels = 10
    sensors = [(x, 0.5, 1.0) for x in (0.1, 0.3, 0.7, 0.9)]
    scene = Scene(pixels=pixels, reflectance=rng.random((pixels, pixels)), source=(0.5, 0.5, 1.0),
                  sensors=sensors, sampling=Sampling(bin_width_opl=0.02, start_opl=1.9, count=80))
    matrix = system_matrix(scene)
    # A's entries are accurate to its tolerance, so mirror columns agree only to
    # ~1e-7; average them to give the exact symmetry this test is about
    mirror = np.arange(pixels * pixels).reshape(pixels, pixels)[::-1].ravel()
    matrix = 0.5 * (matrix + matrix[:, mirror])
    y = matrix @ scene.reflectance.ravel() + 1e-3 * rng.standard_normal(matrix.shape[0])
    with pytest.warns(RankDeficiencyWarning):
        svd = reconstruct(matrix, y, pixels, rule="gcv", method="svd")
    assert any("unknowns" in w for w in svd.warnings)
    assert svd.rank <= pixels * (pixels // 2)  # at most the mirror-symmetric images
    # lsqr cannot see a numerical rank deficiency (it has more non-zero rows than
    # unknowns here, so it does not warn) but it still returns the same answer
    lsqr = reconstruct(matrix, y, pixels, rule=svd.lam, method="lsqr")
    for result in (svd, lsqr):
        assert np.all(np.isfinite(result.image))
        assert np.allclose(result.image, np.flipud(result.image),
                           atol=1e-6 * np.abs(result.image).max())
    assert np.allclose(lsqr.image, svd.image, atol=1e-5 * np.abs(svd.image).max())
    # fewer measurements than unknowns: lsqr warns too
    with pytest.warns(RankDeficiencyWarning):
        few = reconstruct(matrix[:60], y[:60], pixels, rule=1e-6, method="lsqr")
    assert np.all(np.isfinite(few.image))


# --------------------------------------------------------------------- metrics

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


# --------------------------------------------------------------------- the command

SCENE = """
[plane]
pixels = 8
[source]
position = [0.5, 0.5, 1.0]
[sensors]
grid = [4, 4]
extent = 2.0
center = [0.5, 0.5, 1.0]
[sampling]
period = 0.05
start = 1.9
count = 40
[noise]
sigma = 0.001
seed = 3
"""


def _run(argv):
    from validation.cli_reconstruct import add_commands

    parser = argparse.ArgumentParser(prog="diffuse-imaging")
    add_commands(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.run(args)


def test_reconstruct_command_writes_its_files(tmp_path):
    from analytic.io import read_transient, save_npy
    from analytic.noise import add_noise
    from analytic.scene import load_scene
    from analytic.system import forward

    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)
    scene = load_scene(scene_path)
    save_npy(tmp_path / "y.npy", add_noise(forward(scene), scene.noise))
    status = _run(["reconstruct", str(scene_path), "--data", str(tmp_path / "y.npy"),
                   "--out", str(tmp_path / "r"), "--lambda", "discrepancy", "--quiet"])
    assert status == 0
    names = {p.name for p in (tmp_path / "r").iterdir()}
    assert {"reconstruction.png", "reconstruction.exr", "metrics.json", "criterion.png"} <= names
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["rule"] == "discrepancy" and metrics["data_range"] == 1.0
    assert metrics["psnr_db"] > 20  # a uniform 0.5 plane at σ = 1e-3
    image = read_transient(tmp_path / "r" / "reconstruction.exr")
    assert np.allclose(image, np.load(tmp_path / "r" / "reconstruction.npy"), atol=1e-6)
    assert _run(["reconstruct", str(scene_path), "--data", str(tmp_path / "y.npy"), "--out",
                 str(tmp_path / "tv"), "--lambda", "oracle", "--regularizer", "tv", "--quiet"]) == 0
    tv = json.loads((tmp_path / "tv" / "metrics.json").read_text())
    assert tv["method"] == "pdhg" and tv["psnr_db"] > 20
    with pytest.raises(SceneError, match="--lambda"):
        _run(["reconstruct", str(scene_path), "--data", str(tmp_path / "y.npy"),
              "--out", str(tmp_path / "s"), "--lambda", "best"])
    with pytest.raises(SceneError, match="--lambda"):
        _run(["reconstruct", str(scene_path), "--data", str(tmp_path / "y.npy"),
              "--out", str(tmp_path / "s"), "--lambda", "gcv", "--regularizer", "tv"])
    with pytest.raises(FileNotFoundError):
        _run(["reconstruct", str(scene_path), "--data", str(tmp_path / "missing.npy"),
              "--out", str(tmp_path / "s")])
    scene_path.write_text(SCENE.split("[noise]")[0])
    with pytest.raises(SceneError, match="noise.sigma"):
        _run(["reconstruct", str(scene_path), "--data", str(tmp_path / "y.npy"),
              "--out", str(tmp_path / "s"), "--lambda", "discrepancy"])
    assert not (tmp_path / "s").exists()


# --------------------------------------------------------------------- conditioning

def test_conditioning_summary_on_known_singular_values():
    from analytic.conditioning import conditioning_summary, singular_values

    values = np.array([5.0, 1.0, 0.2, 0.05])
    matrix = np.vstack([np.diag(values), np.zeros((3, 4))])  # zero rows add nothing
    assert np.allclose(singular_values(matrix), values)
    summary = conditioning_summary(singular_values(matrix), 4, 7, sigma=0.1)
    assert summary["condition"] == pytest.approx(100.0)
    assert summary["effective_rank"] == 3 and summary["numerical_rank"] == 4
    deficient = conditioning_summary(np.array([2.0, 1e-20]), 2, 2, sigma=0.1)
    assert deficient["condition"] == np.inf and deficient["numerical_rank"] == 1


def test_covering_sampling_keeps_every_path():
    # With an impulse each pixel's row sum over all bins is ∫ a_k over the pixel,
    # whatever the bins; the covering bins must lose none of it.
    from analytic.conditioning import scene_for

    base = Scene(pixels=6, reflectance=0.5, source=(0.5, 0.5, 1.0), sensors=((0.2, 0.3, 1.0),))
    narrow = scene_for(base, extent=3.0, period=0.1, grid=(2, 2))
    wide = narrow.replace(sampling=Sampling(bin_width_opl=0.1, start_opl=0.0, count=120))
    k, n = narrow.sensor_count, narrow.sampling.count
    covered = system_matrix(narrow).toarray().reshape(k, n, -1).sum(axis=1)
    everything = system_matrix(wide).toarray().reshape(k, 120, -1).sum(axis=1)
    assert np.allclose(covered, everything, rtol=1e-9)


# --------------------------------------------------------------------- experiments

def test_device_figures_follow_the_stated_mapping():
    from scipy.integrate import quad

    from analytic.experiments import SPEED_OF_LIGHT, device_figures
    from analytic.waveforms import make_waveform

    unit = SPEED_OF_LIGHT / (750e6 * 0.1)
    figures = device_figures(period=0.1, unit_m=unit)
    assert figures["sampling_hz"] == pytest.approx(750e6)
    assert figures["bandwidth_hz"] == pytest.approx(375e6)
    waveform = make_waveform(Illumination(waveform="butterworth"), 0.1)
    area = quad(lambda t: float(waveform.intensity(np.array([t]))[0]), 0, waveform.duration,
                limit=200)[0]
    assert figures["pulse_energy_per_w_sr"] == pytest.approx(4 * np.pi * area * unit / SPEED_OF_LIGHT,
                                                             rel=1e-6)


def test_reproduce_quick_writes_report_with_every_claim(tmp_path):
    status = _run(["reproduce", "--out", str(tmp_path / "q"), "--quick", "--quiet"])
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


# --------------------------------------------------------------------- total variation

def test_tv_solver_reaches_the_optimum_of_an_independent_conic_solve(rng):
    # Reference: the same convex problem in epigraph form, ½||A f - y||² + λ Σ t
    # with t ≥ |∇f| per pixel, solved by SciPy's SLSQP (no code shared); SLSQP
    # stalls slightly above the optimum on the cone's kink, so PDHG must be at
    # least as low, and its optimality is then proved by a dual certificate.
    from scipy.optimize import minimize

    from analytic.reconstruct import (
        _divergence,
        _gradient,
        _tv_solve,
        _tv_steps,
        reconstruct_tv,
        total_variation,
    )

    pixels, lam = 4, 0.05
    n = pixels * pixels
    matrix = rng.random((24, n))
    truth = np.zeros((pixels, pixels))
    truth[:, 2:] = 1.0
    y = matrix @ truth.ravel() + 0.05 * rng.standard_normal(24)
    # forward differences written out: rows then columns, zero across the far edges
    down, right = np.zeros((n, n)), np.zeros((n, n))
    for r in range(pixels):
        for c in range(pixels):
            p = r * pixels + c
            if r + 1 < pixels:
                down[p, p], down[p, p + pixels] = -1.0, 1.0
            if c + 1 < pixels:
                right[p, p], right[p, p + 1] = -1.0, 1.0

    def objective(v):
        return 0.5 * np.sum((matrix @ v[:n] - y) ** 2) + lam * np.sum(v[n:])

    def objective_gradient(v):
        return np.concatenate([matrix.T @ (matrix @ v[:n] - y), np.full(n, lam)])

    def cone(v):  # t² - |∇f|² ≥ 0 with t ≥ 0 is the second-order cone
        return v[n:] ** 2 - (down @ v[:n]) ** 2 - (right @ v[:n]) ** 2

    def cone_jacobian(v):
        gx, gy = down @ v[:n], right @ v[:n]
        return np.hstack([-2 * gx[:, None] * down - 2 * gy[:, None] * right, np.diag(2 * v[n:])])

    start = np.concatenate([np.full(n, 0.5), np.ones(n)])
    reference = minimize(objective, start, jac=objective_gradient, method="SLSQP",
                         constraints=[{"type": "ineq", "fun": cone, "jac": cone_jacobian},
                                      {"type": "ineq", "fun": lambda v: v[n:],
                                       "jac": lambda v: np.hstack([np.zeros((n, n)), np.eye(n)])}],
                         options={"ftol": 1e-14, "maxiter": 1000})
    result = reconstruct_tv(matrix, y, pixels, rule=lam, iterations=50000, tolerance=1e-12)

    def primal(image):
        return 0.5 * np.sum((matrix @ image.ravel() - y) ** 2) + lam * total_variation(image)
    assert primal(result.image) <= reference.fun + 1e-9
    # and it is optimal: a dual certificate q with |q| ≤ λ, Aᵀ(A f - y) = div q and
    # ⟨q, ∇f⟩ = λ TV(f) proves it for this convex problem, whoever computed q
    f, _, q, _ = _tv_solve(matrix, y, pixels, lam, _tv_steps(matrix, pixels), iterations=50000,
                           tolerance=1e-13)
    assert np.max(np.hypot(q[0], q[1])) <= lam * (1 + 1e-12)
    assert np.allclose(matrix.T @ (matrix @ f - y), _divergence(q).ravel(), atol=1e-8)
    assert np.sum(q * _gradient(f.reshape(pixels, pixels))) == pytest.approx(
        lam * total_variation(f.reshape(pixels, pixels)), rel=1e-8)
    assert np.allclose(f, result.image.ravel(), atol=1e-6)
    image, field = rng.random((pixels, pixels)), rng.random((2, pixels, pixels))
    assert np.sum(_gradient(image) * field) == pytest.approx(-np.sum(image * _divergence(field)))


def test_tv_keeps_edges_that_the_laplacian_blurs(rng):
    # Piecewise-constant image, underdetermined noisy data: TV's oracle error is
    # below the Laplacian's (its prior matches the image).
    pixels = 12
    truth = np.zeros((pixels, pixels))
    truth[3:9, 4:10] = 1.0
    matrix = rng.standard_normal((100, pixels * pixels)) / 10
    y = matrix @ truth.ravel() + 0.02 * rng.standard_normal(100)
    with pytest.warns(RankDeficiencyWarning):
        smooth = reconstruct(matrix, y, pixels, rule="oracle", truth=truth)
    edges = reconstruct(matrix, y, pixels, rule="oracle", truth=truth, regularizer="tv")
    assert edges.method == "pdhg"
    assert np.sum((edges.image - truth) ** 2) < 0.5 * np.sum((smooth.image - truth) ** 2)
    with pytest.raises(ValueError, match="rule"):
        reconstruct(matrix, y, pixels, rule="gcv", regularizer="tv")


def test_photon_counting_comparison_counts_whole_photons_with_one_detector():
    from analytic.experiments import poisson_cases

    rows = poisson_cases(pixels=8, periods=(0.1,), extents=(1.0,), progress=False)
    assert {r["illumination"] for r in rows} == {"impulsive", "low-pass"}
    impulsive, low_pass = sorted(rows, key=lambda r: r["illumination"] != "impulsive")
    # One detector: the photon ratio is the ratio of the pulses' energies (Σ_n κ_n = ∫ s when the
    # bins cover the response), up to the clipped Butterworth undershoot.
    from analytic.scene import Illumination
    from analytic.waveforms import make_waveform
    energy = {name: make_waveform(Illumination(waveform=name), 0.1).energy for name in ("square", "butterworth")}
    ratio = low_pass["expected_photons"] / impulsive["expected_photons"]
    assert ratio == pytest.approx(energy["butterworth"] / energy["square"], rel=1e-2)
    assert all(np.isfinite(r["psnr"]) for r in rows)
