"""The settings structs have one source, their C++ public headers (issue 35, point 4).

Each bound settings struct's fields are read from its header (name and default, as
written there) and the Python class is checked against them: the same fields (renames
listed below), the same defaults, every field in the class docstring's ``Attributes``,
every default the docstring states equal to the real one, and, for ``AlignParams``' groups,
the fields docs/alignment.md lists. The stubs are checked against the bound classes by
test_stubs.py, so a field added, renamed or given another default in C++ fails here until
every copy follows.

And what each of align()'s stages reads (issue 35, point 2): every ``params.<group>.<field>``
in ``cpp/src/alignment`` against the row of docs/architecture.md's stage table that names
its file, both ways.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from architecture_figures import (
    GROUP_READ,
    STAGE_SOURCES,
    declared_reads,
    reads_in,
    stage_reads,
    stage_table,
)
from test_stubs import settable_fields as bound_settable_fields

from spectral_vs import _core

ROOT = Path(__file__).resolve().parents[2]
INCLUDE = ROOT / "cpp" / "include" / "spectral_vs"
ALIGNMENT_DOC = ROOT / "docs" / "alignment.md"


@dataclass(frozen=True)
class Bound:
    """A bound settings class and the C++ struct it binds."""

    header: str
    struct: str
    #: C++ field -> its Python name, where they differ.
    renames: tuple[tuple[str, str], ...] = ()
    #: C++ fields that are groups (their own settings struct), flat in Python.
    groups: tuple[str, ...] = ()


SETTINGS = {
    "SceneParams": Bound("alignment/aligner.hpp", "SceneParams"),
    "LocalParams": Bound("alignment/aligner.hpp", "LocalParams", (("icp", "local_icp"),)),
    "GlobalSearchParams": Bound("alignment/aligner.hpp", "GlobalSearchParams"),
    "RefinementParams": Bound("alignment/aligner.hpp", "RefinementParams"),
    "VerificationParams": Bound("alignment/aligner.hpp", "VerificationParams"),
    "AlignParams": Bound(
        "alignment/aligner.hpp",
        "AlignParams",
        (("limits", "max_voxels"),),
        ("scene", "local", "search", "refinement", "verification"),
    ),
    "ViewAlignParams": Bound(
        "alignment/view_aligner.hpp", "ViewAlignParams", (("limits", "max_voxels"),)
    ),
    "DampingParams": Bound("kinematics/kinematics.hpp", "DampingParams"),
    "VelocityCommandParams": Bound("kinematics/kinematics.hpp", "VelocityCommandParams"),
}

#: Python's names of the C++ enumerators a choice field takes (bindings: kSceneViews, ...).
CHOICE_NAMES = {"automatic": "auto"}

#: C++ defaults that are expressions rather than literals, as Python reads them.
EXPRESSIONS: dict[str, Any] = {
    "Eigen::Vector3d::Zero()": [0.0, 0.0, 0.0],
    "Transform::Identity()": np.eye(4).tolist(),
    "std::numeric_limits<double>::infinity()": math.inf,
}

#: Words the docstrings use for a default, as values.
DEFAULT_WORDS: dict[str, Any] = {
    "Off": False,
    "On": True,
    "the origin": [0.0, 0.0, 0.0],
    "none": 0.0,
    "no limit": 0.0,
}


@dataclass(frozen=True)
class Field:
    name: str
    type: str
    default: str | None  # as written in the header; None: default-constructed


def struct_body(header: str, struct: str) -> str:
    """The text between the braces of `struct <name> {` in a public header."""
    text = (INCLUDE / header).read_text(encoding="utf-8")
    match = re.search(rf"^struct {struct} \{{\n", text, re.MULTILINE)
    assert match, f"struct {struct} not found in {header}"
    depth, start = 1, match.end()
    for i in range(start, len(text)):
        depth += {"{": 1, "}": -1}.get(text[i], 0)
        if depth == 0:
            return text[start:i]
    raise AssertionError(f"struct {struct} in {header} is not closed")


FIELD = re.compile(r"^  ([\w:<>]+) (\w+)(?: = ([^;]+))?;")


def cpp_fields(bound: Bound) -> list[Field]:
    """The data members of the struct, in their order (comments and methods skipped)."""
    fields = []
    for line in struct_body(bound.header, bound.struct).splitlines():
        match = FIELD.match(line)
        if match and not line.lstrip().startswith("//"):
            fields.append(Field(match.group(2), match.group(1), match.group(3)))
    assert fields, f"no fields parsed from {bound.struct}"
    return fields


def python_name(bound: Bound, field: str) -> str:
    return dict(bound.renames).get(field, field)


def flat_fields(name: str) -> list[tuple[str, Field, Bound]]:
    """The flat fields of a class, from C++: its own fields and its groups', each with its
    Python name and the struct that declares it."""
    bound = SETTINGS[name]
    fields: list[tuple[str, Field, Bound]] = []
    for field in cpp_fields(bound):
        if field.name in bound.groups:
            fields += flat_fields(field.type)
        else:
            fields.append((python_name(bound, field.name), field, bound))
    return fields


def expected_python_fields(name: str) -> list[str]:
    return [python_name for python_name, _, _ in flat_fields(name)]


def settable_fields(cls: type) -> list[str]:
    """The bound settings of a class, its groups aside (test_stubs.py's list has them)."""
    groups = set(getattr(cls, "_groups", ()))
    return [name for name in bound_settable_fields(cls) if name not in groups]


def cpp_default(field: Field, bound: Bound) -> Any:
    """The default as Python reads it, from the header's literal."""
    text = " ".join(field.default.split()) if field.default else None
    if text is None or text == "{}":
        return None  # a struct of its own: its fields carry the defaults
    if text in EXPRESSIONS:
        return EXPRESSIONS[text]
    if text in ("true", "false"):
        return text == "true"
    if "::" in text:  # an enumerator of a choice
        enumerator = text.rsplit("::", 1)[1]
        return CHOICE_NAMES.get(enumerator, enumerator)
    number = text.rstrip("fF")
    try:
        return int(number) if re.fullmatch(r"-?\d+", number) else float(number)
    except ValueError:
        pytest.fail(f"{bound.struct}::{field.name}: cannot read the default {text!r}")


def same(actual: Any, expected: Any) -> bool:
    if isinstance(expected, bool) or isinstance(actual, bool):
        return type(actual) is type(expected) and actual == expected
    if isinstance(expected, list):
        return np.allclose(np.asarray(actual, dtype=float), np.asarray(expected), atol=0.0)
    if isinstance(expected, float) or isinstance(actual, float):
        return math.isclose(float(actual), float(expected), rel_tol=1e-12, abs_tol=0.0)
    return bool(actual == expected)


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_python_fields_are_the_cpp_fields(name: str) -> None:
    actual = settable_fields(getattr(_core, name))
    expected = expected_python_fields(name)
    assert actual == expected, (
        f"{name}: bound {actual}, but {SETTINGS[name].header} declares {expected} "
        "(bind the new field, or list a rename in this test)"
    )


def defaults_from_cpp(name: str) -> dict[str, Any]:
    defaults = {python: cpp_default(field, bound) for python, field, bound in flat_fields(name)}
    return {python: value for python, value in defaults.items() if value is not None}


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_python_defaults_are_the_cpp_defaults(name: str) -> None:
    params = getattr(_core, name)()
    for field, expected in defaults_from_cpp(name).items():
        actual = getattr(params, field)
        if isinstance(actual, np.ndarray):
            actual = actual.tolist()
        assert same(actual, expected), f"{name}.{field}: Python {actual!r}, C++ {expected!r}"


def attribute_entries(cls: type) -> dict[str, str]:
    """The numpydoc ``Attributes`` of the class docstring: each name with its text."""
    doc = cls.__doc__ or ""
    section = doc.split("Attributes\n----------\n", 1)
    assert len(section) == 2, f"{cls.__name__}: no Attributes section in its docstring"
    entries: dict[str, str] = {}
    names: list[str] = []
    for line in section[1].splitlines():
        header = re.match(r"^(\w+(?:, \w+)*)(?: : |$)", line)
        if header:
            names = header.group(1).split(", ")
            for entry in names:
                entries[entry] = ""
        elif line.startswith("    "):
            for entry in names:
                entries[entry] += " " + line.strip()
        elif line.strip():
            break  # the next section
    return entries


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_every_field_is_documented(name: str) -> None:
    """The class documents its own fields and groups (a group's fields: its class)."""
    bound = SETTINGS[name]
    own = [python_name(bound, field.name) for field in cpp_fields(bound)]
    documented = attribute_entries(getattr(_core, name))
    missing = [f for f in own if f not in documented]
    assert not missing, f"{name}: fields without an entry in its docstring: {missing}"
    unknown = [f for f in documented if f not in own]
    assert not unknown, f"{name}: its docstring documents fields it does not have: {unknown}"


STATED_DEFAULT = (
    re.compile(r"\(default:? ([^);:,]+?)(?:[);:,]|$)"),  # (default 16)  (default 0: none)
    re.compile(r"; default ([^);:,]+?)\)"),  # ...; default 0.03)
    re.compile(r"(\S+(?: \S+)?) \(default\)"),  # 'trilinear' (default)   0 (default): ...
)


def stated_value(text: str) -> Any:
    text = text.strip().strip("`").rstrip(".")
    if text in DEFAULT_WORDS:
        return DEFAULT_WORDS[text]
    for word, value in DEFAULT_WORDS.items():
        if text.endswith(" " + word):
            return value
    if text in ("True", "False"):
        return text == "True"
    if re.fullmatch(r"'[^']*'", text):
        return text[1:-1]
    power = re.fullmatch(r"(\d+)\^(\d+)", text)
    if power:
        return int(power.group(1)) ** int(power.group(2))
    try:
        return float(text)
    except ValueError:
        return None


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_defaults_the_docstrings_state_are_the_real_ones(name: str) -> None:
    params = getattr(_core, name)()
    checked = 0
    for field, text in attribute_entries(getattr(_core, name)).items():
        for pattern in STATED_DEFAULT:
            for match in pattern.finditer(text):
                stated = stated_value(match.group(1))
                if stated is None:
                    continue  # a sentence, not a value ("the larger of ...")
                actual = getattr(params, field)
                if isinstance(actual, np.ndarray):
                    actual = actual.tolist()
                assert same(actual, stated), (
                    f"{name}.{field}: the docstring says the default is {match.group(1)!r}, "
                    f"it is {actual!r}"
                )
                checked += 1
    if name not in ("DampingParams", "VelocityCommandParams"):
        assert checked > 0, f"{name}: no stated default was read (has the wording changed?)"


def documented_group_fields() -> dict[str, list[str]]:
    """docs/alignment.md's table of AlignParams' groups: the fields of each class."""
    rows = {}
    for line in ALIGNMENT_DOC.read_text(encoding="utf-8").splitlines():
        match = re.match(r"^\| `\w+` \(`(\w+)`\) \| (.+?) \| .+ \|$", line)
        if match:
            rows[match.group(1)] = re.findall(r"`(\w+)`", match.group(2))
    return rows


def test_the_alignment_docs_list_every_group_field() -> None:
    rows = documented_group_fields()
    groups = SETTINGS["AlignParams"].groups
    classes = [f.type for f in cpp_fields(SETTINGS["AlignParams"]) if f.name in groups]
    assert sorted(rows) == sorted(classes)
    for cls in classes:
        assert rows[cls] == expected_python_fields(cls), (
            f"docs/alignment.md lists {rows[cls]} for {cls}, C++ declares "
            f"{expected_python_fields(cls)}"
        )


# --- What each of align()'s stages reads (docs/architecture.md) ---------------------------


def test_every_stage_reads_only_the_settings_its_row_declares():
    rows = stage_table()
    described = {name for files, _ in rows for name in files}
    reads = stage_reads()
    assert set(reads) <= described, f"stage files missing from the table: {set(reads) - described}"
    for files, declared in rows:
        if "every group" in declared:
            continue
        groups, fields = declared_reads(declared)
        read = set().union(*(reads.get(name, set()) for name in files))
        undeclared = {(g, f) for g, f in read if g not in groups and (g, f) not in fields}
        assert not undeclared, f"{files} read {sorted(undeclared)}, not in their row"
        for group in groups | {g for g, _ in fields}:
            assert any(g == group for g, _ in read), f"{files}: row names {group}, never read"


def test_the_stage_reads_parser_sees_a_read_and_a_declaration():
    assert GROUP_READ.findall(
        "problem.params.search.max_parts + params().local.icp + problem.local.tolerance"
    ) == [
        ("search", "max_parts"),
        ("local", "icp"),
        ("local", "tolerance"),
    ]
    groups, fields = declared_reads(
        "`search` (hypotheses); `local.rotation_step`, the switches: `refinement` (polish, icp)"
    )
    assert groups == {"search", "refinement"} and ("local", "rotation_step") in fields
    # A group taken as an argument is read through its name, within its function only (a
    # So3SearchParams named `search` elsewhere, a comment, an #include are no reads).
    source = """#include "alignment/refinement.hpp"
    int f(const GlobalSearchParams& search, const LocalParams& local) {
      return search.hypotheses + g(local.rotation_step);  // local.tolerance
    }
    Window::Window(const LocalParams& local) : bounded_(local.max_translation != 0.0) {}
    void h(const RefinementParams& refinement);
    void k() { So3SearchParams search; search.candidates = 4; refinement.polish(); }
    """
    assert reads_in(source) == {
        ("search", "hypotheses"),
        ("local", "rotation_step"),
        ("local", "max_translation"),
    }


#: The files that hold the whole AlignParams: the pipelines that decide which stages run
#: (aligner.cpp, model_aligner.cpp), the settings' checks, the preparation that builds
#: every stage's Problem, and the public functions that take AlignParams.
WHOLE_SETTINGS = {
    "aligner.cpp",
    "model_aligner.cpp",
    "align_settings.cpp",
    "align_detail.hpp",
    "prepared.hpp",
    "scene_preparation.cpp",
    "scene_preparation.hpp",
    "algorithm1.cpp",  # rotation_step_about (public)
    "plane_turn.cpp",  # PlaneTurn (public)
}


def test_no_stage_holds_the_whole_settings():
    """Every other stage takes the settings groups it reads as arguments (issue 35)."""
    holders = {
        path.name
        for path in STAGE_SOURCES.glob("*.[ch]pp")
        if re.search(r"(?<!View)AlignParams&", path.read_text())
    }
    assert holders <= WHOLE_SETTINGS, f"stages that take AlignParams: {holders - WHOLE_SETTINGS}"


def test_the_servo_scores_steps_at_the_relocalization_threshold_the_cpp_default_states():
    # StepScoreParams (C++, for embedders) and RelocalizationParams (the servo, Python)
    # state the same threshold twice: the C++ default must follow the servo's.
    from spectral_vs.servo.fault_settings import RelocalizationParams

    fields = {f.name: f for f in cpp_fields(Bound("alignment/verification.hpp", "StepScoreParams"))}
    cpp = float(fields["relocalize_fitness"].default)
    assert cpp == RelocalizationParams().relocalize_fitness


# --- The stages' tuned constants (issue 35, point 6) ----------------------------------------

#: A named constant: ``constexpr double kFlatAxisRatio = 0.1;``.
TUNED_CONSTANT = re.compile(r"^\s*(?:inline\s+)?constexpr\s+[\w:]+\s+(k\w+)\s*=")


def constant_notes(path: Path) -> dict[str, bool]:
    """Each named constant of a file, and whether its note is there: a comment on its line,
    or in the comment just above it or above the run of constants it stands in."""
    lines = path.read_text().splitlines()
    notes = {}
    for i, line in enumerate(lines):
        match = TUNED_CONSTANT.match(line)
        if not match:
            continue
        j = i - 1
        while j >= 0 and TUNED_CONSTANT.match(lines[j]):
            j -= 1
        notes[match.group(1)] = "//" in line or (j >= 0 and lines[j].strip().startswith("//"))
    return notes


def test_every_tuned_constant_of_the_stages_carries_its_note():
    """Each stage's constants are named in its own file, each with its unit and the
    measurement behind it (docs/architecture.md, "Tuned constants")."""
    found = {}
    for path in sorted(STAGE_SOURCES.glob("*.[ch]pp")):
        found.update(
            {f"{path.name}: {name}": noted for name, noted in constant_notes(path).items()}
        )
    assert len(found) > 80, "the constants' parse found too few"
    bare = sorted(name for name, noted in found.items() if not noted)
    assert not bare, f"constants without a note: {bare}"


def test_the_constant_parser_sees_a_note_above_a_run_of_constants(tmp_path):
    source = tmp_path / "stage.cpp"
    source.write_text(
        "// Two steps, degrees: measured on the tuning set.\n"
        "constexpr double kFirst = 4.0;\n"
        "constexpr double kLast = 0.25;\n"
        "\n"
        "constexpr int kBare = 3;\n"
        "inline constexpr double kInline = 1.0;  // metres\n"
    )
    assert constant_notes(source) == {
        "kFirst": True,
        "kLast": True,
        "kBare": False,
        "kInline": True,
    }
