"""The aligner (Algorithm 1) from Python: accuracy in degrees and millimetres, bad input."""

from __future__ import annotations

import numpy as np
import pytest

import spectral_vs as svs
from spectral_vs import data
from spectral_vs.data import scenes
from spectral_vs.data.scenes import BoxWithBall


def rotation(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rodrigues' formula: an independent construction of the ground truth."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = np.radians(angle_deg)
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


#: A 24 x 12 x 8 cm box with a 6 cm ball on one face.
BOX_WITH_BALL = BoxWithBall(
    half=(0.12, 0.06, 0.04), ball_centre=(0.07, 0.0, 0.07), ball_radius=0.03, offset=(0, 0, 0)
)


def box_with_ball(rng: np.random.Generator, samples: int) -> tuple[np.ndarray, np.ndarray]:
    return scenes.box_with_ball(rng, samples=samples, shape=BOX_WITH_BALL)


def make_case(rng, angle_deg):
    points, normals = box_with_ball(rng, 9000)
    R = rotation(rng.normal(size=3), angle_deg)
    t = rng.uniform(-0.1, 0.1, size=3)
    scene_points, scene_normals = box_with_ball(rng, 9000)  # an independent resampling
    scene_points = scene_points + rng.normal(0, 0.001, scene_points.shape)
    model = svs.PointCloud(points, normals)
    scene = svs.PointCloud(scene_points @ R.T + t, scene_normals @ R.T)
    return model, scene, R, t


def errors(result, R, t):
    T = np.asarray(result.T_scene_model)
    cos = np.clip((np.trace(T[:3, :3].T @ R) - 1) / 2, -1, 1)
    return np.degrees(np.arccos(cos)), 1000 * np.linalg.norm(T[:3, 3] - t)


@pytest.mark.parametrize("angle", [5, 15])
def test_paper_mode_converges_from_small_rotations(angle):
    rng = np.random.default_rng(angle)
    model, scene, R, t = make_case(rng, angle)
    result = svs.align(model, scene, global_search=False, downsample=False)
    rotation_error, translation_error = errors(result, R, t)
    assert result.converged
    assert rotation_error < 1.0
    assert translation_error < 2.0
    assert result.fitness > 0.9
    assert len(result.history) == result.iterations
    # The costs of eq. (9) and (16) fall from the first iteration to the last.
    assert result.history[-1].rotation_cost <= result.history[0].rotation_cost
    assert result.history[-1].translation_cost < result.history[0].translation_cost


@pytest.mark.parametrize("angle", [60, 120, 180])
def test_global_search_recovers_large_rotations(angle):
    rng = np.random.default_rng(100 + angle)
    model, scene, R, t = make_case(rng, angle)
    result = svs.align(model, scene, downsample=False)
    rotation_error, translation_error = errors(result, R, t)
    assert rotation_error < 1.0
    assert translation_error < 2.0


def test_fitness_tells_success_from_failure():
    rng = np.random.default_rng(7)
    model, scene, R, t = make_case(rng, 120)
    stuck = svs.align(
        model, scene, global_search=False, downsample=False
    )  # beyond the paper's basin
    found = svs.align(model, scene, downsample=False)
    assert errors(stuck, R, t)[0] > 5.0
    assert errors(found, R, t)[0] < 1.0
    assert found.fitness > 0.9 > 0.75 > stuck.fitness


def test_same_input_gives_the_same_pose():
    rng = np.random.default_rng(8)
    model, scene, _, _ = make_case(rng, 40)
    first = svs.align(model, scene, downsample=False)
    second = svs.align(model, scene, downsample=False)
    np.testing.assert_array_equal(first.T_scene_model, second.T_scene_model)


def test_max_iterations_reports_not_converged():
    rng = np.random.default_rng(9)
    model, scene, _, _ = make_case(rng, 15)
    result = svs.align(model, scene, global_search=False, max_iterations=1, downsample=False)
    assert not result.converged
    assert result.iterations == 1


def test_arrays_without_normals_are_accepted(rng):
    points, _ = box_with_ball(rng, 6000)
    result = svs.align(points, points + np.array([0.01, 0.0, 0.0]), sensor_origin=(0.0, 0.0, 1.0))
    assert np.linalg.norm(np.asarray(result.T_scene_model)[:3, 3] - [0.01, 0, 0]) < 0.002


def test_bad_input():
    rng = np.random.default_rng(10)
    model, scene, _, _ = make_case(rng, 10)
    with pytest.raises(ValueError, match="model is empty"):
        svs.align(svs.PointCloud(np.zeros((0, 3))), scene, downsample=False)
    lonely = svs.PointCloud(np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]))  # no normal can be fitted
    with pytest.raises(ValueError, match="no point has enough neighbours"):
        svs.align(model, lonely, downsample=False)
    with pytest.raises(ValueError, match="voxel_size must be finite and > 0"):
        svs.align(model, scene, voxel_size=-1.0, downsample=False)
    with pytest.raises(ValueError, match="translation_gain must be in"):
        svs.align(model, scene, translation_gain=1.5, downsample=False)
    with pytest.raises(ValueError, match="initial_guess is not a rigid transform"):
        svs.align(model, scene, initial_guess=np.diag([2.0, 1, 1, 1]), downsample=False)
    with pytest.raises(ValueError, match="exceeds the limit of 1000 voxels"):
        svs.align(model, scene, max_voxels=1000, downsample=False)
    # An unknown setting is the TypeError that AlignParams(gain=0.1) raises, named.
    with pytest.raises(TypeError, match="unknown alignment setting 'gain'"):
        svs.align(model, scene, gain=0.1)
    with pytest.raises(TypeError, match="unexpected keyword argument 'gain'"):
        svs.AlignParams(gain=0.1)
    with pytest.raises(TypeError, match=r"'voxel'.*did you mean .*'voxel_size'"):
        svs.align(model, scene, voxel=0.01)
    with pytest.raises(ValueError, match="model must be a PointCloud or an"):
        svs.align(np.zeros((5, 4)), scene)


def test_settings_passed_in_are_not_changed():
    rng = np.random.default_rng(11)
    model, scene, _, _ = make_case(rng, 10)
    settings = svs.AlignParams()
    svs.align(model, scene, settings, max_iterations=3, downsample=False)
    assert settings.max_iterations == svs.AlignParams().max_iterations


def test_iterations_are_timed():
    rng = np.random.default_rng(12)
    model, scene, _, _ = make_case(rng, 10)
    result = svs.align(model, scene, global_search=False, downsample=False)
    seconds = [step.seconds for step in result.history]
    assert all(s > 0.0 for s in seconds)
    assert sum(seconds) < 10.0  # a bound that catches a unit error (ms for s), not a speed


@pytest.mark.parametrize("global_search", [True, False])
def test_the_stages_account_for_the_call(global_search):
    """AlignResult.timings: every stage timed once, none negative, together the whole call
    but for the settings' checks and the result's copies (consistency, not a speed)."""
    rng = np.random.default_rng(13)
    model, scene, _, _ = make_case(rng, 60)
    result = svs.align(model, scene, global_search=global_search, downsample=False, threads=1)
    stages = result.timings.as_dict()
    total = stages.pop("total")
    assert list(stages) == [
        "preparation",
        "rotation_search",
        "placement",
        "algorithm1",
        "icp",
        "alternatives",
        "verdict",
    ]
    assert all(seconds >= 0.0 for seconds in stages.values())
    assert 0.9 * total <= sum(stages.values()) <= total
    searched = ("rotation_search", "placement")
    if global_search:
        assert all(stages[name] > 0.0 for name in ("preparation", *searched, "algorithm1"))
    else:  # the paper's mode: Algorithm 1 from the guess, no search
        assert all(stages[name] == 0.0 for name in (*searched, "icp"))
        assert stages["algorithm1"] > 0.0


def test_bad_search_settings_name_the_setting():
    rng = np.random.default_rng(13)
    model, scene, _, _ = make_case(rng, 10)
    with pytest.raises(ValueError, match=r"refinements must be in \[1, hypotheses = 4\]"):
        svs.align(model, scene, hypotheses=4, refinements=5, downsample=False)
    with pytest.raises(ValueError, match="search_voxel_size must be >= 0"):
        svs.align(model, scene, search_voxel_size=-0.01, downsample=False)
    with pytest.raises(ValueError, match="window_margin must be >= 0"):
        svs.align(model, scene, window_margin=float("nan"), downsample=False)
    with pytest.raises(ValueError, match=r"refinement_iterations must be in \[1, 10000\], got 0"):
        svs.align(model, scene, refinement_iterations=0, downsample=False)


def test_refinements_stop_at_their_iterations():
    """With global search each refinement runs at most refinement_iterations of
    Algorithm 1 (max_iterations is the paper's mode's); a run cut short says so."""
    rng = np.random.default_rng(14)
    model, scene, _, _ = make_case(rng, 10)
    result = svs.align(model, scene, refinement_iterations=2, max_iterations=50, tolerance=1e-9)
    assert result.iterations == 2 and len(result.history) == 2
    assert not result.converged and result.stop_reason == "max_iterations"
    paper = svs.align(model, scene, global_search=False, max_iterations=3, tolerance=1e-9)
    assert paper.iterations == 3


def _benchmark_cases():
    pytest.importorskip("pybullet")  # the meshes come with pybullet_data
    import cases

    return cases


def test_polish_resolves_the_near_symmetric_mug():
    """The mug's EGI barely sees its handle: the global search alone ends 5-15 degrees
    off about the mug's axis (docs/experiments.md). Without the ICP, the polish's pattern
    search on the voxel correlation sees the handle; with it, the polish is the sweep
    about the mug's axis alone (24 turns) and the ICP ends closer."""
    cases = _benchmark_cases()

    rotation_errors = {False: [], True: []}
    for angle in (30.0, 60.0, 120.0, 150.0):
        for index in (0, 5):
            case = cases.make_case(cases.CaseSpec("full", "mug", angle, index))
            for icp in (False, True):
                result = svs.align(
                    case.model_cloud(), case.scene_cloud(), polish=True, icp_refinement=icp
                )
                rotation, translation = cases.pose_error(case, np.asarray(result.T_scene_model))
                rotation_errors[icp].append(rotation)
                assert translation < 0.005  # metres
                if icp:
                    assert result.polish_evaluations == 24
                else:
                    assert result.polish_evaluations > 24
    for icp, errors in rotation_errors.items():
        assert sum(e < 2.0 for e in errors) >= 6, (icp, errors)
        assert np.median(errors) < 1.5, (icp, errors)
    assert np.median(rotation_errors[True]) < np.median(rotation_errors[False])


def test_flat_axis_sweep_finds_the_mug_handle():
    """Where the global search ended on the wrong side of the mug's handle (17-59 degrees
    off about the mug's axis without the sweep, measured), the turns about the axis its
    EGI cannot see, scored by voxel overlap, find the handle."""
    cases = _benchmark_cases()

    for angle, index in ((30.0, 1), (60.0, 1), (90.0, 1), (120.0, 1), (150.0, 0), (150.0, 2)):
        case = cases.make_case(cases.CaseSpec("full", "mug", angle, index))
        result = svs.align(case.model_cloud(), case.scene_cloud())
        rotation, translation = cases.pose_error(case, np.asarray(result.T_scene_model))
        assert rotation < 2.0, (angle, index, rotation)  # degrees
        assert translation < 0.002  # metres


def test_each_refined_mug_is_swept_before_the_comparison():
    """Without a view, fitness ranks the mug upside down about as high as upright with
    its handle elsewhere (0.955 against 0.952-0.955 in full-mug-a180-9, the one C-1
    failure of the run before): each refined pose is turned about the mug's axis before
    the refinements are compared, and upright with its handle in place wins (fitness
    1.0). The mugs of the experiment at 180 degrees. The flips fit about as well as the
    best: all three hypotheses are refined."""
    cases = _benchmark_cases()
    for index in (0, 9, 18):
        case = cases.make_case(cases.CaseSpec("full", "mug", 180.0, index))
        result = svs.align(case.model_cloud(), case.scene_cloud())
        rotation, translation = cases.pose_error(case, np.asarray(result.T_scene_model))
        assert rotation < 2.0 and translation < 0.002, (index, rotation, translation)
        assert result.refinements_run == 3


@pytest.fixture(scope="module")
def room_frame(data_dir) -> np.ndarray:
    """The organized 640 x 480 room frame, read once for the tests that cut views of it."""
    return svs.load_organized(data_dir / "five_people.pcd")


@pytest.mark.parametrize("seed", [2, 4])
def test_a_room_frame_refines_only_its_best_hypothesis(data_dir, room_frame, seed):
    """Half of the 640 x 480 room frame (five_people.pcd, 1.8-9.8 m deep), moved, onto
    the whole frame with the defaults: the hypotheses after the first fit 0.36-0.61 of
    the refined pose (seeds 0-4, measured), under the 0.65 below which they are not
    refined, and the pose is the one three refinements give. Measured: 0.04 / 0.08
    degree, 3 / 4 mm."""
    scene = svs.load_cloud(data_dir / "five_people.pcd")  # the frame's finite points
    pair = data.make_view_pair(room_frame, seed=seed)
    result = svs.align(pair.current, scene)
    T_true = np.linalg.inv(pair.T_current_reference)
    rotation_error, translation_error = errors(result, T_true[:3, :3], T_true[:3, 3])
    assert result.refinements_run == 1
    assert rotation_error < 0.5 and translation_error < 15.0  # degrees, mm
    assert result.score > 0.8


def test_a_sparse_scan_keeps_to_the_coarse_icp_stage():
    """bun0.pcd has about one point per 8 mm voxel: within 0.4 voxel the nearest points
    are mostly too far to pair, and the ICP's fine stage, run on it, left the bunny scan
    at a median 3.9 degrees / 2.3 mm (0.26 degree / 0.93 mm without it, over 140 cases).
    The first 6 cases at 60 degrees, measured: median 0.2-0.3 degree."""
    cases = _benchmark_cases()
    errors = []
    for spec in cases.case_specs(["bunny_scan"], [60.0], 6):
        case = cases.make_case(spec)
        result = svs.align(case.model_cloud(), case.scene_cloud())
        rotation, translation = cases.pose_error(case, np.asarray(result.T_scene_model))
        errors.append((rotation, 1000 * translation))
    median = np.median(errors, axis=0)
    assert median[0] < 1.0 and median[1] < 2.0, median  # degrees, mm


def test_view_fitness_tells_the_pose_from_its_flip():
    """With the sensor's origin given, fitness checks a pose against what the single view
    saw: at the true pose the scan confirms the model's visible side; turned 180 degrees
    the model stands where the sensor saw through it. The first 10 single-view cases at
    90 degrees (all objects in turn), measured: truth 0.79-0.94, flip 0.00-0.63, at least
    0.19 below the truth."""
    cases = _benchmark_cases()
    for spec in cases.case_specs(["partial"], [90.0], 10):
        case = cases.make_case(spec)
        center = case.T_true[:3, :3] @ case.model_center + case.T_true[:3, 3]
        flip = np.eye(4)
        flip[:3, :3] = rotation([1.0, 0.0, 0.0], 180.0)
        flip[:3, 3] = center - flip[:3, :3] @ center
        fitness = []
        for T in (case.T_true, flip @ case.T_true):
            result = svs.align(
                case.model_cloud(), case.scene_cloud(), global_search=False, initial_guess=T,
                max_iterations=1, sensor_origin=case.viewpoint, scene_view="single_view",
                downsample=False,
                voxel_size=0.008,
            )  # fmt: skip
            fitness.append(result.fitness)
        assert fitness[0] > 0.75, spec.case_id
        assert fitness[1] < fitness[0] - 0.15, (spec.case_id, fitness)


def test_single_view_search_tells_near_symmetric_objects_from_their_flips():
    """A single view without a table is searched as one part: its hypotheses are placed
    from the model's side facing the sensor, and each refined pose is tightened by the
    ICP before the view's fitness compares them. The first 10 single-view cases at 60
    and 150 degrees (not chosen), measured: 20 of 20 within 5 degrees and 10 mm; 17 of
    20 before (the duck and blob000 ended turned half a turn), 19 of 20 without the
    ICP."""
    cases = _benchmark_cases()
    successes = 0
    for spec in cases.case_specs(["partial"], [60.0, 150.0], 10):
        case = cases.make_case(spec)
        result = svs.align(
            case.model_cloud(),
            case.scene_cloud(),
            sensor_origin=case.viewpoint,
            scene_view="single_view",
        )
        rotation_deg, translation_m = cases.pose_error(case, np.asarray(result.T_scene_model))
        successes += rotation_deg < 5.0 and translation_m < 0.010
    assert successes >= 18


def test_part_search_finds_the_target_in_clutter():
    """In clutter the EGI of the whole scene mixes every object's normals and its best
    rotations are mostly other objects' (36% success before the search per part, in
    docs/experiments.md). Searched per connected part above the table, the target is
    found: the first 8 clutter cases at 60 and 150 degrees (not chosen), measured 15 of
    16 within 5 degrees and 10 mm (13 with half as many hypotheses per part, each placed
    twice at the alignment's voxel, and no ICP before the ranking)."""
    cases = _benchmark_cases()
    successes = 0
    for spec in cases.case_specs(["clutter"], [60.0, 150.0], 8):
        case = cases.make_case(spec)
        result = svs.align(
            case.model_cloud(),
            case.scene_cloud(),
            sensor_origin=case.viewpoint,
            scene_view="single_view",
        )
        rotation_deg, translation_m = cases.pose_error(case, np.asarray(result.T_scene_model))
        successes += rotation_deg < 5.0 and translation_m < 0.010
    assert successes >= 13


def _assert_clutter_aligned(cells: list[tuple[str, float, int]]) -> None:
    """Each (object, angle, index) clutter case of the benchmark, in its camera's frame,
    aligned with the defaults within 5 degrees and 10 mm of the truth."""
    cases = _benchmark_cases()
    for name, angle, index in cells:
        spec = cases.CaseSpec("clutter", name, angle, index)
        case = cases.in_camera_frame(cases.make_case(spec))
        result = svs.align(case.model_cloud(), case.scene_cloud(), threads=1)
        rotation_deg, translation_m = cases.pose_error(case, np.asarray(result.T_scene_model))
        assert rotation_deg < 5.0 and translation_m < 0.010, spec


def test_each_part_gets_distinct_rotations():
    """Neighbouring maxima of a part's SO(3) search often climb to one peak of the EGI
    correlation; placing each spent the part's share of hypotheses on one rotation. Now a
    rotation within 10 degrees of an earlier one of the part is not placed and the search
    offers three times as many maxima. The two tuning clutter scenes of the benchmark's
    cases that this turned into successes (measured: the duck turned 90 degrees, off by
    135 degrees before; the bunny turned 150 degrees, 160 degrees and 178 mm off before),
    in their camera's frame with the defaults, within 5 degrees and 10 mm."""
    _assert_clutter_aligned([("duck", 90.0, 10), ("bunny", 150.0, 2)])


def test_clutter_rotations_are_screened_by_fitness():
    """A bunny or a duck seen from one side among other objects correlates weakly with its
    model's EGI: its true rotation was not among its part's 24 best-correlated maxima.
    Each part's 96 best maxima are now placed coarsely and scored on a sparse model, and
    the fittest 24 go on. Two tuning clutter scenes past the benchmark's cases (indices
    28 and 38, turned 120 degrees) that this turned into successes (measured before: the
    duck 178 degrees and 43 mm off, the bunny 177 degrees and 143 mm off, both on another
    object), in their camera's frame with the defaults, within 5 degrees and 10 mm."""
    _assert_clutter_aligned([("duck", 120.0, 28), ("bunny", 120.0, 38)])


def test_more_hypotheses_are_tried_as_alternatives():
    """The alternatives try the global search's 16 best hypotheses as they are (8 before):
    in clutter the right pose can rank past the 8th by fitness, and the reselection returns
    it once it is an alternative. The three tuning clutter scenes past the benchmark's cases
    that this turned into successes (blob 004 at 60 degrees, the jenga box and blob 000 at
    180), in their camera's frame with the defaults, within 5 degrees and 10 mm."""
    _assert_clutter_aligned([("blob004", 60.0, 34), ("jenga", 180.0, 31), ("blob000", 180.0, 33)])


def test_a_plate_lying_on_the_table_is_not_taken_for_it():
    """The support plane's band (points within it are the table's) reached 1.5 voxels
    above the table: a plate 9 mm thick lying on it (cases.THIN_OBJECTS, cut from the
    jenga mesh) had its top face taken for the table and was never searched. The band now
    stays under 0.4 of the model's thickness. Two cluttered tables measured off by 107
    degrees / 167 mm and 102 degrees / 164 mm before (benchmarks/thin_objects.py, 15 of 42
    right before, 42 after), now within 5 degrees and 10 mm up to the plate's half turns."""
    _assert_clutter_aligned([("plate", 60.0, 1), ("plate", 10.0, 5)])


def test_icp_refinement_tightens_the_spectral_result():
    """The final point-to-plane ICP starts where the spectral search ended (about 0.3
    degree / 0.3 mm off on full models: the 8 mm grid's and the EGI's floor) and ends
    near the sampling's own limit; the same successes. The first 9 full-model cases at 60
    degrees, measured: median 0.31 deg / 0.29 mm without, 0.22 deg / 0.13 mm with (over
    the 140 cases of docs/experiments.md: 0.29 / 0.31 and 0.17 / 0.10)."""
    cases = _benchmark_cases()
    errors = {False: [], True: []}
    for spec in cases.case_specs(["full"], [60.0], 9):
        case = cases.make_case(spec)
        for icp in (False, True):
            result = svs.align(case.model_cloud(), case.scene_cloud(), icp_refinement=icp)
            rotation_deg, translation_m = cases.pose_error(case, np.asarray(result.T_scene_model))
            assert rotation_deg < 5.0 and translation_m < 0.010, (spec.case_id, icp)
            assert (result.icp_iterations > 0) == icp
            errors[icp].append((rotation_deg, 1000 * translation_m))
    without, with_icp = np.median(errors[False], axis=0), np.median(errors[True], axis=0)
    assert with_icp[0] < 0.25 and with_icp[1] < 0.2, with_icp  # degrees, mm
    assert with_icp[0] < without[0] and with_icp[1] < without[1]


def test_the_viewpoint_aliases_removed_in_0_3_are_refused_by_name():
    """align(viewpoint=...) and scene_viewpoint (0.2's aliases of sensor_origin) are gone:
    a TypeError names the keyword and the setting to use."""
    rng = np.random.default_rng(7)
    model, scene, _, _ = make_case(rng, 30)
    for keyword in ("viewpoint", "scene_viewpoint"):
        with pytest.raises(TypeError, match=f"{keyword}.*sensor_origin"):
            svs.align(model, scene, **{keyword: (0.0, 0.0, 1.5)})
    with pytest.raises(AttributeError):
        svs.AlignParams().scene_viewpoint = (0.0, 0.0, 1.5)


def test_camera_frame_views_are_single_views_and_full_models_are_not():
    """With the defaults, a scan in its camera's frame is checked as a single view and a
    full model's copy is not: the first 9 cases of each family at 60 degrees."""
    cases = _benchmark_cases()
    for family, expected in (("partial", True), ("clutter", True), ("full", False)):
        for spec in cases.case_specs([family], [60.0], 9):
            case = cases.in_camera_frame(cases.make_case(spec))
            result = svs.align(case.model_cloud(), case.scene_cloud(), hypotheses=4, refinements=1)
            assert result.single_view is expected, spec.case_id


def test_a_correct_initial_guess_is_never_made_worse():
    """A guess at the truth, with a neighbourhood of 10 degrees and 10 mm, ends within 2
    degrees and 2 mm of the truth (the EGI's accuracy floor with noisy normals is 1-1.5
    degrees) on every one of 18 single-view and clutter cases (the guess's own error is 0)."""
    cases = _benchmark_cases()
    for spec in cases.case_specs(["partial", "clutter"], [90.0], 9):
        case = cases.in_camera_frame(cases.make_case(spec))
        result = svs.align(
            case.model_cloud(), case.scene_cloud(), initial_guess=case.T_true,
            guess_angle_deg=10.0, guess_distance=0.01,
        )  # fmt: skip
        rotation_deg, translation_m = cases.pose_error(case, np.asarray(result.T_scene_model))
        assert rotation_deg < 2.0 and translation_m < 0.002, (spec.case_id, rotation_deg)
