"""The pictures of docs/architecture.md, drawn from the code as it stands (issue 35, point 10).

Nothing in them is typed by hand but the stages' names and order:

* ``docs/figures/architecture_align.png``: align()'s stages, each with its files and every
  settings group field those files read (``params.<group>.<field>``, or ``<argument>.<field>``
  of a group a stage takes; parsed from ``cpp/src/alignment``);
* ``docs/figures/architecture_views.png``: align_views()' stages, each with the internal
  headers of align()'s it includes (the pieces both pipelines share);
* ``docs/figures/architecture_servo.png``: one servo step, ``SpectralServo._step_record``,
  as the calls it makes to the servo's parts in the order they stand in the source (parsed
  with ``ast`` from ``python/spectral_vs/servo/controller.py``).

``tests/python/test_settings_source.py`` checks the same parse of the stages' reads
against the table of docs/architecture.md. Usage::

    python benchmarks/architecture_figures.py
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import report as report_lib

ROOT = Path(__file__).resolve().parents[1]
STAGE_SOURCES = ROOT / "cpp" / "src" / "alignment"
ARCHITECTURE_DOC = ROOT / "docs" / "architecture.md"
CONTROLLER = ROOT / "python" / "spectral_vs" / "servo" / "controller.py"
FIGURES = ROOT / "docs" / "figures"

#: The groups a stage declares; `scene` (the unit every stage measures in) and the
#: top-level fields (threads, limits, max_seconds, initial_guess) every stage may read.
STAGE_GROUPS = ("search", "refinement", "local", "verification")
#: A read through the whole settings: ``params.<group>.<field>`` (``params()``:
#: ModelAligner's), or through a member of a struct a stage was handed,
#: ``problem.<group>.<field>`` (Algorithm 1's ``problem.local``).
GROUP_READ = re.compile(r"(?:params(?:\(\))?|problem)\.(" + "|".join(STAGE_GROUPS) + r")\.(\w+)")
#: Each group's C++ type: a stage declares the groups it reads by taking them as
#: arguments (``const GlobalSearchParams& search``), and reads them as ``<name>.<field>``.
GROUP_TYPES = {
    "GlobalSearchParams": "search",
    "RefinementParams": "refinement",
    "LocalParams": "local",
    "VerificationParams": "verification",
}
GROUP_ARGUMENT = re.compile(r"const (" + "|".join(GROUP_TYPES) + r")&\s*(\w+)")

#: align()'s stages in the order it runs them, and their files.
ALIGN_STAGES = (
    ("scene preparation", ("prepared.hpp", "scene_preparation.cpp", "support_plane.cpp")),
    ("hypotheses", ("hypotheses.cpp", "hypothesis.hpp")),
    (
        "refinement",
        ("refinement.cpp", "refinement.hpp", "polish.cpp", "algorithm1.cpp", "icp_refinement.cpp"),
    ),
    (
        "verification, alternatives, reselection",
        ("verifier.cpp", "alternatives.cpp", "reselection.cpp", "part_coverage.cpp", "resting.cpp"),
    ),
    ("verdict", ("verdict.cpp", "covariance.cpp")),
)
#: align_views()' stages in order, and their files.
VIEW_STAGES = (
    ("preparation", ("view_preparation.cpp", "view_scale.cpp")),
    ("hypotheses", ("view_hypotheses.cpp",)),
    ("refinement: align()'s, configured by the views' data", ("view_aligner.cpp",)),
    ("verification, then align()'s verdict", ("view_verification.cpp",)),
)


# --- Reading the code ----------------------------------------------------------------------


def code_of(text: str) -> str:
    """C++ source without its comments (a comment names fields it does not read)."""
    return re.sub(r"//[^\n]*", "", text)


def function_after(code: str, start: int) -> str:
    """From an argument at ``start`` to the end of its function's body (its constructor
    initialisers included); empty for a declaration or a struct member (a ``;`` first)."""
    depth = 1  # inside the argument list
    for i in range(start, len(code)):
        if code[i] == ";":
            return ""
        if code[i] in "([":
            depth += 1
        elif code[i] in ")]":
            depth -= 1
        elif code[i] == "{" and depth <= 0:
            braces = 0
            for j in range(i, len(code)):
                braces += {"{": 1, "}": -1}.get(code[j], 0)
                if braces == 0:
                    return code[start : j + 1]
    return ""


def reads_in(text: str) -> set[tuple[str, str]]:
    """The (group, field) reads of one source file: through the whole settings or a
    member (GROUP_READ), and through each group argument, within its function."""
    code = code_of(text)
    found = set(GROUP_READ.findall(code))
    for match in GROUP_ARGUMENT.finditer(code):
        type_name, name = match.groups()
        body = function_after(code, match.end())
        read = re.findall(r"(?<![\w.])" + name + r"\.(\w+)\b(?!\s*\()", body)
        found |= {(GROUP_TYPES[type_name], field) for field in read}
    return found


def stage_reads() -> dict[str, set[tuple[str, str]]]:
    """Per source file of align()'s stages (not align_views' view_* files), the
    (group, field) of every AlignParams group it reads."""
    reads = {}
    for path in sorted(STAGE_SOURCES.glob("*.[ch]pp")):
        if path.name.startswith("view_"):
            continue
        found = reads_in(path.read_text())
        if found:
            reads[path.name] = found
    return reads


def stage_table() -> list[tuple[list[str], str]]:
    """The rows of docs/architecture.md's stage table: (its files, what it declares)."""
    text = ARCHITECTURE_DOC.read_text()
    table = text[text.index("| stage | group |") :].split("\n\n", 1)[0]
    rows = []
    for line in table.splitlines()[2:]:
        stage, declared = line.strip("|").split("|", 1)
        rows.append((re.findall(r"`(\w+\.[ch]pp)`", stage), declared))
    return rows


def declared_reads(declared: str) -> tuple[set[str], set[tuple[str, str]]]:
    """What a row's second column names: whole groups (`search`, or `search` followed by a
    parenthesised list of some of its fields counts as those fields) and single fields
    (`local.max_translation`)."""
    groups, fields = set(), set()
    for match in re.finditer(r"`(\w+)(?:\.(\w+))?`", declared):
        group, field = match.groups()
        if group not in STAGE_GROUPS:
            continue
        if field:
            fields.add((group, field))
        else:
            groups.add(group)
    unquoted = r"(?<![`.\w])(" + "|".join(STAGE_GROUPS) + r") \(([^)]*)\)"
    for match in re.finditer(unquoted, declared):
        group, listed = match.groups()
        fields |= {(group, f.strip()) for f in listed.split(",") if f.strip().isidentifier()}
    return groups, fields


def shared_headers(name: str) -> list[str]:
    """The internal headers of align()'s stages that the view stage file ``name`` includes."""
    text = (STAGE_SOURCES / name).read_text()
    headers = re.findall(r'#include "alignment/(\w+)\.hpp"', text)
    return [h for h in headers if not h.startswith("view_")]


def servo_parts() -> dict[str, str]:
    """The servo's parts: each attribute ``SpectralServo.__init__`` makes (``self._gate =
    FrameGate(...)``) and its class."""
    return dict(re.findall(r"self\.(_\w+) = ([A-Z]\w*)\(", CONTROLLER.read_text()))


def step_calls() -> list[tuple[str, str]]:
    """The calls ``_step_record`` makes to the servo's parts, in source order: (the part's
    class, the method); the servo's own helpers as ``SpectralServo``."""
    parts = servo_parts()
    tree = ast.parse(CONTROLLER.read_text())
    method = next(
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef) and node.name == "_step_record"
    )
    aliases = {}  # local name -> attribute (gate, relocalizer = self._gate, self._relocalizer)
    for node in ast.walk(method):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Tuple):
            for target, value in zip(node.targets[0].elts, node.value.elts, strict=False):
                if isinstance(target, ast.Name) and isinstance(value, ast.Attribute):
                    aliases[target.id] = value.attr
    calls = []
    for node in ast.walk(method):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)):
            continue
        path = [node.func.attr]  # gate.clock.tick: ["clock", "tick"] of the gate
        owner = node.func.value
        while isinstance(owner, ast.Attribute) and not _is_part(owner):
            path.insert(0, owner.attr)
            owner = owner.value
        if isinstance(owner, ast.Name) and owner.id == "self":
            calls.append((node.lineno, "SpectralServo", ".".join(path)))
        elif (attribute := _part_of(owner, aliases)) in parts:
            calls.append((node.lineno, parts[attribute], ".".join(path)))
    return [(part, name) for _, part, name in sorted(calls)]


def _is_part(node: ast.Attribute) -> bool:
    """``node`` is ``self._part``."""
    return isinstance(node.value, ast.Name) and node.value.id == "self"


def _part_of(node: ast.expr, aliases: dict[str, str]) -> str | None:
    """The servo attribute ``node`` names: ``self._gate``, or a local alias of it."""
    if isinstance(node, ast.Attribute) and _is_part(node):
        return node.attr
    if isinstance(node, ast.Name):
        return aliases.get(node.id)
    return None


# --- Drawing -------------------------------------------------------------------------------


def _reads_text(files: tuple[str, ...], reads: dict[str, set[tuple[str, str]]]) -> str:
    by_group: dict[str, set[str]] = {}
    for name in files:
        for group, field in reads.get(name, ()):
            by_group.setdefault(group, set()).add(field)
    if not by_group:
        return "reads: no settings group beside scene"
    return "reads: " + "; ".join(
        f"{group}.{{{', '.join(sorted(fields))}}}" for group, fields in sorted(by_group.items())
    )


def _boxes(ax, rows: list[tuple[str, str, str]], colour: str) -> None:
    """A column of boxes, top to bottom, joined by arrows: (title, files, detail)."""
    height = 1.0 / len(rows)
    for i, (title, files, detail) in enumerate(rows):
        y = 1.0 - (i + 0.5) * height
        ax.text(
            0.5, y, f"{title}\n{files}\n{detail}", ha="center", va="center", fontsize=8,
            wrap=True,
            bbox={"boxstyle": "round,pad=0.5", "facecolor": colour, "edgecolor": "0.4"},
        )  # fmt: skip
        if i + 1 < len(rows):
            ax.annotate(
                "", xy=(0.5, y - 0.42 * height), xytext=(0.5, y - 0.3 * height),
                arrowprops={"arrowstyle": "->", "color": "0.3"},
            )  # fmt: skip
    ax.set_axis_off()


def draw_align(path: Path) -> Path:
    import matplotlib.pyplot as plt

    reads = stage_reads()
    rows = [(title, ", ".join(files), _reads_text(files, reads)) for title, files in ALIGN_STAGES]
    fig, ax = plt.subplots(figsize=(10, 6.5))
    _boxes(ax, rows, "#e8f0fb")
    fig.suptitle("align(): its stages and the settings each reads (parsed from the code)")
    return report_lib.save_figure(fig, path)


def draw_views(path: Path) -> Path:
    import matplotlib.pyplot as plt

    rows = []
    for title, files in VIEW_STAGES:
        shared = sorted({h for name in files for h in shared_headers(name)})
        rows.append((title, ", ".join(files), "shares: " + (", ".join(shared) or "none")))
    common = ", ".join(shared_headers("view_stages.hpp"))
    fig, ax = plt.subplots(figsize=(10, 5))
    _boxes(ax, rows, "#eef7e8")
    fig.suptitle(
        "align_views(): its stages and the pieces of align() they share (#includes)\n"
        f"every stage, through view_stages.hpp: {common}",
        fontsize=10,
    )
    return report_lib.save_figure(fig, path)


def draw_servo(path: Path) -> Path:
    import matplotlib.pyplot as plt

    calls = step_calls()
    lanes = list(dict.fromkeys(part for part, _ in calls))
    fig, ax = plt.subplots(figsize=(11, 0.32 * len(calls) + 1.2))
    for j in range(len(lanes)):
        ax.axvline(j, color="0.85", zorder=0)
    previous = None
    for i, (part, name) in enumerate(calls):
        x, y = lanes.index(part), -i
        ax.plot(x, y, "o", color="C0")
        ax.text(x + 0.08, y, f"{name}()", va="center", fontsize=8)
        if previous is not None:
            ax.annotate(
                "", xy=(x, y), xytext=previous, arrowprops={"arrowstyle": "->", "color": "0.6"}
            )
        previous = (x, y)
    ax.set_xticks(range(len(lanes)), lanes, fontsize=8)
    ax.xaxis.tick_top()
    ax.set_yticks([])
    ax.set_xlim(-0.5, len(lanes) - 0.2)
    for side in ("right", "bottom", "left"):
        ax.spines[side].set_visible(False)
    fig.suptitle("One servo step (SpectralServo._step_record): the parts it calls, in order")
    return report_lib.save_figure(fig, path)


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    for draw, name in (
        (draw_align, "architecture_align.png"),
        (draw_views, "architecture_views.png"),
        (draw_servo, "architecture_servo.png"),
    ):
        print(f"wrote {draw(FIGURES / name).relative_to(ROOT)}")


if __name__ == "__main__":
    main()
