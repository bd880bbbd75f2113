"""The peer registration methods of the benchmark (benchmarks/peers.py) and its smoke run.

Needs the optional ``bench`` extra (open3d, small_gicp) and pybullet (the case meshes);
skipped without them."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before an OpenMP runtime loads
pytest.importorskip("open3d")
pytest.importorskip("pybullet")  # the meshes come with pybullet_data

import cases
import peers

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def c1_case() -> cases.Case:
    """A C-1 case: the full bunny onto a resampled, noisy copy, 10 degrees off."""
    return cases.make_case(cases.CaseSpec("full", "bunny", 10.0, 0))


def test_case_starts_ten_degrees_away(c1_case: cases.Case) -> None:
    rotation, translation = cases.pose_error(c1_case, np.eye(4))
    assert rotation == pytest.approx(10.0, abs=1e-6)
    assert translation > 0.002  # the offset is the wrapper's job too (up to 50 mm)


def test_point_to_plane_icp_recovers_ten_degrees(c1_case: cases.Case) -> None:
    result = peers.register(
        "o3d_icp",
        c1_case.model_points,
        c1_case.model_normals,
        c1_case.scene_points,
        c1_case.scene_normals,
        voxel=0.008,
        T_init=np.eye(4),
    )
    rotation, translation = cases.pose_error(c1_case, result.T_scene_model)
    assert rotation < 1.0  # degrees
    assert translation < 0.002  # metres
    assert result.seconds > 0.0
    R = result.T_scene_model[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)


def test_unknown_method_is_rejected(c1_case: cases.Case) -> None:
    with pytest.raises(ValueError, match="method must be one of"):
        peers.register(
            "icp",
            c1_case.model_points,
            c1_case.model_normals,
            c1_case.scene_points,
            c1_case.scene_normals,
        )


def test_quick_run(tmp_path: Path) -> None:
    pytest.importorskip("small_gicp")
    output = tmp_path / "peers.json"
    run = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "peers_benchmark.py"),
            "--quick",
            "--families",
            "full",
            "--output",
            str(output),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    results = json.loads(output.read_text())
    assert results["cases"] == 2  # 2 angles x 1 case
    assert {r["method"] for r in results["records"]} == set(peers.METHODS)
    assert all(r["time_s"] > 0.0 and r["rotation_error_deg"] >= 0.0 for r in results["records"])
    assert len(results["determinism"]) == len(peers.METHODS)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity here")
def test_configure_threads_pins_the_process_to_as_many_cores() -> None:
    # In a child process: the pin would stay on this one. Open3D's TBB loops are bounded
    # only by the cores the process may run on.
    code = (
        "import os, peers; peers.configure_threads(1); "
        "print(len(os.sched_getaffinity(0)), os.environ['OMP_NUM_THREADS'])"
    )
    run = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT / "benchmarks",
        timeout=60,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["1", "1"]


def _records(method: str, success: bool, case_ids: list[str]) -> list[dict]:
    return [
        {"case_id": c, "family": "full", "angle_deg": 30.0, "method": method,
         "rotation_error_deg": 1.0 if success else 90.0, "translation_error_m": 0.001,
         "success": success, "time_s": 0.1, "cpu_s": 0.1}
        for c in case_ids
    ]  # fmt: skip


def _run(records: list[dict], methods: list[str], command: str) -> dict:
    return {
        "commands": [command], "date": "2026-01-01", "commit": "abc", "core_sha256": command,
        "load_average": [1.0, 1.0], "runtime_s": 60.0, "threads": 1, "settings": {},
        "voxel_size": 0.008, "success": {}, "methods": methods,
        "cases_per_family": {"full": 2}, "determinism_records": [], "records": records,
    }  # fmt: skip


def test_replace_methods_keeps_every_other_methods_rows() -> None:
    """A rerun of ours replaces ours' rows only: the peer's rows and success stay, ours'
    success is the rerun's, and the rerun's build is recorded beside the first run's."""
    import peers_benchmark

    ids = ["full-bunny-a30-0", "full-bunny-a30-1"]
    base = _run(_records("ours", False, ids) + _records("o3d_icp", True, ids), ["ours"], "a")
    new = _run(_records("ours", True, ids), ["ours"], "b")
    merged = peers_benchmark.replace_methods(base, new)
    assert [(r["case_id"], r["method"]) for r in merged["records"]] == [
        (ids[0], "ours"), (ids[0], "o3d_icp"), (ids[1], "ours"), (ids[1], "o3d_icp")
    ]  # fmt: skip
    success = {s["method"]: s["success_rate"] for s in merged["family_summary"]}
    assert success == {"ours": 1.0, "o3d_icp": 1.0}
    assert merged["core_sha256"] == "a" and merged["replaced"][0]["core_sha256"] == "b"
    assert merged["runtime_s"] == 120.0 and merged["commands"] == ["a", "b"]
    with pytest.raises(ValueError, match="cases of full"):
        peers_benchmark.replace_methods(base, _run(_records("ours", True, ids[:1]), ["ours"], "c"))
    # A second rerun of ours supersedes the first: one provenance line, each command once.
    again = peers_benchmark.replace_methods(
        merged, _run(_records("ours", True, ids), ["ours"], "b")
    )
    assert [r["core_sha256"] for r in again["replaced"]] == ["b"]
    assert again["commands"] == ["a", "b"]
    peer = peers_benchmark.replace_methods(
        again, _run(_records("o3d_icp", True, ids), ["o3d_icp"], "d")
    )
    assert [r["core_sha256"] for r in peer["replaced"]] == ["b", "d"]
