"""The README runs as written: its Python examples are executed in order, in one namespace
(each builds on the ones before, as a reader types them), against the shared scans it
names; the outputs it shows for ``make demo`` are compared with what the commands print
now, times aside."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: How the README names the shared scans: beside the repository.
README_DATA = "../shared/data"


def fenced_blocks(language: str) -> list[tuple[int, str]]:
    """The README's fenced blocks of ``language``: (line of the opening fence, text)."""
    blocks, current, start = [], None, 0
    for number, line in enumerate(README.read_text().splitlines(), start=1):
        if current is None and line.strip() == f"```{language}":
            current, start = [], number
        elif current is not None and line.strip() == "```":
            blocks.append((start, "\n".join(current)))
            current = None
        elif current is not None:
            current.append(line)
    return blocks


PYTHON_BLOCKS = fenced_blocks("python")


def test_the_readme_has_its_examples():
    assert len(PYTHON_BLOCKS) >= 7  # the package, depth, Open3D, alignment, trust, views, servo


@pytest.fixture(scope="module")
def scans(data_dir) -> Path:
    """The shared scans, resolved before any example changes the working folder."""
    return data_dir.resolve()


@pytest.fixture(scope="module")
def namespace(scans, tmp_path_factory):
    """One namespace for all the examples, run from a scratch folder."""
    cwd = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("readme"))
    yield {"__name__": "readme"}
    os.chdir(cwd)


@pytest.mark.parametrize("line, code", PYTHON_BLOCKS, ids=[f"line{n}" for n, _ in PYTHON_BLOCKS])
def test_python_example_runs(line, code, namespace, scans, monkeypatch):
    if "import open3d" in code:
        o3d = pytest.importorskip("open3d")
        # The example ends by opening a viewer window: not in a test.
        monkeypatch.setattr(o3d.visualization, "draw_geometries", lambda *args, **kw: None)
    if "from spectral_vs import sim" in code:
        pytest.importorskip("pybullet")
    code = code.replace(README_DATA, str(scans))
    exec(compile(code, f"README.md:{line}", "exec"), namespace)


def masked(text: str) -> str:
    """``text`` without what changes from run to run: times, and the thread count."""
    text = re.sub(r"\s*\d+(\.\d+)? (ms|s)\b", " <time>", text)
    return re.sub(r"\d+ threads", "<n> threads", text)


def shown_output(after: str) -> list[str]:
    """The lines of the first ``text`` block of the README after the text ``after``, less
    the elisions (``...``)."""
    readme = README.read_text()
    rest = readme[readme.index(after) :]
    block = rest.split("```text\n", 1)[1].split("```", 1)[0]
    return [line for line in block.splitlines() if line.strip() != "..."]


def run_cli(args: list[str], cwd: Path) -> str:
    cli = Path(sys.executable).with_name("spectral-vs")
    done = subprocess.run(
        [str(cli), *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout + done.stderr


def assert_shown(shown: list[str], printed: str) -> None:
    """Every line the README shows is printed (times aside)."""
    printed_lines = set(masked(printed).splitlines())
    missing = [line for line in shown if masked(line) not in printed_lines]
    assert not missing, "README lines not printed:\n" + "\n".join(missing) + "\n--\n" + printed


def test_servo_sim_prints_what_the_readme_shows(tmp_path):
    pytest.importorskip("pybullet")
    printed = run_cli(["servo-sim", "--out", "results/servo"], tmp_path)
    assert_shown(shown_output("`make demo` first runs the paper's robot experiment"), printed)


def test_demo_prints_what_the_readme_shows(tmp_path, scans):
    printed = run_cli(["demo", "--data", str(scans), "--output", "results/demo"], tmp_path)
    assert_shown(shown_output("Then it runs `spectral-vs demo"), printed)


def cli_synopses() -> list[tuple[str, list[str]]]:
    """Each ``spectral-vs SUBCOMMAND ...`` line of the README's shell blocks (a line ending
    in a backslash continues on the next): the subcommand and the options it names."""
    synopses = []
    for _, block in fenced_blocks("sh"):
        for line in block.replace("\\\n", " ").splitlines():
            words = line.split()
            if len(words) >= 2 and words[0] == "spectral-vs":
                synopses.append((words[1], sorted(set(re.findall(r"--[a-z][a-z-]*", line)))))
    return synopses


def test_the_readme_shows_the_command_line():
    assert {name for name, _ in cli_synopses()} >= {"align", "align-views", "demo", "servo-sim"}


@pytest.mark.parametrize("subcommand, options", cli_synopses(), ids=lambda v: str(v)[:40])
def test_command_line_options_in_the_readme_exist(subcommand, options, tmp_path):
    """Every option a README command line names is one its subcommand's --help lists."""
    if subcommand == "servo-sim":
        pytest.importorskip("pybullet")
    printed = run_cli([subcommand, "--help"], tmp_path)
    missing = [option for option in options if option not in printed]
    assert not missing, f"spectral-vs {subcommand} --help does not list {missing}"
