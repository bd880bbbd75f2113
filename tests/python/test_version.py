"""One version everywhere: the CMake project's, which the wheel's metadata, the package's
``__version__``, the command line and the installed CMake package all report."""

from __future__ import annotations

import re
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import spectral_vs as svs

ROOT = Path(__file__).resolve().parents[2]


def cmake_project_version() -> str:
    text = (ROOT / "CMakeLists.txt").read_text()
    match = re.search(r"project\(spectral_vs VERSION ([0-9]+\.[0-9]+\.[0-9]+)", text)
    assert match, "CMakeLists.txt names no project version"
    return match.group(1)


def test_the_package_reports_the_cmake_project_version():
    expected = cmake_project_version()
    assert version("spectral_vs") == expected
    assert svs.__version__ == expected


def test_the_command_line_reports_it():
    cli = Path(sys.executable).with_name("spectral-vs")
    printed = subprocess.run([str(cli), "--version"], capture_output=True, text=True, check=True)
    assert printed.stdout.strip() == f"spectral_vs {cmake_project_version()}"


def test_the_changelog_leads_with_it():
    first = re.search(r"^## (\S+)", (ROOT / "CHANGELOG.md").read_text(), re.MULTILINE)
    assert first and first.group(1) == cmake_project_version()


def test_cmake_users_ask_for_it():
    major_minor = ".".join(cmake_project_version().split(".")[:2])
    for path in ("README.md", "examples/CMakeLists.txt", "tests/cpp/consumer/CMakeLists.txt"):
        asked = re.findall(
            r"find_package\(spectral_vs ([0-9.]+) REQUIRED\)", (ROOT / path).read_text()
        )
        assert asked == [major_minor], path
