"""Settings a person can write: every bound settings struct and ServoParams take each of
their fields as a keyword, show every field in their repr, and refuse unknown names."""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest

import spectral_vs as svs

BOUND = [svs.AlignParams, svs.ViewAlignParams, svs.DampingParams, svs.VelocityCommandParams]


def fields_of(cls: type) -> list[str]:
    """The settable properties of a bound class, in the order they were bound, without its
    deprecated aliases (keywords that stand for other fields) and its groups (whose fields
    are its own too)."""
    aliases = getattr(cls, "_deprecated_aliases", ()) + getattr(cls, "_groups", ())
    return [
        name
        for name, value in vars(cls).items()
        if not name.startswith("_")
        and isinstance(value, property)
        and value.fset is not None
        and name not in aliases
    ]


def another_value(name: str, value):
    """A value of the field's type other than its default (any field, present or future)."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return 0.5 if math.isinf(value) else value + 0.25
    if isinstance(value, str):
        return value  # a choice: the others are the binding's (tested where it is bound)
    if value is None:
        return np.array([0.0, 0.0, 1.0])  # the optional 3-vectors (viewpoints)
    if isinstance(value, np.ndarray) and value.shape == (4, 4):
        moved = value.copy()
        moved[:3, 3] += [0.01, -0.02, 0.03]
        return moved
    if isinstance(value, np.ndarray):
        return value + 0.1
    if isinstance(value, svs.DampingParams):
        return svs.DampingParams(max_damping=value.max_damping + 0.01)
    raise AssertionError(f"no other value for the field {name} = {value!r}")


def same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(a, b)
    return bool(a == b)


@pytest.mark.parametrize("cls", BOUND, ids=lambda c: c.__name__)
def test_every_field_is_a_keyword_and_in_the_repr(cls):
    names = fields_of(cls)
    assert len(names) >= 2
    default = cls()
    changed = {name: another_value(name, getattr(default, name)) for name in names}
    params = cls(**changed)
    for name, value in changed.items():
        assert same(getattr(params, name), value), name
    text = repr(params)
    assert text.startswith(f"{cls.__name__}(") and text.endswith(")")
    # Every field, in the order bound, as name=value.
    positions = [text.index(f"{name}=") for name in names]
    assert positions == sorted(positions)
    # A field changed alone changes equality; copies are equal and independent.
    assert params != default and params == copy.copy(params) == copy.deepcopy(params)
    for name in names:
        one_back = copy.deepcopy(params)
        setattr(one_back, name, getattr(default, name))
        if not same(getattr(one_back, name), getattr(params, name)):  # str choices stay
            assert one_back != params, name
            assert same(getattr(params, name), changed[name]), "the copy is independent"


@pytest.mark.parametrize("cls", [svs.AlignParams, svs.ViewAlignParams, svs.DampingParams])
def test_the_repr_evaluates_back_to_equal_settings(cls):
    params = cls(**{name: another_value(name, getattr(cls(), name)) for name in fields_of(cls)})
    assert eval(repr(params), {cls.__name__: cls}) == params


def test_the_repr_shows_values_as_written():
    text = repr(
        svs.AlignParams(voxel_size=0.005, sensor_origin=(0, 0, 0.5), rotation_step="gradient")
    )
    assert "voxel_size=0.005," in text
    assert "sensor_origin=[0.0, 0.0, 0.5]," in text
    assert "rotation_step='gradient'," in text
    assert "initial_guess=[[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]," in text
    nested = repr(svs.VelocityCommandParams(dt=0.1))
    assert "dt=0.1," in nested
    assert "damping=DampingParams(singular_value_threshold=0.05, max_damping=0.05)," in nested


@pytest.mark.parametrize("cls", BOUND, ids=lambda c: c.__name__)
def test_an_unknown_keyword_is_a_type_error_naming_it(cls):
    with pytest.raises(
        TypeError, match=rf"{cls.__name__}\(\) got an unexpected keyword argument 'colour'"
    ):
        cls(colour=1)
    with pytest.raises(TypeError, match="unexpected keyword argument '_private'"):
        cls(_private=1)


def test_a_misspelt_keyword_gets_a_suggestion_and_a_wrong_type_names_the_field():
    with pytest.raises(TypeError, match=r"'voxelsize'.*did you mean 'voxel_size'"):
        svs.AlignParams(voxelsize=0.01)
    with pytest.raises(TypeError, match=r"AlignParams\.threads takes int, got 'two' \(str\)"):
        svs.AlignParams(threads="two")
    with pytest.raises(ValueError, match="occupancy must be 'binary', 'count' or 'trilinear'"):
        svs.AlignParams(occupancy="dense")
    with pytest.raises(ValueError, match="initial_guess must be a"):
        svs.AlignParams(initial_guess=np.zeros((3, 3)))


def test_keywords_equal_attribute_assignment():
    by_keyword = svs.AlignParams(voxel_size=0.01, hypotheses=12, global_search=False)
    by_attribute = svs.AlignParams()
    by_attribute.voxel_size, by_attribute.hypotheses = 0.01, 12
    by_attribute.global_search = False
    assert by_keyword == by_attribute
    assert svs.AlignParams() == svs.AlignParams()  # defaults, as the C++ struct has them


def test_servo_params_take_every_field_and_show_it():
    fields = dataclasses.fields(svs.ServoParams)
    assert all(f.repr for f in fields)
    params = svs.ServoParams(voxel_size=0.02, mode="pose", align_overrides={"threads": 2})
    text = repr(params)
    for f in fields:
        assert f"{f.name}=" in text
    assert "voxel_size=0.02," in text and "mode='pose'," in text
    assert "align_overrides={'threads': 2}" in text
    with pytest.raises(TypeError, match="unexpected keyword argument 'colour'"):
        svs.ServoParams(colour=1)


def test_the_alias_removed_in_0_3_is_no_keyword_and_no_field():
    with pytest.raises(TypeError, match="scene_viewpoint"):
        svs.AlignParams(scene_viewpoint=(0.1, 0.0, 0.0))
    with pytest.raises(AttributeError):
        svs.SceneParams().scene_viewpoint = (0.1, 0.0, 0.0)
    with pytest.raises(TypeError, match="current_viewpoint"):
        svs.ViewAlignParams(current_viewpoint=(0.1, 0.0, 0.0))


GROUPS = {
    "scene": svs.SceneParams,
    "local": svs.LocalParams,
    "search": svs.GlobalSearchParams,
    "refinement": svs.RefinementParams,
    "verification": svs.VerificationParams,
}


def test_align_params_groups_hold_every_grouped_field_under_its_flat_name():
    params = svs.AlignParams()
    grouped = []
    for name, cls in GROUPS.items():
        group = getattr(params, name)
        assert isinstance(group, cls) and group == cls()  # the C++ defaults, per group
        grouped += fields_of(cls)
    top = [name for name in fields_of(svs.AlignParams) if name not in grouped]
    assert top == ["initial_guess", "threads", "max_seconds", "max_voxels"]
    assert len(grouped) + len(top) == len(fields_of(svs.AlignParams))


def test_a_group_is_a_reference_into_the_params_and_the_flat_field_is_the_same_value():
    params = svs.AlignParams(voxel_size=0.005, hypotheses=8)
    assert params.scene.voxel_size == 0.005 and params.search.hypotheses == 8
    params.search.hypotheses = 12
    params.refinement.polish = False
    params.scene.sensor_origin = (0.0, 0.0, 0.5)
    assert params.hypotheses == 12 and params.polish is False
    np.testing.assert_array_equal(params.sensor_origin, [0.0, 0.0, 0.5])
    params.max_iterations = 7
    assert params.local.max_iterations == 7
    assert params == svs.AlignParams(
        voxel_size=0.005, hypotheses=12, polish=False, sensor_origin=(0, 0, 0.5), max_iterations=7
    )
    detached = copy.copy(params.search)
    detached.hypotheses = 3
    assert params.hypotheses == 12  # a copy of a group is its own


def test_a_group_is_a_keyword_and_can_be_assigned_as_a_copy():
    search = svs.GlobalSearchParams(hypotheses=8, refinements=2)
    params = svs.AlignParams(search=search, voxel_size=0.005)
    assert params.hypotheses == 8 and params.refinements == 2 and params.voxel_size == 0.005
    search.hypotheses = 4
    assert params.hypotheses == 8  # the group given was copied in
    params.refinement = svs.RefinementParams(polish=False)
    assert params.polish is False and params.refinement_iterations == 20
    assert "GlobalSearchParams" not in repr(params) and "hypotheses=8" in repr(params)
    assert params == svs.AlignParams(voxel_size=0.005, hypotheses=8, refinements=2, polish=False)
    with pytest.raises(TypeError, match=r"AlignParams\.search takes GlobalSearchParams"):
        svs.AlignParams(search=svs.LocalParams())
    with pytest.raises(TypeError, match="'search'"):
        svs.align(np.zeros((3, 3)), np.zeros((3, 3)), search=1)


def test_servo_params_groups_and_flat_names_are_one_setting():
    from spectral_vs.servo import FaultParams, RegistrationParams

    flat = svs.ServoParams(voxel_size=0.01, max_outage=0.3)
    grouped = svs.ServoParams(
        registration=RegistrationParams(voxel_size=0.01), faults=FaultParams(max_outage=0.3)
    )
    assert flat == grouped and flat.faults.max_outage == 0.3 and flat.voxel_size == 0.01
    flat.max_outage = 0.4  # written through to the group
    assert flat.faults.max_outage == 0.4 and flat != grouped
    assert grouped.faults.max_outage == 0.3  # groups are not shared between settings
    assert "max_outage=0.3," in repr(grouped) and "faults=FaultParams(" in repr(grouped)
    with pytest.raises(TypeError, match=r"view_overrides.*'hypothesis'"):
        svs.ServoParams(view_overrides={"hypothesis": 3})
    with pytest.raises(TypeError, match=r"align_overrides.*'voxelsize'"):
        svs.ServoParams(align_overrides={"voxelsize": 0.01})
    with pytest.raises(AttributeError, match="no setting 'colour'"):
        flat.colour = 1
