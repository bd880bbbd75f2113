"""The type stubs of the compiled module (spectral_vs/_core.pyi) against the module itself.

pybind11 functions have no runtime signature that ``inspect`` can read, so mypy's
stubtest checks names, classes and read-only fields only; the parameter lists are
compared here with the signature pybind11 writes on the first line of each docstring.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import site
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import spectral_vs
from spectral_vs import _core

STUB = Path(_core.__file__).with_name("_core.pyi")
ALLOWLIST = Path(__file__).with_name("stubtest_allowlist.txt")
ROOT = Path(__file__).resolve().parents[2]

# Dunders every class has from object (or pybind11) that the stubs need not repeat.
INHERITED = {"__doc__", "__module__", "__init__", "__repr__", "__str__"}

# Parameters are compared as (name, "positional" or "keyword", default). A stub default
# written `...` stands for a runtime default that is not a Python literal (an array, inf,
# a params object); every literal default must be spelled out as the module has it.
Parameter = tuple[str, str, Any]
NO_DEFAULT = "<no default>"
NOT_LITERAL = "<not a literal>"


def stub_module() -> ast.Module:
    if not STUB.is_file():
        pytest.fail(f"{STUB.name} is not installed beside {Path(_core.__file__).name}")
    return ast.parse(STUB.read_text(encoding="utf-8"), filename=str(STUB))


def stub_members(body: list[ast.stmt]) -> dict[str, list[ast.stmt]]:
    """Names a class or module body defines, each with its statements (overloads, setters)."""
    members: dict[str, list[ast.stmt]] = {}
    for node in body:
        if isinstance(node, ast.FunctionDef | ast.ClassDef):
            members.setdefault(node.name, []).append(node)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            members.setdefault(node.target.id, []).append(node)
    return members


def is_type_alias(nodes: list[ast.stmt]) -> bool:
    return all(
        isinstance(node, ast.AnnAssign)
        and isinstance(node.annotation, ast.Name)
        and node.annotation.id == "TypeAlias"
        for node in nodes
    )


def decorator_names(node: ast.FunctionDef) -> set[str]:
    names = set()
    for decorator in node.decorator_list:
        if isinstance(decorator, ast.Name):
            names.add(decorator.id)
        elif isinstance(decorator, ast.Attribute):
            names.add(decorator.attr)  # `@x.setter`
    return names


def has_constructor(cls: type) -> bool:
    """pybind11 classes without py::init keep a generic __init__ that only raises."""
    return (cls.__dict__["__init__"].__doc__ or "").startswith("__init__(")


def runtime_class_members(cls: type) -> set[str]:
    if issubclass(cls, BaseException):  # InputWarning: a Python class, nothing of its own
        return set()
    names = {name for name in vars(cls) if not name.startswith("_")}
    names |= {
        name
        for name in vars(cls)
        if name.startswith("__") and name.endswith("__") and name not in INHERITED
    }
    if has_constructor(cls):
        names.add("__init__")
    return names


def test_stub_names_match_module() -> None:
    module = stub_module()
    stub_names = {
        name for name, nodes in stub_members(module.body).items() if not is_type_alias(nodes)
    }
    runtime_names = {name for name in vars(_core) if not name.startswith("__")}
    problems = []
    if stub_names != runtime_names:
        problems.append(
            f"module: missing in {STUB.name}: {sorted(runtime_names - stub_names)}, "
            f"not in the module: {sorted(stub_names - runtime_names)}"
        )
    for node in module.body:
        if not isinstance(node, ast.ClassDef) or node.name not in runtime_names:
            continue
        members = {
            name
            for name in stub_members(node.body)
            if not name.startswith("_")
            or name == "__init__"
            or (name.startswith("__") and name not in INHERITED)
        }
        expected = runtime_class_members(getattr(_core, node.name))
        if members != expected:
            problems.append(
                f"{node.name}: missing in {STUB.name}: {sorted(expected - members)}, "
                f"not in the module: {sorted(members - expected)}"
            )
    assert not problems, "\n".join(problems)


# --- Signatures --------------------------------------------------------------------


def split_top_level(text: str, separator: str = ",") -> list[str]:
    """Split at separators outside brackets and quotes."""
    parts, depth, quote, current = [], 0, "", ""
    for char in text:
        if quote:
            quote = "" if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char in "([{":
            depth += 1
        elif char in ")]}":
            depth -= 1
        elif char == separator and depth == 0:
            parts.append(current.strip())
            current = ""
            continue
        current += char
    if current.strip():
        parts.append(current.strip())
    return parts


def literal_or_marker(text: str) -> Any:
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return NOT_LITERAL


def docstring_signatures(function: Any, name: str) -> list[list[Parameter]]:
    """Parameter lists of the `name(...) -> ...` lines pybind11 writes in the docstring."""
    lines = (function.__doc__ or "").splitlines()
    if len(lines) > 1 and lines[1].strip() == "Overloaded function.":
        headers = [line.split(". ", 1)[1] for line in lines if line[:1].isdigit() and ". " in line]
    else:
        headers = lines[:1]
    signatures = []
    for header in headers:
        if not header.startswith(name + "("):
            pytest.fail(f"{name}: no pybind11 signature in its docstring: {header!r}")
        inner = header[len(name) + 1 : header.rindex(") -> ")]
        parameters: list[Parameter] = []
        kind = "positional"
        for part in split_top_level(inner):
            if part == "*":
                kind = "keyword"
                continue
            if part == "/":
                continue
            head, _, default = part.partition(" = ")
            parameters.append(
                (
                    head.split(":")[0].strip(),
                    kind,
                    literal_or_marker(default) if default else NO_DEFAULT,
                )
            )
        signatures.append(parameters)
    return signatures


def stub_signature(node: ast.FunctionDef) -> list[Parameter]:
    args = node.args
    positional = args.posonlyargs + args.args
    defaults: list[ast.expr | None] = [None] * (len(positional) - len(args.defaults))
    defaults += args.defaults
    parameters: list[Parameter] = []
    for arg, default in zip(positional, defaults, strict=True):
        parameters.append((arg.arg, "positional", stub_default(default)))
    for arg, default in zip(args.kwonlyargs, args.kw_defaults, strict=True):
        parameters.append((arg.arg, "keyword", stub_default(default)))
    if args.kwarg is not None:  # pybind11 writes **kwargs where the positional ones go
        parameters.append((f"**{args.kwarg.arg}", "positional", NO_DEFAULT))
    return parameters


def stub_default(node: ast.expr | None) -> Any:
    if node is None:
        return NO_DEFAULT
    if isinstance(node, ast.Constant) and node.value is Ellipsis:
        return NOT_LITERAL
    return ast.literal_eval(node)


def signature_cases() -> list[tuple[str, Any, list[ast.FunctionDef]]]:
    """(qualified name, runtime function, stub definitions) of every function and method."""
    cases = []

    def add(qualname: str, runtime: Any, nodes: list[ast.stmt]) -> None:
        defs = [
            node
            for node in nodes
            if isinstance(node, ast.FunctionDef)
            and not {"property", "setter"} & decorator_names(node)
        ]
        if defs:
            cases.append((qualname, runtime, defs))

    for name, nodes in stub_members(stub_module().body).items():
        if name not in vars(_core):
            continue  # reported by test_stub_names_match_module
        runtime = getattr(_core, name)
        for node in nodes:
            if isinstance(node, ast.ClassDef):
                for member, member_nodes in stub_members(node.body).items():
                    if hasattr(runtime, member):
                        add(f"{name}.{member}", getattr(runtime, member), member_nodes)
        add(name, runtime, nodes)
    return cases


def settable_fields(cls: type) -> list[str]:
    """The properties with a setter of a bound class, in the order they were bound."""
    return [
        name
        for name, value in vars(cls).items()
        if not name.startswith("_") and isinstance(value, property) and value.fset is not None
    ]


def pretty(parameters: list[Parameter]) -> str:
    out = []
    for i, (name, kind, default) in enumerate(parameters):
        if kind == "keyword" and (i == 0 or parameters[i - 1][1] != "keyword"):
            out.append("*")
        out.append(name if default == NO_DEFAULT else f"{name}={default!r}")
    return "(" + ", ".join(out) + ")"


SIGNATURE_CASES = signature_cases()


@pytest.mark.parametrize(
    ("qualname", "runtime", "defs"), SIGNATURE_CASES, ids=[case[0] for case in SIGNATURE_CASES]
)
def test_stub_signatures_match_module(
    qualname: str, runtime: Any, defs: list[ast.FunctionDef]
) -> None:
    is_method = "." in qualname
    static = any("staticmethod" in decorator_names(node) for node in defs)
    actual = docstring_signatures(runtime, qualname.rsplit(".", 1)[-1])
    if is_method and not static:  # self is `self: Class` or `arg0: Class`
        actual = [signature[1:] for signature in actual]

    stubs = [stub_signature(node) for node in defs]
    if is_method and not static:
        stubs = [signature[1:] for signature in stubs]

    if actual == [[("**kwargs", "positional", NO_DEFAULT)]] and qualname.endswith(".__init__"):
        # A settings struct (bindings/settings.hpp) takes its fields as keywords: the stub
        # spells them out, keyword-only, in the order of the bound settable properties.
        fields = settable_fields(getattr(_core, qualname.split(".")[0]))
        assert len(stubs) == 1 and stubs[0] == [(f, "keyword", NOT_LITERAL) for f in fields], (
            f"{qualname}: stub {pretty(stubs[0])} but the settings are {fields}"
        )
        return

    if len(defs) == 1:
        # Names, order, keyword-only markers and literal defaults must all agree.
        assert stubs[0] in actual, (
            f"{qualname}: stub {pretty(stubs[0])} but the module has "
            + " or ".join(pretty(s) for s in actual)
        )
    else:
        # @overload variants narrow types and defaults (Literal[True], ...): only the
        # parameter names and their order must be the runtime's.
        names = {tuple(name for name, _, _ in s) for s in actual}
        for signature in stubs:
            assert tuple(name for name, _, _ in signature) in names, (
                f"{qualname}: overload {pretty(signature)} but the module has "
                + " or ".join(pretty(s) for s in actual)
            )


# --- mypy -------------------------------------------------------------------------


def run_python(module: str, *args: str, cwd: Path, pythonpath: Path | None) -> str:
    """Output of `python -m module args`; fails the test on a non-zero exit."""
    if importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed (pip install mypy)")
    env = dict(os.environ)
    env.pop("MYPYPATH", None)
    env.pop("PYTHONPATH", None)
    if pythonpath is not None and str(pythonpath) not in site.getsitepackages():
        env["PYTHONPATH"] = str(pythonpath)
    result = subprocess.run(
        [sys.executable, "-m", module, *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, f"python -m {module} failed:\n{result.stdout}{result.stderr}"
    return result.stdout


def test_stubtest(tmp_path: Path) -> None:
    """mypy's stubtest: every name in the stubs and back, classes, read-only fields."""
    # The spectral_vs imported here (an installed wheel or a build tree) is the one checked.
    run_python(
        "mypy.stubtest",
        "spectral_vs._core",
        "--allowlist",
        str(ALLOWLIST),
        cwd=tmp_path,
        pythonpath=Path(spectral_vs.__file__).parents[1],
    )


def test_package_type_checks_against_stubs() -> None:
    """mypy on the package sources ([tool.mypy] in pyproject.toml) with these stubs."""
    if not (ROOT / "python" / "spectral_vs" / "_core.pyi").is_file():
        pytest.skip("the package sources are not beside the tests")
    run_python("mypy", cwd=ROOT, pythonpath=None)
