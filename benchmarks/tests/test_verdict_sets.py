"""The verdict's problem sets (benchmarks/verdict_sets.py) and the calibration arithmetic of
benchmarks/verdict_benchmark.py.

The two sets share no object, scene or seed; a seed fixes a problem's arrays; the depth
noise has the Nguyen model's spread; a base-frame problem is its camera problem moved; a
problem without a right answer has no truth. The isotonic fit equals the closed-form
least-squares monotone fit and an exhaustive search; the knots, threshold, inflation
factor and the left error do what their docstrings say."""

from __future__ import annotations

import dataclasses
import itertools
import math

import cases
import numpy as np
import pytest
import verdict_benchmark as bench
import verdict_sets as vs


def scans_available() -> bool:
    return all(
        (cases.data_dir() / name).is_file()
        for name in ("milk_cartoon_all_small_clorox.pcd", "five_people.pcd")
    )


needs_scans = pytest.mark.skipif(not scans_available(), reason="the real scans are missing")


# --- The sets ----------------------------------------------------------------------------------


def labels(set_name: str, field: str) -> set:
    out: set = set()
    for spec in vs.specs(set_name):
        value = getattr(spec, field)
        out |= set(value) if isinstance(value, tuple) else {value}
    return out


@pytest.mark.parametrize("field", ["objects", "scenes", "seed"])
def test_no_object_scene_or_seed_is_in_both_sets(field):
    calibration, validation = labels("calibration", field), labels("validation", field)
    assert len(calibration) > 5 and len(validation) > 5
    assert calibration.isdisjoint(validation)


def test_the_real_scans_and_object_pools_are_split():
    assert labels("calibration", "scenes") >= {"scan:table", "scan:bun0"}
    assert "scan:room" in labels("validation", "scenes")
    assert "scan:room" not in labels("calibration", "scenes")
    assert set(vs.MATERIAL["calibration"]["objects"]).isdisjoint(
        vs.MATERIAL["validation"]["objects"]
    )


@pytest.mark.parametrize("set_name", vs.SETS)
def test_each_set_has_the_sizes_and_families_asked_for(set_name):
    specs = vs.specs(set_name)
    align = [s for s in specs if s.kind == "align"]
    views = [s for s in specs if s.kind == "views"]
    assert 150 <= len(align) <= 250 and 80 <= len(views) <= 150
    assert len({s.case_id for s in specs}) == len(specs)
    overlaps = [s.args["overlap"] for s in views if s.family == "scan"]
    assert min(overlaps) < 0.32 and max(overlaps) > 0.98
    factors = {s.args.get("voxel_factor") for s in specs if s.family == "wrong_voxel"}
    assert factors == {10.0, 0.1}


def test_problems_without_a_right_answer_are_declared_so():
    for set_name in vs.SETS:
        for spec in vs.specs(set_name):
            assert spec.has_truth == (spec.family not in vs.NO_TRUTH_FAMILIES)


def test_the_same_seed_gives_the_same_specs():
    first, second = vs.specs("validation"), vs.specs("validation")
    assert [(s.case_id, s.seed, s.args) for s in first] == [
        (s.case_id, s.seed, s.args) for s in second
    ]


def same_arrays(a: vs.VerdictCase, b: vs.VerdictCase) -> None:
    for cloud in ("source", "target"):
        np.testing.assert_array_equal(getattr(a, cloud).points, getattr(b, cloud).points)
        np.testing.assert_array_equal(getattr(a, cloud).normals, getattr(b, cloud).normals)
    np.testing.assert_array_equal(a.T_true, b.T_true)


@needs_scans
def test_a_view_pair_is_the_same_on_every_build():
    spec = next(s for s in vs.specs("calibration") if s.family == "scan_base")
    a, b = vs.build_case(spec), vs.build_case(spec)
    same_arrays(a, b)
    assert len(a.source) > 1000


def test_a_castle_is_the_same_on_every_build_and_differs_by_seed():
    pytest.importorskip("pybullet")
    castles = [s for s in vs.specs("validation") if s.family == "castle"]
    a, b, other = vs.build_case(castles[0]), vs.build_case(castles[0]), vs.build_case(castles[1])
    same_arrays(a, b)
    assert len(a.target) != len(other.target)


# --- Depth noise ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("depth_m", "sigma_mm"), [(1.0, 1.884), (2.0, 6.064)])
def test_the_depth_noise_has_the_nguyen_spread(depth_m, sigma_mm):
    assert 1000 * vs.nguyen_sigma_m(depth_m) == pytest.approx(sigma_mm, rel=1e-12)
    rng = np.random.default_rng(5)
    noisy = vs.noisy_depth(np.full((100, 200), depth_m), rng)
    kept = noisy[np.isfinite(noisy)]
    assert 1000 * np.std(kept - depth_m) == pytest.approx(sigma_mm, rel=0.10)
    assert 1.0 - kept.size / noisy.size == pytest.approx(vs.DROPPED_SHARE, abs=0.006)


# --- Frames and truths -------------------------------------------------------------------------


def camera_twin(spec: vs.Spec) -> vs.Spec:
    return dataclasses.replace(spec, args={k: v for k, v in spec.args.items() if k != "frame"})


def check_moved(base: vs.VerdictCase, camera: vs.VerdictCase) -> None:
    T = np.asarray(base.info["T_base_target"])
    assert np.linalg.norm(T[:3, 3]) > 0.3  # really elsewhere
    np.testing.assert_array_equal(base.source.points, camera.source.points)
    np.testing.assert_allclose(base.target.points, cases.apply(T, camera.target.points), atol=1e-12)
    np.testing.assert_allclose(base.target.normals, camera.target.normals @ T[:3, :3].T, atol=1e-12)
    np.testing.assert_allclose(base.sensor_origin, cases.apply(T, camera.sensor_origin[None])[0])
    np.testing.assert_allclose(base.T_true, T @ camera.T_true, atol=1e-12)
    # An estimate off by 3 degrees and 4 mm is off by as much in either frame.
    off = cases.rotation_about(
        cases.axis_angle(np.array([1.0, 2.0, 0.5]), math.radians(3.0)), camera.T_true[:3, 3]
    )
    off[:3, 3] += [0.004, 0.0, 0.0]
    estimate = off @ camera.T_true
    rot_c, trans_c = vs.pose_errors(camera, estimate)
    rot_b, trans_b = vs.pose_errors(base, T @ estimate)
    assert rot_b == pytest.approx(rot_c, abs=1e-9) and trans_b == pytest.approx(trans_c, abs=1e-12)
    assert rot_c == pytest.approx(3.0, abs=1e-6)


def test_a_base_frame_scan_is_the_camera_scan_moved():
    pytest.importorskip("pybullet")
    spec = next(s for s in vs.specs("calibration") if s.family == "base_frame")
    base, camera = vs.build_case(spec), vs.build_case(camera_twin(spec))
    assert np.allclose(camera.sensor_origin, 0.0)  # the camera case is in its camera's frame
    check_moved(base, camera)


@needs_scans
def test_a_base_frame_view_pair_is_the_camera_pair_moved():
    spec = next(s for s in vs.specs("validation") if s.family == "scan_base")
    check_moved(vs.build_case(spec), vs.build_case(camera_twin(spec)))


def test_a_wrong_object_has_no_truth_and_is_not_in_the_scene():
    pytest.importorskip("pybullet")
    for spec in [s for s in vs.specs("calibration") if s.family == "wrong_object"][:2]:
        case = vs.build_case(spec)
        assert case.T_true is None and not case.has_truth
        assert vs.pose_errors(case, np.eye(4)) is None and not vs.is_right(case, np.eye(4))
        present = case.info.get("objects", [case.info["object"]])
        assert case.info["wrong_model"] in vs.MATERIAL["calibration"]["objects"]
        assert case.info["wrong_model"] not in present
        assert len(case.source) == cases.MODEL_SAMPLES


@needs_scans
def test_views_of_two_scenes_have_no_truth():
    pytest.importorskip("pybullet")
    spec = next(s for s in vs.specs("validation") if s.family == "share_nothing")
    case = vs.build_case(spec)
    assert case.T_true is None and not vs.is_right(case, np.eye(4))
    assert len(case.source) > 1000 and len(case.target) > 1000


def test_errors_count_symmetries_and_the_left_error_is_first_order():
    T_true = cases.pose(cases.axis_angle(np.array([0.0, 0.0, 1.0]), 0.3), np.array([0.1, 0, 0]))
    half_turn = cases.rotation_about(np.diag([-1.0, -1.0, 1.0]), np.array([0.0, 0.0, 0.0]))
    case = vs.VerdictCase(
        spec=vs.specs("calibration")[0],
        source=None,
        target=None,
        T_true=T_true,
        symmetries=np.array([np.eye(4), half_turn]),
        center=np.zeros(3),
        sensor_origin=np.zeros(3),
    )
    flipped = T_true @ half_turn
    assert vs.pose_errors(case, flipped) == pytest.approx((0.0, 0.0), abs=1e-9)
    np.testing.assert_allclose(vs.nearest_truth(case, flipped), flipped, atol=1e-12)
    delta = np.array([0.002, -0.001, 0.003, 0.004, 0.001, -0.002])
    exp_delta = cases.pose(cases.axis_angle(delta[:3], np.linalg.norm(delta[:3])), delta[3:])
    error = vs.left_error(exp_delta @ flipped, flipped)
    np.testing.assert_allclose(error[:3], delta[:3], atol=1e-12)
    np.testing.assert_allclose(error[3:], delta[3:], atol=1e-12)


@pytest.mark.parametrize("angle_deg", [0.001, 37.0, 179.95])
def test_the_rotation_log_is_axis_times_angle(angle_deg):
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    vector = vs.rotation_log(cases.axis_angle(axis, math.radians(angle_deg)))
    np.testing.assert_allclose(vector, math.radians(angle_deg) * axis, atol=1e-9)


# --- Calibration arithmetic ---------------------------------------------------------------------


def min_max_isotonic(y: np.ndarray) -> np.ndarray:
    """The least-squares monotone fit in closed form: f_i = max_{j<=i} min_{k>=i} mean(y_j..k)."""
    n = len(y)
    return np.array(
        [max(min(y[j : k + 1].mean() for k in range(i, n)) for j in range(i + 1)) for i in range(n)]
    )


def test_pav_equals_the_closed_form_monotone_fit():
    rng = np.random.default_rng(3)
    for _ in range(20):
        y = rng.integers(0, 2, size=9).astype(float)
        _, fitted, _ = bench.pav(np.arange(9.0), y)
        np.testing.assert_allclose(fitted, min_max_isotonic(y), atol=1e-12)
    _, fitted, _ = bench.pav(np.arange(6.0), np.array([1.0, 0, 1, 0, 0, 1]))
    np.testing.assert_allclose(fitted, [0.4, 0.4, 0.4, 0.4, 0.4, 1.0])


def test_pav_is_the_best_monotone_fit_by_exhaustive_search():
    y = np.array([1.0, 0.0, 0.0, 1.0])
    levels = np.arange(13) / 12.0  # every PAV value of 4 binary labels is on this grid
    best = min(
        np.sum((np.array(f) - y) ** 2) for f in itertools.combinations_with_replacement(levels, 4)
    )
    _, fitted, _ = bench.pav(np.arange(4.0), y)
    assert np.sum((fitted - y) ** 2) == pytest.approx(best, abs=1e-12)
    np.testing.assert_allclose(fitted, [1 / 3, 1 / 3, 1 / 3, 1.0])


def test_pav_pools_equal_scores():
    xs, fitted, weights = bench.pav(np.array([0.5, 0.2, 0.5, 0.9]), np.array([1.0, 0, 0, 1]))
    np.testing.assert_array_equal(xs, [0.2, 0.5, 0.9])
    np.testing.assert_array_equal(weights, [1, 2, 1])
    np.testing.assert_allclose(fitted, [0.0, 0.5, 1.0])


def test_the_knots_are_few_monotone_and_span_zero_to_one():
    rng = np.random.default_rng(8)
    scores = rng.random(600)
    right = rng.random(600) < scores**2
    knots = bench.fit_calibration(scores, right)
    assert 3 <= len(knots) <= bench.MAX_KNOTS
    assert knots[0, 0] == 0.0 and knots[-1, 0] == 1.0
    assert np.all(np.diff(knots[:, 0]) > 0) and np.all(np.diff(knots[:, 1]) >= 0)
    for s in (0.3, 0.6, 0.9):  # close to the true P(right | s) = s^2
        assert bench.calibrated(np.array([s]), knots)[0] == pytest.approx(s**2, abs=0.12)


def test_the_threshold_keeps_the_most_right_with_at_most_one_percent_wrong():
    conf = np.concatenate([np.linspace(0.0, 0.5, 50), np.linspace(0.6, 1.0, 200)])
    right = conf > 0.45  # right from index 45 on
    right[[60, 230]] = False
    ambiguous = np.zeros_like(right)
    # From index 45: 205 reliable, 2 wrong (0.98%); from 44 on a third wrong one (1.5%).
    threshold = bench.choose_threshold(conf, right, ~ambiguous)
    assert threshold == conf[45]
    shares = bench.reliable_shares(conf, right, ~ambiguous, threshold)
    assert shares["wrong_reliable"] == 2 and shares["right_share_reliable"] == 1.0
    # A third wrong one: no threshold below it keeps 1%, so only the 9 above it are kept.
    right[240] = False
    threshold = bench.choose_threshold(conf, right, ~ambiguous)
    assert threshold == conf[241]
    assert bench.reliable_shares(conf, right, ~ambiguous, threshold)["reliable"] == 9
    ambiguous[240] = True  # an ambiguous answer is never reliable: back to 2 wrong of 204
    assert bench.choose_threshold(conf, right, ~ambiguous) == conf[45]


def test_the_inflation_factor_makes_the_mean_nees_six():
    rng = np.random.default_rng(11)
    A = rng.normal(size=(6, 6))
    C = A @ A.T + 0.1 * np.eye(6)
    errors = rng.multivariate_normal(np.zeros(6), 4.0 * C, size=4000)
    right = {"right": True, "family": "full", "covariance": C.tolist()}
    records = [right | {"error_vector": e.tolist()} for e in errors] + [
        {"right": False, "family": "full", "covariance": C.tolist(), "error_vector": [9.0] * 6},
        # Left out of the fit: a wrong-voxel answer, however far off.
        right | {"family": "wrong_voxel", "error_vector": [9.0] * 6},
    ]
    # The library's k: the factor on the covariance as computed, times the k it used.
    k = bench.inflation_factor(records, "align") / bench.current_inflation("align")
    assert k == pytest.approx(4.0, rel=0.06)
    assert np.mean(bench.nees_values(records, k)) == pytest.approx(6.0, rel=1e-9)


def test_auc_and_calibration_error_on_known_values():
    scores = np.array([0.1, 0.4, 0.35, 0.8])
    labels = np.array([False, False, True, True])
    assert bench.auc(scores, labels) == pytest.approx(0.75)
    conf = np.array([0.95, 0.95, 0.15, 0.15])
    right = np.array([True, False, False, False])
    assert bench.expected_calibration_error(conf, right) == pytest.approx(0.5 * 0.45 + 0.5 * 0.15)


def test_auc_counts_every_pair_ties_half_as_brute_force_does():
    rng = np.random.default_rng(7)
    for _ in range(5):
        scores = rng.integers(0, 6, size=150).astype(float)  # many ties
        labels = rng.random(150) < 0.3
        pos, neg = scores[labels], scores[~labels]
        pairs = [(p > n) + 0.5 * (p == n) for p in pos for n in neg]
        assert bench.auc(scores, labels) == pytest.approx(np.mean(pairs), abs=1e-12)
    assert bench.auc(np.array([0.2, 0.3]), np.array([True, True])) is None


def test_the_emulated_verdict_reads_the_fitted_calibration_and_the_gates():
    calibration = {"align": {"knots": [[0.0, 0.0], [0.5, 0.2], [1.0, 0.9]], "threshold": 0.7}}
    base = {"kind": "align", "score": 0.9, "ambiguous": False, "status": None}
    records = [
        base,
        base | {"score": 0.6},  # confidence 0.34: doubtful
        base | {"ambiguous": True},
        base | {"status": "bad_scale"},
        base | {"score": None},  # no answer
    ]
    rows = bench.with_verdict(records, calibration, "fitted")
    assert rows[0]["confidence"] == pytest.approx(0.2 + 0.7 * 0.8)
    assert rows[1]["confidence"] == pytest.approx(0.2 + 0.7 * 0.2)
    assert [r["reliable"] for r in rows] == [True, False, False, False, False]
    assert [r["verdict_source"] for r in rows] == ["emulated"] * 4 + ["error"]
    library = bench.with_verdict([base | {"reliable": False, "confidence": 0.1}], {}, "library")
    assert library[0]["reliable"] is False and library[0]["verdict_source"] == "library"
