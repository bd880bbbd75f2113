"""The pictures of docs/architecture.md read the code (benchmarks/architecture_figures.py):
the servo's parts and the order one step calls them, and the pieces align_views shares."""

from __future__ import annotations

import architecture_figures as figures


def test_the_servo_parts_are_what_its_constructor_makes():
    parts = figures.servo_parts()
    assert parts["_gate"] == "FrameGate"
    assert parts["_tracker"] == "Tracker"
    assert parts["_relocalizer"] == "Relocalizer"


def test_a_step_gates_the_frame_then_relocalizes_then_tracks_then_commands():
    calls = figures.step_calls()
    order = [f"{part}.{name}" for part, name in calls]
    assert order[0] == "FrameGate.clock.tick"
    first = {name: order.index(name) for name in order[::-1]}
    assert (
        first["FrameGate.fault"]
        < first["Relocalizer.relocalize"]
        < first["Tracker.measure"]
        < first["Tracker.jump"]
        < first["SpectralServo._command"]
    )
    # Every call is a part's or the servo's own: none is lost to an unknown receiver.
    assert {part for part, _ in calls} <= set(figures.servo_parts().values()) | {"SpectralServo"}


def test_the_view_stages_share_the_hypothesis_the_refinement_and_the_verdict():
    assert "hypothesis" in figures.shared_headers("view_stages.hpp")
    assert "refinement" in figures.shared_headers("view_aligner.cpp")
    assert "verdict_detail" in figures.shared_headers("view_verification.cpp")
    assert not any(h.startswith("view_") for h in figures.shared_headers("view_verification.cpp"))
