"""The room-frame benchmark's table (benchmarks/room_frame_benchmark.py): one row per set of
frames and variant, its success against two voxels of that set's defaults, and how many
frames took under 1 s."""

from __future__ import annotations

import room_frame_benchmark as bench


def record(frames: str, seed: int, cpu: float, rotation: float, translation: float) -> dict:
    return {
        "set": frames,
        "seed": seed,
        "variant": "defaults",
        "cpu_s": cpu,
        "voxel_size_m": 0.15,
        "single_view": True,
        "rotation_error_deg": rotation,
        "translation_error_m": translation,
    }


def test_a_row_per_set_with_its_success_and_frames_under_a_second():
    records = [
        record("room, seeds 0-1", 0, 0.3, 0.1, 0.01),
        record("room, seeds 0-1", 1, 1.2, 0.1, 0.31),  # over 2 voxels (0.30 m) off: wrong
        {"set": "room, seeds 0-1", "seed": 0, "variant": "voxel 8 mm", "error": "over the limit"},
        record("table scan, seeds 0-0", 0, 0.5, 6.0, 0.0),  # over 5 degrees off: wrong
    ]
    rows = bench.table(records).splitlines()[2:]
    assert len(rows) == 3
    room, refused, table = (row.split(" | ") for row in rows)
    assert room[0] == "| room, seeds 0-1" and room[1] == "defaults"
    assert room[5] == "1 of 2"  # success
    assert room[8:11] == ["0.75 s", "1.20 s", "1 of 2 |"]  # median, max CPU, under 1 s
    assert refused[1] == "voxel 8 mm" and refused[5] == "refused: over the limit"
    assert table[0] == "| table scan, seeds 0-0" and table[5] == "0 of 1"


def test_the_sets_follow_the_seeds_asked_for():
    names = [(name, scan, list(seeds)) for name, scan, seeds, _ in bench.sets(2, 3, 1)]
    assert names == [
        ("room, seeds 0-1", "room", [0, 1]),
        ("room, seeds 2-4", "room", [2, 3, 4]),
        ("table scan, seeds 0-0", "table", [0]),
    ]
