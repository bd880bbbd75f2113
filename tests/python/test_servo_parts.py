"""The servo's frame gate on its own, without a servo around it: the holds on empty, thin
and stale frames, and the occluders it drops in front of a wall, against the geometry of
the scene; and the plane turn of the tracker against a known turn about a table."""

from __future__ import annotations

import numpy as np
import pytest

import spectral_vs as svs
from spectral_vs import PointCloud
from spectral_vs.servo import ServoParams
from spectral_vs.servo.gate import FrameGate
from spectral_vs.servo.records import _empty_record


def square(depth: float, half: float, step: float) -> np.ndarray:
    """A square of points facing the camera at ``depth`` m, ``half`` m across each way."""
    u = np.arange(-half, half + step / 2, step)
    x, y = np.meshgrid(u, u)
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, depth)])


def cloud(points: np.ndarray) -> PointCloud:
    return PointCloud(points, np.tile([0.0, 0.0, -1.0], (len(points), 1)))


WALL = square(1.0, 0.4, 0.01)  # the reference: a wall 1 m ahead, 0.8 m wide
PARAMS = ServoParams(min_points=100, occlusion_margin=0.05)


def test_the_gate_holds_on_an_empty_a_thin_and_a_stale_frame():
    gate = FrameGate(PARAMS, WALL)
    frame = cloud(WALL)
    assert gate.fault(frame, 0, None)[0] == "empty_cloud"
    hold, message = gate.fault(frame, 99, None)
    assert hold == "too_few_points"
    assert "99 points" in message and "min_points 100" in message
    assert gate.fault(frame, len(frame), 1.0) is None
    assert gate.fault(frame, len(frame), 1.0)[0] == "stale_frame"  # its stamp again
    gate.reset()
    assert gate.fault(frame, len(frame), 1.0) is None  # a new run: no last frame


@pytest.mark.parametrize(("board_half", "holds"), [(0.1, False), (0.14, True)])
def test_the_gate_drops_a_board_in_front_of_the_wall_and_measures_what_it_hides(board_half, holds):
    """A board at 0.4 m hides the wall's middle; seen through the camera it covers the
    square of half-width 2.5 board_half at 1 m: 0.39 of the wall's area for a 20 cm board
    (under occlusion_max_share 0.5: registered on the rest), 0.77 for a 28 cm one (most
    of the reference behind it: the step holds)."""
    gate = FrameGate(PARAMS, WALL)
    board = square(0.4, board_half, 0.005)
    shadow = 2.5 * board_half  # the board's half-width seen on the wall, m
    seen = WALL[np.abs(WALL[:, :2]).max(axis=1) > shadow + 1e-9]
    frame = cloud(np.vstack([seen, board]))
    record = _empty_record(0, len(frame))

    kept, occluded, hidden, message = gate.drop_occluders(frame, record, np.eye(4))

    assert record.occluded_points == len(board)  # every board point, no wall point
    np.testing.assert_array_equal(np.asarray(kept.points), seen)
    assert occluded
    expected = ((2 * shadow) / 0.8) ** 2  # the hidden share of the wall's area
    assert hidden == pytest.approx(expected, abs=0.05)
    assert record.hidden_share == hidden
    if holds:
        assert message is not None and "occlusion_max_share 0.5" in message
    else:
        assert message is None


def test_without_an_estimate_the_gate_drops_nothing():
    gate = FrameGate(PARAMS, WALL)
    frame = cloud(np.vstack([WALL, square(0.4, 0.1, 0.005)]))
    record = _empty_record(0, len(frame))
    kept, occluded, hidden, message = gate.drop_occluders(frame, record, None)
    assert kept is frame and not occluded and hidden == 0.0 and message is None
    assert record.occluded_points == 0


def table_with_blocks() -> PointCloud:
    """A table's normals (up, two thirds of the view) and the sides of three blocks turned
    15, 40 and 70 degrees about the table's normal: the rotation about it shows only in
    the blocks."""
    normals = [np.tile([0.0, 0.0, 1.0], (3000, 1))]
    for yaw in np.radians([15.0, 40.0, 70.0]):
        sides = [[np.cos(yaw + k * np.pi / 2), np.sin(yaw + k * np.pi / 2), 0.0] for k in range(4)]
        normals.append(np.repeat(sides, 125, axis=0))
    n = np.vstack(normals)
    return PointCloud(np.random.default_rng(0).uniform(-0.3, 0.3, n.shape), n)


def about_z(degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_the_plane_turn_turns_the_estimate_about_the_tables_normal():
    from spectral_vs.servo.plane_turn import _PlaneTurn

    params = ServoParams()
    reference = table_with_blocks()
    turn = _PlaneTurn.of(reference, np.zeros(3), params, svs.AlignParams())
    assert turn is not None
    assert np.degrees(np.arccos(min(1.0, turn.axis[2]))) < 0.1
    R_true = about_z(3.0)
    current = PointCloud(np.asarray(reference.points) @ R_true.T,
                         np.asarray(reference.normals) @ R_true.T)  # fmt: skip
    step = turn.turn(current, np.eye(4))
    assert np.degrees(step) == pytest.approx(3.0, abs=0.75)
    T = turn.turned(np.eye(4), step)
    np.testing.assert_allclose(T[:3, :3], about_z(np.degrees(step)), atol=1e-12)
    # A view of the table alone has nothing off the plane to turn by.
    up = np.tile([0.0, 0.0, 1.0], (500, 1))
    assert turn.turn(PointCloud(up, up), np.eye(4)) == 0.0


def test_the_plane_turn_refuses_settings_out_of_range_naming_them():
    reference = table_with_blocks()
    with pytest.raises(ValueError, match="plane_cone"):
        svs._core.PlaneTurn.of(reference, plane_cone=2.0)
    with pytest.raises(ValueError, match="stride"):
        svs._core.PlaneTurn.of(reference, stride=0)
    up = np.tile([0.0, 0.0, 1.0], (500, 1))
    assert svs._core.PlaneTurn.of(PointCloud(up, up)) is None  # no normal off the plane


def test_the_servos_plane_settings_default_to_the_cores_plane_turn():
    """The servo's ``plane`` group and the core's ``PlaneTurn.of`` state the same defaults
    where they are the same setting (the servo passes every one of them; a C++ user gets
    the core's)."""
    import re

    from spectral_vs.servo.stage_settings import PlaneTurnParams

    signature = svs._core.PlaneTurn.of.__doc__.splitlines()[0]
    core = {
        name: float(value) for name, value in re.findall(r"(\w+): [^=,]+ = ([-+0-9.e]+)", signature)
    }
    plane = PlaneTurnParams()
    assert core["plane_cone"] == plane.plane_cone
    assert core["min_plane_share"] == plane.min_plane_share
    assert core["stride"] == plane.plane_turn_stride
    assert core["fine_bandwidth"] == plane.plane_turn_bandwidth
    # The coarse step's bandwidth is the registration's: the servo passes its own (8); the
    # core's default is align()'s (16).
    assert core["bandwidth"] == svs.AlignParams().bandwidth
    assert core["max_tilt"] == plane.plane_turn_tilt
