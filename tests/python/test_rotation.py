"""Rotation estimation from Python: harmonics, Wigner matrices, EGI correlation, search.

Every check compares with an independent answer (closed forms, polynomials rotated
point by point, finite differences, brute force), never with the code's own output.
"""

from __future__ import annotations

import numpy as np
import pytest

import spectral_vs as svs


def hat(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def axis_angle(axis, degrees: float) -> np.ndarray:
    """Rodrigues' formula."""
    axis = np.asarray(axis, dtype=float)
    k = hat(axis / np.linalg.norm(axis))
    t = np.radians(degrees)
    return np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * (k @ k)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = (np.trace(a.T @ b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def euler_zyz(alpha, beta, gamma):
    return (
        axis_angle((0, 0, 1), np.degrees(alpha))
        @ axis_angle((0, 1, 0), np.degrees(beta))
        @ axis_angle((0, 0, 1), np.degrees(gamma))
    )


def random_axis(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def grid_directions(bandwidth: int) -> np.ndarray:
    theta, phi = svs.sphere_grid(bandwidth)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def polynomial(axes: np.ndarray, weights: np.ndarray, degrees, x: np.ndarray) -> np.ndarray:
    """sum_i w_i (a_i . x)^d_i: band-limited to l <= max(d_i), evaluated anywhere."""
    return sum(w * (x @ a) ** d for a, w, d in zip(axes, weights, degrees, strict=True))


def clustered_normals(rng: np.random.Generator, count: int = 3000) -> np.ndarray:
    """Normals of a generic asymmetric shape: clusters of different spread and weight."""
    centres = np.array([random_axis(rng) for _ in range(6)])
    spread = np.array([0.05, 0.1, 0.2, 0.08, 0.3, 0.15])
    which = rng.integers(0, 7, count)
    n = rng.normal(size=(count, 3))
    clustered = which < 6
    n[clustered] = centres[which[clustered]] + spread[which[clustered], None] * n[clustered]
    return n / np.linalg.norm(n, axis=1, keepdims=True)


SPECIAL_ROTATIONS = [
    ((1, 0, 0), 90.0),
    ((0, 1, 0), 90.0),
    ((0, 1, 0), -90.0),
    ((0, 0, 1), -45.0),
    ((0, 0, 1), -179.9),
    ((1, 1, 1), 179.9),
    ((1, 0, 0), 180.0),
    ((0, 1, 0), 180.0),
    ((0, 0, 1), 180.0),
    ((1, -2, 3), 180.0),
    ((0.3, 0.5, -0.8), 37.0),
]


# --- Spherical harmonics and the transform -------------------------------------------


def test_real_harmonics_match_closed_forms(rng):
    for _ in range(10):
        x, y, z = n = random_axis(rng)
        s = svs.real_spherical_harmonics(2.5 * n, 2)
        c1, c2 = np.sqrt(3 / (4 * np.pi)), 0.5 * np.sqrt(15 / np.pi)
        expected = [
            0.5 / np.sqrt(np.pi),
            c1 * y,
            c1 * z,
            c1 * x,
            c2 * x * y,
            c2 * y * z,
            0.25 * np.sqrt(5 / np.pi) * (3 * z * z - 1),
            c2 * x * z,
            0.5 * c2 * (x * x - y * y),
        ]
        np.testing.assert_allclose(s, expected, atol=1e-14)
    assert svs.sh_index(2, -2) == 4


@pytest.mark.parametrize("bandwidth", [1, 4, 16, 33])
def test_round_trip_of_band_limited_function(rng, bandwidth):
    axes = np.array([random_axis(rng) for _ in range(4)])
    degrees = [bandwidth - 1, max(bandwidth - 2, 0), bandwidth - 1, 1 if bandwidth > 1 else 0]
    f = polynomial(axes, rng.normal(size=4), degrees, grid_directions(bandwidth))
    coefficients = svs.sh_coefficients(f, bandwidth)
    assert coefficients.shape == (bandwidth**2,)
    np.testing.assert_allclose(svs.sh_synthesis(coefficients, bandwidth), f, atol=1e-10)


def test_single_harmonic_has_unit_coefficients():
    x = grid_directions(8)
    f = 0.25 * np.sqrt(15 / np.pi) * (x[..., 0] ** 2 - x[..., 1] ** 2)  # S^2_2
    expected = np.zeros(64)
    expected[svs.sh_index(2, 2)] = 1.0
    np.testing.assert_allclose(svs.sh_coefficients(f, 8), expected, atol=1e-13)
    np.testing.assert_allclose(svs.sh_coefficients(np.ones((16, 16)), 8)[0], np.sqrt(4 * np.pi))


# --- Real Wigner matrices -------------------------------------------------------------


def rotations_under_test(rng):
    yield from (axis_angle(a, d) for a, d in SPECIAL_ROTATIONS)
    for _ in range(4):
        yield axis_angle(random_axis(rng), rng.uniform(-180, 180))


def test_wigner_is_an_orthogonal_representation_with_the_so3_character(rng):
    lmax = 32
    rotations = list(rotations_under_test(rng))
    for i, R in enumerate(rotations):
        U = svs.wigner_real(R, lmax)
        R2 = rotations[(3 * i + 1) % len(rotations)]
        U2, U12 = svs.wigner_real(R2, lmax), svs.wigner_real(R @ R2, lmax)
        theta = np.radians(angle_deg(np.eye(3), R))
        for ell in range(lmax + 1):
            assert U[ell].shape == (2 * ell + 1, 2 * ell + 1)
            np.testing.assert_allclose(U[ell].T @ U[ell], np.eye(2 * ell + 1), atol=1e-12)
            np.testing.assert_allclose(U12[ell], U[ell] @ U2[ell], atol=1e-12)
            character = np.sin((2 * ell + 1) * theta / 2) / np.sin(theta / 2)
            assert U[ell].trace() == pytest.approx(character, abs=1e-9)


def test_wigner_rotates_coefficients_of_rotated_polynomials(rng):
    # g(x) = f(R^T x) for f = sum w (a . x)^d is sum w ((R a) . x)^d: rotated exactly,
    # point by point, with no harmonics involved. Degrees 32 and 31 give every l <= 32.
    bandwidth, lmax = 33, 32
    axes = np.array([random_axis(rng) for _ in range(6)])
    weights, degrees = rng.normal(size=6), [32, 31, 32, 31, 20, 7]
    x = grid_directions(bandwidth)
    F = svs.sh_coefficients(polynomial(axes, weights, degrees, x), bandwidth)
    for R in rotations_under_test(rng):
        G = svs.sh_coefficients(polynomial(axes @ R.T, weights, degrees, x), bandwidth)
        U = svs.wigner_real(R, lmax)
        for ell in range(lmax + 1):
            block = slice(ell * ell, (ell + 1) ** 2)
            np.testing.assert_allclose(G[block], U[ell] @ F[block], atol=1e-10 * np.abs(F).max())


def test_generators_agree_with_central_differences():
    lmax, h = 20, 1e-5
    u = svs.wigner_generators(lmax)
    for k, e in enumerate(np.eye(3)):
        plus, minus = (
            svs.wigner_real(axis_angle(e, np.degrees(h)), lmax),
            svs.wigner_real(axis_angle(e, -np.degrees(h)), lmax),
        )
        for ell in range(1, lmax + 1):
            difference = (plus[ell] - minus[ell]) / (2 * h)
            assert np.linalg.norm(difference - u[k][ell]) <= 1e-6 * np.linalg.norm(u[k][ell])
            np.testing.assert_array_equal(u[k][ell], -u[k][ell].T)


# --- Correlation ---------------------------------------------------------------------


def test_gradient_and_hessian_agree_with_finite_differences(rng):
    bandwidth = 12
    target, model = rng.normal(size=bandwidth**2), rng.normal(size=bandwidth**2)
    R = axis_angle(random_axis(rng), 64.0)
    value, gradient, hessian = svs.so3_correlation(target, model, R, hessian=True)

    def C(e):
        angle = np.linalg.norm(e)
        step = np.eye(3) if angle == 0 else axis_angle(e, np.degrees(angle))
        return svs.so3_correlation(target, model, R @ step)[0]

    assert C(np.zeros(3)) == pytest.approx(value, abs=1e-15)
    h = 1e-5
    numeric = np.array([(C(h * e) - C(-h * e)) / (2 * h) for e in np.eye(3)])
    assert np.linalg.norm(numeric - gradient) <= 1e-6 * np.linalg.norm(gradient)

    def second(h):
        E = h * np.eye(3)
        return np.array(
            [[(C(a + b) - C(a - b) - C(b - a) + C(-a - b)) / (4 * h * h) for b in E] for a in E]
        )

    numeric_hessian = (4 * second(5e-4) - second(1e-3)) / 3  # Richardson
    assert np.linalg.norm(numeric_hessian - hessian) <= 1e-6 * np.linalg.norm(hessian)


def test_normalised_correlation_is_a_cosine_and_cost_its_complement(rng):
    target, model = rng.normal(size=64), rng.normal(size=64)
    t, m = target.copy(), model.copy()
    t[0] = m[0] = 0.0
    value, _ = svs.so3_correlation(target, model, np.eye(3))
    assert value == pytest.approx(t @ m / np.linalg.norm(t) / np.linalg.norm(m), abs=1e-14)
    raw, _ = svs.so3_correlation(target, model, np.eye(3), normalised=False)
    assert raw == pytest.approx(target @ model, rel=1e-12)
    R = axis_angle((1, 2, 2), 70.0)
    c, _ = svs.so3_correlation(target, model, R)
    assert svs.rotation_cost(target, model, R) == pytest.approx(1.0 - c, abs=1e-12)
    correlation = svs.So3Correlation(target, model)
    assert correlation.bandwidth == 8
    assert correlation.evaluate(R)[0] == pytest.approx(c, abs=1e-15)


# --- EGI coefficients ----------------------------------------------------------------


def covariance_error(normals, R, bandwidth, method):
    F = svs.egi_coefficients(normals, bandwidth, method=method)
    G = svs.egi_coefficients(normals @ R.T, bandwidth, method=method)
    U = svs.wigner_real(R, bandwidth - 1)
    expected = np.concatenate([U[ell] @ F[ell * ell : (ell + 1) ** 2] for ell in range(bandwidth)])
    return np.linalg.norm(G - expected) / np.linalg.norm(expected)


@pytest.mark.parametrize("bandwidth", [8, 16, 32])
def test_egi_covariance_error_by_method(rng, bandwidth):
    normals = clustered_normals(rng)
    R = axis_angle(random_axis(rng), 50.0)
    assert covariance_error(normals, R, bandwidth, "projection") < 1e-12
    # Snapping normals to grid cells: tens of percent (docs/rotation.md).
    assert 0.05 < covariance_error(normals, R, bandwidth, "histogram") < 1.0


def test_egi_coefficients_of_a_cloud_and_weights(data_dir):
    cloud = svs.load_cloud(data_dir / "bun0.pcd")
    F = svs.egi_coefficients(cloud, 8)
    np.testing.assert_allclose(F, svs.egi_coefficients(cloud.normals, 8), atol=1e-13)
    weights = np.full(len(cloud), 0.5)
    np.testing.assert_allclose(svs.egi_coefficients(cloud, 8, weights=weights), 0.5 * F, atol=1e-13)
    assert F[0] == pytest.approx(len(cloud) / np.sqrt(4 * np.pi))  # S^0_0 = 1 / sqrt(4 pi)


def test_smoothing_is_the_heat_kernel(rng):
    c = rng.normal(size=36)
    s = svs.smooth_coefficients(c, 6, 0.2)
    ell = np.floor(np.sqrt(np.arange(36)))
    np.testing.assert_allclose(s, c * np.exp(-ell * (ell + 1) * 0.04 / 2), rtol=1e-14)
    assert not np.shares_memory(s, c)


# --- Finding the rotation ------------------------------------------------------------


@pytest.fixture(scope="module")
def bunny_normals(data_dir):
    """The normals of the real bunny scan (PCL test data, 397 points)."""
    return svs.load_cloud(data_dir / "bun0.pcd").normals


@pytest.mark.parametrize("degrees", [5.0, 10.0, 20.0])
def test_gradient_ascent_from_identity_finds_small_rotations(rng, bunny_normals, degrees):
    bandwidth = 16
    R = axis_angle(random_axis(rng), degrees)
    model = svs.egi_coefficients(bunny_normals, bandwidth)
    target = svs.egi_coefficients(bunny_normals @ R.T, bandwidth)
    for newton in (False, True):
        result = svs.refine_rotation(target, model, np.eye(3), newton=newton, max_iterations=500)
        assert result.converged
        assert angle_deg(result.R, R) < 0.01
        assert "converged=True" in repr(result)


@pytest.mark.parametrize("degrees", [30.0, 90.0, 135.0, 180.0])
def test_global_search_then_refinement_recovers_any_rotation(rng, bunny_normals, degrees):
    bandwidth = 16
    R = axis_angle(random_axis(rng), degrees)
    model = svs.egi_coefficients(bunny_normals, bandwidth)
    target = svs.egi_coefficients(bunny_normals @ R.T, bandwidth)
    candidates = svs.so3_search(target, model, bandwidth, k=8)
    assert 1 <= len(candidates) <= 8
    values = [c for _, c in candidates]
    assert values == sorted(values, reverse=True)
    grid_step_deg = 180.0 / bandwidth
    assert angle_deg(candidates[0][0], R) < 1.25 * grid_step_deg
    refined = max(
        (svs.refine_rotation(target, model, R0) for R0, _ in candidates),
        key=lambda r: r.correlation,
    )
    assert angle_deg(refined.R, R) < 1.0
    assert refined.correlation == pytest.approx(1.0, abs=1e-9)


def test_search_maximum_matches_brute_force_on_its_grid(rng):
    bandwidth = 4
    target, model = rng.normal(size=16), rng.normal(size=16)
    n = 2 * bandwidth
    best = max(
        svs.so3_correlation(
            target,
            model,
            euler_zyz(
                np.pi * i / bandwidth, np.pi * (2 * j + 1) / (4 * bandwidth), np.pi * k / bandwidth
            ),
        )[0]
        for i in range(n)
        for j in range(n)
        for k in range(n)
    )
    candidates = svs.so3_search(target, model, bandwidth, k=3)
    assert candidates[0][1] == pytest.approx(best, abs=1e-12)
    for R, value in candidates:
        assert svs.so3_correlation(target, model, R)[0] == pytest.approx(value, abs=1e-12)


# --- Bad input -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("R", "message"),
    [
        (2 * np.eye(3), "R is not a rotation matrix"),
        (np.diag([1.0, 1.0, -1.0]), "det = -1"),
        (np.full((3, 3), np.nan), "R is not finite"),
        (np.eye(3, dtype=int), "R must have a floating dtype"),
        (np.eye(4), r"R must have shape \(3, 3\)"),
    ],
)
def test_bad_rotations_raise(R, message):
    with pytest.raises(ValueError, match=message):
        svs.wigner_real(R, 4)
    with pytest.raises(ValueError, match=message):
        svs.so3_correlation(np.ones(16), np.ones(16), R)


def test_bad_sizes_and_bandwidths_raise():
    with pytest.raises(ValueError, match=r"bandwidth must be in \[1, 128\], got 0"):
        svs.sh_coefficients(np.zeros((2, 2)), 0)
    with pytest.raises(ValueError, match=r"bandwidth must be in \[1, 128\], got 129"):
        svs.egi_coefficients(np.eye(3), 129)
    with pytest.raises(ValueError, match=r"grid must have shape \(2B, 2B\) = \(8, 8\)"):
        svs.sh_coefficients(np.zeros((8, 6)), 4)
    with pytest.raises(ValueError, match="expected bandwidth\\^2 = 16 coefficients"):
        svs.sh_synthesis(np.zeros(15), 4)
    with pytest.raises(ValueError, match=r"target_coefficients: length 15 is not B\^2"):
        svs.so3_correlation(np.ones(15), np.ones(16), np.eye(3))
    with pytest.raises(ValueError, match="model_coefficients: expected bandwidth\\^2 = 16"):
        svs.so3_correlation(np.ones(16), np.ones(9), np.eye(3))
    with pytest.raises(ValueError, match="target_coefficients: expected bandwidth\\^2 = 25"):
        svs.so3_search(np.ones(16), np.ones(16), 5)
    with pytest.raises(ValueError, match="target_coefficients must have a floating dtype"):
        svs.so3_search(np.ones(16, dtype=np.int64), np.ones(16), 4)
    with pytest.raises(ValueError, match=r"lmax must be in \[0, 127\]"):
        svs.wigner_real(np.eye(3), 128)
    with pytest.raises(ValueError, match="method must be 'projection' or 'histogram'"):
        svs.egi_coefficients(np.eye(3), 4, method="counts")
    with pytest.raises(ValueError, match=r"params\.candidates must be >= 1"):
        svs.so3_search(np.ones(16), np.ones(16), 4, k=0)
    with pytest.raises(ValueError, match="no energy at degrees l >= 1"):
        svs.so3_search(np.eye(16)[0], np.ones(16), 4)
    with pytest.raises(ValueError, match="sigma must be finite and >= 0"):
        svs.smooth_coefficients(np.ones(16), 4, -0.1)


# --- The rotation law about one axis (the servo's plane turn) ------------------------


def test_rotation_step_about_an_axis_is_the_law_along_it(rng):
    """Brute force: the slope and curvature of C(R exp(theta hat(axis))) by central
    differences, then the law (Newton where concave, else the gradient law, capped)."""
    normals = clustered_normals(rng)
    model = svs.egi_coefficients(normals, 8)
    params = svs.AlignParams()
    params.max_rotation_step = 0.05
    params.rotation_gain = 1.0
    axis = random_axis(rng)
    cases = 0
    for degrees in (0.5, 1.5, 2.5, 20.0, 60.0, 120.0):
        truth = axis_angle(axis, degrees)  # the scene: the model turned about the axis
        scene = svs.egi_coefficients(normals @ truth.T, 8)
        correlation = svs.So3Correlation(scene, model)
        R = np.eye(3)
        step = svs.rotation_step_about(correlation, R, 3.0 * axis, params)  # any length

        def C(theta, scene=scene, R=R):
            turned = R @ axis_angle(axis, np.degrees(theta))
            return svs.so3_correlation(scene, model, turned)[0]

        h = 1e-4
        slope = (C(h) - C(-h)) / (2 * h)
        curvature = (C(h) - 2 * C(0.0) + C(-h)) / h**2
        assert step.slope == pytest.approx(slope, rel=1e-6, abs=1e-9)
        assert step.curvature == pytest.approx(curvature, rel=1e-4, abs=1e-6)
        raw = -slope / curvature if curvature < 0 else slope
        expected = float(np.clip(raw, -0.05, 0.05))
        assert step.newton == (curvature < 0)
        assert step.capped == (abs(raw) > 0.05)
        assert step.turn == pytest.approx(expected, abs=1e-6)
        if degrees < 3.0:  # near the peak: the Newton step lands on the truth (within 0.05 deg)
            assert step.newton and not step.capped
            assert np.degrees(abs(step.turn - np.radians(degrees))) < 0.05
            cases += 1
        else:  # farther: a capped step toward the truth
            assert step.turn == pytest.approx(0.05 if degrees < 180 else -0.05)
    assert cases == 3
    # The gain scales the Newton step too (the law of align()): 1 degree short of the truth.
    near = axis_angle(axis, 119.0)
    full = svs.rotation_step_about(correlation, near, axis, params)
    params.rotation_gain = 0.5
    half = svs.rotation_step_about(correlation, near, axis, params)
    assert full.newton and not full.capped
    assert np.degrees(abs(full.turn - np.radians(1.0))) < 0.05
    assert half.turn == pytest.approx(0.5 * full.turn, rel=1e-12)
    with pytest.raises(ValueError, match="axis"):
        svs.rotation_step_about(correlation, np.eye(3), np.zeros(3), params)
