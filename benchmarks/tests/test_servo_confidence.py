"""The arithmetic of benchmarks/servo_confidence.py on synthetic step records: which steps
count (a score, no latency scenario, the chosen seeds), what is right (10 mm and 5 degrees
at once), and that each kind of step reads its own map."""

from __future__ import annotations

import json

import numpy as np
import pytest
import servo_confidence as sc


def write_run(folder, name, scenario, seed, robot="iiwa", **steps):
    folder.mkdir(parents=True, exist_ok=True)
    run = {"index": 0, **steps}
    data = {"robot": robot, "scenario": scenario, "seed": seed, "commit": "abc1234"}
    (folder / f"{name}.json").write_text(json.dumps({**data, "records": [run]}))


def test_only_scored_steps_of_timely_frames_and_chosen_seeds_count(tmp_path):
    steps = {
        "score": [0.99, None, 0.95, 0.5],
        "confidence": [0.99, None, 0.8, 0.3],
        "moved": [True, False, True, True],
        "carried": [False, False, False, True],
        "mm": [1.0, 0.0, 12.0, 3.0],
        "deg": [0.5, 0.0, 1.0, 6.0],
    }
    write_run(tmp_path, "a", "clean", 201, **steps)
    write_run(tmp_path, "b", "latency_1", 201, **steps)  # frames older than their poses
    write_run(tmp_path, "c", "clean", 0, **steps)  # another seed
    read = sc.read_steps(tmp_path, seeds={201})
    assert read["score"].tolist() == [0.99, 0.95, 0.5]  # the step without a score is out
    # 10 mm and 5 degrees both: 12 mm is wrong, so is 6 degrees.
    assert read["right"].tolist() == [True, False, False]
    assert read["carried"].tolist() == [False, False, True]
    assert read["commits"].tolist() == ["abc1234"]
    assert len(sc.read_steps(tmp_path)["score"]) == 6  # both seeds, still no latency


def test_each_kind_of_step_reads_its_own_map():
    steps = {"score": np.array([0.2, 0.2, 0.9]), "carried": np.array([False, True, True])}
    maps = {
        "servo": np.array([[0.0, 0.1], [1.0, 0.9]]),
        "servo_carried": np.array([[0.0, 0.95], [1.0, 0.99]]),
    }
    confidence = sc.with_maps(steps, maps)
    assert confidence == pytest.approx([0.1 + 0.2 * 0.8, 0.95 + 0.2 * 0.04, 0.95 + 0.9 * 0.04])


def test_the_maps_are_fitted_per_kind_and_the_figures_count_the_steps():
    rng = np.random.default_rng(3)
    score = rng.random(400)
    carried = rng.random(400) < 0.3
    # Registered steps are right when they score high; carried ones nearly always.
    right = np.where(carried, rng.random(400) < 0.97, score > 0.5)
    steps = {"score": score, "carried": carried, "right": right, "moved": np.ones(400, bool)}
    maps = sc.fit_maps(steps)
    assert sc.calibrated(np.array([0.9]), maps["servo"])[0] > 0.9
    assert sc.calibrated(np.array([0.1]), maps["servo"])[0] < 0.1
    assert sc.calibrated(np.array([0.1]), maps["servo_carried"])[0] > 0.9
    m = sc.metrics(sc.with_maps(steps, maps), right, steps["moved"])
    assert m["steps"] == 400 and m["right"] == int(right.sum())
    assert m["moved"] == 400 and m["wrong_moved"] == int((~right).sum())
