"""The ``spectral-vs`` command line, run in-process on clouds written to files."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from conftest import box_and_sphere

import spectral_vs as svs
from spectral_vs.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def rotation(axis, angle_deg: float) -> np.ndarray:
    """Rodrigues' formula, independent of the CLI's own helper."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = np.radians(angle_deg)
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


@pytest.fixture(scope="module")
def case(tmp_path_factory) -> dict:
    """A box with a sphere beside it as MODEL (.pcd) and, resampled, rotated by 35 degrees,
    shifted and noisy, as SCENE (.ply); the true T_scene_model as text and as .npy."""
    folder = tmp_path_factory.mktemp("cli")
    rng = np.random.default_rng(31)
    points, normals = box_and_sphere(rng)
    scene_points, scene_normals = box_and_sphere(rng)  # an independent sample
    T = np.eye(4)
    T[:3, :3] = rotation([0.3, -0.5, 1.0], 35.0)
    T[:3, 3] = [0.05, -0.03, 0.02]
    scene_points = scene_points @ T[:3, :3].T + T[:3, 3] + rng.normal(0, 0.001, scene_points.shape)
    svs.save_cloud(folder / "model.pcd", svs.PointCloud(points, normals))
    svs.save_cloud(folder / "scene.ply", svs.PointCloud(scene_points, scene_normals @ T[:3, :3].T))
    np.savetxt(folder / "truth.txt", T)
    np.save(folder / "truth.npy", T)
    return {
        "model": str(folder / "model.pcd"),
        "scene": str(folder / "scene.ply"),
        "truth_txt": str(folder / "truth.txt"),
        "truth_npy": str(folder / "truth.npy"),
        "T": T,
        "points": points,
    }


def errors(T_estimate: np.ndarray, T_true: np.ndarray, center: np.ndarray) -> tuple[float, float]:
    """Rotation error (degrees) and error at ``center`` (mm), computed here, not by the CLI."""
    cos = (np.trace(T_estimate[:3, :3].T @ T_true[:3, :3]) - 1) / 2
    offset = (T_estimate[:3, :3] - T_true[:3, :3]) @ center + T_estimate[:3, 3] - T_true[:3, 3]
    return float(np.degrees(np.arccos(np.clip(cos, -1, 1)))), 1000 * float(np.linalg.norm(offset))


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_align_json_recovers_the_pose(case, capsys):
    code, out, err = run(
        capsys, "align", case["model"], case["scene"], "--ground-truth", case["truth_npy"], "--json"
    )
    report = json.loads(out)
    assert code == 0
    assert err == ""  # --json prints no progress
    for key in (
        "T_scene_model",
        "converged",
        "iterations",
        "fitness",
        "correlation",
        "time_s",
        "rotation_error_deg",
        "translation_error_mm",
        "passed",
    ):
        assert key in report
    assert report["converged"] is True or report["stop_reason"] in ("kept_start", "reselected")
    assert report["passed"] is True
    # iterations describe the run of the returned pose: none when it did not end one.
    assert report["iterations"] >= 1 or report["stop_reason"] in ("kept_start", "reselected")
    assert report["fitness"] > 0.9
    T = np.array(report["T_scene_model"])
    rotation_error, translation_error = errors(T, case["T"], case["points"].mean(axis=0))
    assert rotation_error < 2.0
    assert translation_error < 3.0
    # The CLI's own error report agrees with the errors computed here.
    assert report["rotation_error_deg"] == pytest.approx(rotation_error, abs=1e-6)
    assert report["translation_error_mm"] == pytest.approx(translation_error, abs=0.2)


def test_align_text_output_and_progress(case, capsys):
    code, out, err = run(
        capsys, "align", case["model"], case["scene"], "--ground-truth", case["truth_txt"]
    )
    assert code == 0
    assert "T_scene_model" in out
    match = re.search(r"rotation ([\d.]+) deg, translation ([\d.]+) mm", out)
    assert match, out
    assert float(match.group(1)) < 2.0
    assert float(match.group(2)) < 3.0
    # Progress: one line per stage on stderr, each with its elapsed time.
    lines = err.strip().splitlines()
    assert lines[0].startswith("loading model model.pcd ... 6000 points")
    # The voxel is derived from the clouds, as align() derives it, and said so.
    model, scene = svs.load_cloud(case["model"]), svs.load_cloud(case["scene"])
    voxel_mm = 1000 * svs.alignment_voxel_size(model, scene)
    aligning = [line for line in lines if line.startswith("aligning (")]
    assert len(aligning) == 1
    assert aligning[0].startswith(f"aligning ({voxel_mm:.3g} mm voxels (derived), global search")
    assert all(re.search(r"\d+ (ms|s)$", line) for line in lines), err
    # The verdict tells whether to take the pose, with the threshold it is read against.
    match = re.search(r"^reliable: confidence ([\d.]+) \(reliable at ([\d.]+) or more", out, re.M)
    assert match, out
    assert float(match.group(2)) == pytest.approx(svs.RELIABLE_CONFIDENCE)
    assert float(match.group(1)) >= svs.RELIABLE_CONFIDENCE
    assert "converged" not in out


def test_align_json_reports_the_confidence_inliers_and_the_voxel_used(case, capsys):
    code, out, _ = run(
        capsys, "align", case["model"], case["scene"], "--voxel-size", "0.008", "--json"
    )
    report = json.loads(out)
    assert code == 0
    assert report["voxel_size_m"] == pytest.approx(0.008)
    assert report["reliable"] is True and report["status"] == "reliable"
    assert report["confidence"] >= svs.RELIABLE_CONFIDENCE
    # The covariance: 6 x 6, symmetric, its deviations under the 8 mm voxel's half.
    covariance = np.array(report["covariance"])
    assert covariance.shape == (6, 6) and np.allclose(covariance, covariance.T)
    assert max(report["rotation_std_deg"]) < 1.0 and max(report["translation_std_mm"]) < 4.0
    # Inliers: model points within the inlier distance (one voxel) of the scene; the scene
    # is an independent sample with 1 mm noise, so their RMSE is a few mm, under a voxel.
    assert report["inlier_distance_mm"] == pytest.approx(8.0, abs=1e-6)
    assert report["inliers"] > 100
    assert 0.5 < report["inlier_rmse_mm"] < 8.0
    assert isinstance(report["ambiguous"], bool) and isinstance(report["alternatives"], list)
    for alternative in report["alternatives"]:
        assert np.array(alternative["T_scene_model"]).shape == (4, 4)


def test_the_viewpoint_option_removed_in_0_3_is_refused(case, capsys):
    # --viewpoint was 0.2's alias of --sensor-origin: bad input now, exit code 2.
    arguments = ("align", case["model"], case["scene"], "--voxel-size", "0.008", "--json")
    with pytest.raises(SystemExit) as exit_info:
        run(capsys, *arguments, "--viewpoint", "0", "0", "1")
    assert exit_info.value.code == 2
    assert "--viewpoint" in capsys.readouterr().err


def test_align_quiet_prints_no_progress(case, capsys):
    code, out, err = run(capsys, "align", case["model"], case["scene"], "--quiet")
    assert code == 0
    assert "search ended normally" in out and "reliable: confidence" in out
    assert err == ""


def test_align_writes_figures_and_the_aligned_model(case, capsys, tmp_path):
    plot, render, aligned = tmp_path / "c.png", tmp_path / "figs" / "a.png", tmp_path / "m.ply"
    code, _, _ = run(
        capsys,
        "align",
        case["model"],
        case["scene"],
        "--quiet",
        "--ground-truth",
        case["truth_txt"],
        "--plot",
        str(plot),
        "--render",
        str(render),
        "--save-aligned",
        str(aligned),
    )
    assert code == 0
    for png in (plot, render):
        data = png.read_bytes()
        assert data[:8] == PNG_MAGIC
        assert len(data) > 10_000
    # The saved cloud is MODEL moved onto the scene: within 3 mm of the truth, point by point.
    moved = svs.load_cloud(aligned)
    expected = case["points"] @ case["T"][:3, :3].T + case["T"][:3, 3]
    assert len(moved) == len(expected)
    distances = np.linalg.norm(np.asarray(moved.points) - expected, axis=1)
    assert np.max(distances) < 0.003


def test_paper_mode_from_an_initial_guess(case, capsys, tmp_path):
    """Local refinement (no global search) from a guess 8 degrees and 15 mm off the truth."""
    guess = case["T"].copy()
    guess[:3, :3] = rotation([1.0, 0.2, -0.4], 8.0) @ guess[:3, :3]
    guess[:3, 3] += [0.015, 0.0, 0.0]
    np.savetxt(tmp_path / "guess.txt", guess)
    code, out, _ = run(
        capsys,
        "align",
        case["model"],
        case["scene"],
        "--paper",
        "--quiet",
        "--initial-guess",
        str(tmp_path / "guess.txt"),
        "--ground-truth",
        case["truth_txt"],
        "--json",
    )
    report = json.loads(out)
    assert code == 0
    assert report["rotation_error_deg"] < 2.0
    assert report["translation_error_mm"] < 3.0


def test_wrong_ground_truth_exits_1(case, capsys, tmp_path):
    wrong = case["T"].copy()
    wrong[:3, :3] = rotation([0.0, 0.0, 1.0], 20.0) @ wrong[:3, :3]
    np.savetxt(tmp_path / "wrong.txt", wrong)
    code, out, _ = run(
        capsys,
        "align",
        case["model"],
        case["scene"],
        "--quiet",
        "--json",
        "--ground-truth",
        str(tmp_path / "wrong.txt"),
    )
    report = json.loads(out)
    assert code == 1
    assert report["passed"] is False
    assert report["rotation_error_deg"] == pytest.approx(20.0, abs=2.0)


def test_an_unfinished_search_exits_1_with_the_reason(case, capsys):
    code, out, _ = run(
        capsys, "align", case["model"], case["scene"], "--quiet", "--paper", "--max-iterations", "1"
    )
    assert code == 1
    assert "search stopped (max_iterations), 1 iteration of Algorithm 1" in out
    assert "; not reliable: " in out


def test_a_wrong_object_exits_1(case, data_dir, capsys):
    """The Stanford bunny's scan aligned into the box and ball: no pose is right, and the
    command must not exit 0 (the verdict, not the search's ending, decides)."""
    code, out, _ = run(
        capsys, "align", str(data_dir / "bun0.pcd"), case["scene"], "--quiet", "--json"
    )
    report = json.loads(out)
    assert code == 1
    assert report["reliable"] is False and report["passed"] is False
    assert report["status"] != "reliable"


def test_a_floating_pose_exits_1_unless_the_object_may_float(capsys, tmp_path):
    """The duck held 80 mm above the table: right, but it neither rests on the table nor
    stands on anything, so `floating` (exit 1, the reason printed) unless --may-float."""
    pytest.importorskip("pybullet")  # the meshes come with pybullet_data
    import cases

    model, scan, T, origin = cases.held_above_table("duck", 0.08)
    svs.save_cloud(tmp_path / "duck.pcd", model)
    svs.save_cloud(tmp_path / "scan.pcd", scan)
    argv = ["align", str(tmp_path / "duck.pcd"), str(tmp_path / "scan.pcd"), "--quiet"]
    argv += ["--sensor-origin", *map(str, origin), "--scene-view", "single_view"]
    code, out, _ = run(capsys, *argv)
    assert code == 1
    assert "floating" in out and "neither rests on the table" in out
    code, out, _ = run(capsys, *argv, "--may-float", "--json")
    report = json.loads(out)
    assert code == 0 and report["status"] == "reliable" and report["rests"] is False
    rotation_deg, error_mm = errors(np.array(report["T_scene_model"]), T, model.points.mean(axis=0))
    assert rotation_deg < 1.0 and error_mm < 1.0


def test_missing_file_exits_2_and_names_it(case, capsys, tmp_path):
    missing = tmp_path / "nowhere.pcd"
    code, out, err = run(capsys, "align", case["model"], str(missing))
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith("error: SCENE:")
    assert str(missing) in err
    code, _, err = run(capsys, "align", str(missing), case["scene"], "--quiet")
    assert code == 2
    assert err.startswith("error: MODEL:") and str(missing) in err


@pytest.mark.parametrize("name", ["notes.pcd", "notes.ply", "notes.txt"])
def test_not_a_point_cloud_exits_2(case, capsys, tmp_path, name):
    path = tmp_path / name
    path.write_text("these are not points\n")
    code, _, err = run(capsys, "align", str(path), case["scene"], "--quiet")
    assert code == 2
    assert err.startswith("error: MODEL:")
    assert str(path) in err
    assert err.count("\n") == 1


def test_bad_transform_file_exits_2(case, capsys, tmp_path):
    (tmp_path / "t.txt").write_text("1 0 0\n0 1 0\n0 0 1\n")
    code, _, err = run(
        capsys,
        "align",
        case["model"],
        case["scene"],
        "--quiet",
        "--ground-truth",
        str(tmp_path / "t.txt"),
    )
    assert code == 2
    assert err.startswith("error: --ground-truth:") and "4x4" in err
    np.savetxt(tmp_path / "scaled.txt", np.diag([2.0, 1.0, 1.0, 1.0]))
    code, _, err = run(
        capsys,
        "align",
        case["model"],
        case["scene"],
        "--quiet",
        "--initial-guess",
        str(tmp_path / "scaled.txt"),
    )
    assert code == 2
    assert err.startswith("error: --initial-guess:") and "not a rigid transform" in err


def test_bad_output_extension_exits_2_before_aligning(case, capsys, tmp_path):
    code, _, err = run(
        capsys, "align", case["model"], case["scene"], "--save-aligned", str(tmp_path / "out.xyz")
    )
    assert code == 2
    assert err.startswith("error: --save-aligned:")
    assert "loading" not in err


def test_bad_option_value_exits_2(case, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["align", case["model"], case["scene"], "--voxel-size", "-1"])
    assert exit_info.value.code == 2
    assert "argument --voxel-size: must be a finite number > 0" in capsys.readouterr().err


def test_help_explains_the_transform(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["align", "--help"])
    out = capsys.readouterr().out
    assert exit_info.value.code == 0
    assert "T_scene_model" in out
    assert "metres" in out
    assert "spectral-vs align" in out  # the example in the epilog


def demo_errors(out: str) -> tuple[float, float]:
    match = re.search(r"error: rotation ([\d.]+) deg, translation ([\d.]+) mm", out)
    assert match, out
    return float(match.group(1)), float(match.group(2))


def test_demo_on_the_milk_carton_scan(data_dir, capsys, tmp_path):
    code, out, _ = run(
        capsys, "demo", "--data", str(data_dir), "--output", str(tmp_path), "--quiet", "--check"
    )
    assert "0 shared" in out
    rotation_error, translation_error = demo_errors(out)
    assert rotation_error <= 5.0  # degrees
    assert translation_error <= 10.0  # mm
    # The carton is cut from the scan: its back was never seen, and the pose turned half a
    # turn about its upright axis fits the scan about as well. The verdict says so, names
    # the other pose, and --check does not pass an answer a robot could not act on.
    assert re.search(r"^ambiguous: confidence [\d.]+", out, re.M), out
    assert re.search(r"1 other pose fits as well; the best 1[78]\d deg", out), out
    assert code == 1, out
    for name in ("convergence.png", "alignment.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == PNG_MAGIC
        assert len(data) > 10_000


def test_demo_without_scans_uses_a_generated_scene(capsys, tmp_path):
    code, out, _ = run(
        capsys, "demo", "--data", str(tmp_path / "no-scans"), "--output", str(tmp_path), "--quiet"
    )
    assert "using a generated scene" in out
    assert code == 0  # the demo reports; only --check turns a miss into status 1
    demo_errors(out)
    for name in ("convergence.png", "alignment.png"):
        assert (tmp_path / name).read_bytes()[:8] == PNG_MAGIC


def test_translation_demo(data_dir, capsys):
    code, out, _ = run(capsys, "demo", "--translation-only", "--data", str(data_dir))
    assert code == 0
    match = re.search(r"error: ([\d.]+) mm", out)
    assert match and float(match.group(1)) < 2.0


@pytest.fixture(scope="module")
def view_pair(data_dir, tmp_path_factory) -> dict:
    """Two 320 x 240 views of the table scan (disjoint pixels, the current moved by a known
    transform) as REFERENCE (.pcd) and CURRENT (.ply), and the true T_current_reference."""
    from spectral_vs import data

    folder = tmp_path_factory.mktemp("views")
    scan = svs.load_organized(data_dir / "milk_cartoon_all_small_clorox.pcd")
    pair = data.view_pairs(scan, 1, downscale=2, seed=3)[0]
    svs.save_cloud(folder / "reference.pcd", pair.reference)
    svs.save_cloud(folder / "current.ply", pair.current)
    np.savetxt(folder / "truth.txt", pair.T_current_reference)
    return {
        "reference": str(folder / "reference.pcd"),
        "current": str(folder / "current.ply"),
        "truth": str(folder / "truth.txt"),
        "T": np.asarray(pair.T_current_reference),
        "origin": [str(x) for x in pair.current_viewpoint],
        "reference_points": np.asarray(pair.reference.points),
    }


def test_align_views_json_recovers_the_pose(view_pair, capsys):
    code, out, err = run(
        capsys,
        "align-views",
        view_pair["reference"],
        view_pair["current"],
        "--sensor-origin",
        *view_pair["origin"],
        "--ground-truth",
        view_pair["truth"],
        "--json",
    )
    report = json.loads(out)
    assert code == 0 and err == ""
    assert report["status"] == "reliable" and report["reliable"] is True
    assert report["passed"] is True
    T = np.array(report["T_current_reference"])
    center = view_pair["reference_points"].mean(axis=0)
    rotation_error, translation_error = errors(T, view_pair["T"], center)
    assert rotation_error < 1.0
    assert translation_error < 5.0
    assert report["rotation_error_deg"] == pytest.approx(rotation_error, abs=1e-6)
    assert report["translation_error_mm"] == pytest.approx(translation_error, abs=0.2)
    # A right pose of two views that share 40-80% is well supported (docs/views.md).
    assert report["support_score"] > 0.1
    assert report["support_score"] == pytest.approx(report["fitness"] * report["overlap"], rel=1e-9)
    assert report["confidence"] >= svs.RELIABLE_CONFIDENCE
    assert report["hypotheses_checked"] == svs.ViewAlignParams().hypotheses
    assert 0 < report["voxel_size_m"] < report["search_voxel_size_m"]


def test_align_views_text_output_progress_and_the_aligned_reference(view_pair, capsys, tmp_path):
    aligned = tmp_path / "out" / "reference_in_current.ply"
    code, out, err = run(
        capsys,
        "align-views",
        view_pair["reference"],
        view_pair["current"],
        "--sensor-origin",
        *view_pair["origin"],
        "--save-aligned",
        str(aligned),
    )
    assert code == 0
    assert "T_current_reference" in out
    assert re.search(r"^reliable: confidence [\d.]+", out, re.M), out
    assert re.search(r"support score [\d.]+ \(fitness [\d.]+, overlap [\d.]+\)", out)
    lines = err.strip().splitlines()
    assert lines[0].startswith("loading reference reference.pcd ...")
    assert all(re.search(r"\d+ (ms|s)$", line) for line in lines), err
    # The written cloud is the reference moved onto the current view: within a few mm of
    # where the true transform puts it.
    moved = np.asarray(svs.load_cloud(aligned).points)
    reference = view_pair["reference_points"]
    expected = reference @ view_pair["T"][:3, :3].T + view_pair["T"][:3, 3]
    assert moved.shape == reference.shape
    assert np.max(np.linalg.norm(moved - expected, axis=1)) < 0.01  # m


def test_align_views_that_share_nothing_exit_1(view_pair, capsys, tmp_path):
    """A plane seen edge-on from behind (every normal facing away from the sensor): no
    pose is supported, the command says so and exits with 1."""
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-0.5, 0.5, (3000, 2)), np.full(3000, 1.0)])
    away = tmp_path / "away.pcd"
    svs.save_cloud(away, svs.PointCloud(points, np.tile([0.0, 0.0, 1.0], (3000, 1))))
    code, out, _ = run(capsys, "align-views", view_pair["reference"], str(away), "--json")
    report = json.loads(out)
    assert code == 1
    assert report["status"] == "no_support" and report["passed"] is False
    assert report["confirmed"] == 0


def test_align_views_bad_input_exits_2_and_names_the_argument(view_pair, capsys, tmp_path):
    missing = tmp_path / "nowhere.pcd"
    code, out, err = run(capsys, "align-views", view_pair["reference"], str(missing))
    assert code == 2 and out == ""
    assert err.startswith("error: CURRENT: no such file:") and str(missing) in err
    notes = tmp_path / "notes.pcd"
    notes.write_text("these are not points\n")
    code, _, err = run(capsys, "align-views", str(notes), view_pair["current"], "--quiet")
    assert code == 2 and err.startswith("error: REFERENCE:")
    (tmp_path / "t.txt").write_text("1 0 0\n0 1 0\n0 0 1\n")
    code, _, err = run(
        capsys,
        "align-views",
        view_pair["reference"],
        view_pair["current"],
        "--prior",
        str(tmp_path / "t.txt"),
    )
    assert code == 2 and err.startswith("error: --prior:") and "4x4" in err
    code, _, err = run(
        capsys,
        "align-views",
        view_pair["reference"],
        view_pair["current"],
        "--save-aligned",
        str(tmp_path / "out.xyz"),
    )
    assert code == 2 and err.startswith("error: --save-aligned:") and "loading" not in err
