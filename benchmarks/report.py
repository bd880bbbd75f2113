"""What the benchmark scripts share: the machine, commit and build they ran on, table
and JSON formatting, common figures and the docs tables."""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
BENCHMARKS_DOC = ROOT / "docs" / "benchmarks.md"
#: Issue 14's targets for the servo step (everything the controller does with a capture,
#: 320 x 240, one core), CPU ms: the median and the 95th percentile.
SERVO_STEP_TARGETS_MS = (5.0, 15.0)


def cpu_model(default: str = "unknown CPU") -> str:
    """The CPU's model name from /proc/cpuinfo, else ``default``."""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return default


def machine() -> str:
    """CPU model, core count and kernel, for the record beside every timing."""
    return f"{cpu_model()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}"


def replace_block(path: Path, name: str, text: str) -> bool:
    """Put ``text`` between the ``<!-- name:begin -->`` and ``<!-- name:end -->`` markers."""
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    if not path.is_file() or begin not in path.read_text():
        return False
    head, rest = path.read_text().split(begin, 1)
    _, tail = rest.split(end, 1)
    path.write_text(f"{head}{begin}\n{text}\n{end}{tail}")
    return True


def median(values) -> float | None:
    """The median of the values that are not None, or None for none."""
    import numpy as np

    values = [v for v in values if v is not None]
    return float(np.median(values)) if values else None


def publish(name: str, text: str, path: Path = BENCHMARKS_DOC) -> None:
    """Print ``text`` and put it between the ``name`` markers of ``path``."""
    print(text)
    if replace_block(path, name, text):
        print(f"wrote the {name} block into {path.relative_to(ROOT)}")


def commit() -> str:
    """Short hash of the checked-out commit, or ``unknown`` outside a git checkout."""
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=ROOT, capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def core_sha256() -> str:
    """First 12 hex digits of the compiled module's hash (which build ran)."""
    import spectral_vs as svs

    return hashlib.sha256(Path(svs._core.__file__).read_bytes()).hexdigest()[:12]


def add_cases_per_cell(parser: Any, defaults: dict[str, int], note: str = "") -> None:
    """The ``--cases-per-cell`` option (None: each family's count in ``defaults``)."""
    parser.add_argument(
        "--cases-per-cell",
        type=int,
        default=None,
        help="cases per (family, angle) cell for every family (default: "
        + ", ".join(f"{k} {v}" for k, v in defaults.items())
        + f"{note})",
    )


# --- Tables -------------------------------------------------------------------------------


def auc(scores, labels) -> float | None:
    """ROC AUC as the Mann-Whitney statistic (ties count half); None without both classes."""
    import numpy as np

    scores, labels = np.asarray(scores, dtype=float), np.asarray(labels, dtype=bool)
    n_pos, n_neg = int(labels.sum()), int((~labels).sum())
    if n_pos == 0 or n_neg == 0:
        return None
    # Ranks from 1, ties given their mean rank: the positives' rank sum counts every
    # (positive, negative) pair the positive wins, ties half (O(n log n), for 10^5 steps).
    _, inverse, counts = np.unique(scores, return_inverse=True, return_counts=True)
    mean_rank = np.cumsum(counts) - (counts - 1) / 2.0
    wins = mean_rank[inverse][labels].sum() - n_pos * (n_pos + 1) / 2.0
    return float(wins / (n_pos * n_neg))


def pct(x: float | None) -> str:
    """A rate as a whole percentage, ``-`` for none."""
    return "-" if x is None else f"{100 * x:.0f}%"


def num(x: float | None, unit: str = "", scale: float = 1.0, digits: int = 2) -> str:
    """``scale * x`` with ``digits`` decimals and ``unit``, ``-`` for none."""
    return "-" if x is None else f"{scale * x:.{digits}f}{unit}"


def markdown(header: list[str], rows: list[list[str]]) -> str:
    """A markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])


# --- Results files ------------------------------------------------------------------------


def rounded(value):
    """Floats to 6 significant digits, recursively (keeps the JSON small and diffable);
    infinities and NaN as null."""
    if isinstance(value, float):
        return float(f"{value:.6g}") if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: rounded(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [rounded(v) for v in value]
    return value


def to_json(results: dict) -> str:
    """Summaries indented, then one line per record of ``results["records"]``."""
    head = json.dumps(rounded({k: v for k, v in results.items() if k != "records"}), indent=1)
    lines = ",\n".join(json.dumps(rounded(r)) for r in results["records"])
    return f'{head[:-2]},\n "records": [\n{lines}\n ]\n}}\n'


def write_results(
    results: dict, output: Path, default: Path, report: Callable[[dict], None]
) -> bool:
    """Write ``results`` (:func:`to_json`) to ``output``; if that is the script's
    ``default`` results file, also ``report(results)`` (figures and docs). Returns
    whether it reported."""
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(to_json(results))
    if output.resolve() != default.resolve():
        return False
    report(results)
    return True


# --- Figures ------------------------------------------------------------------------------


def success_by_angle(
    plt: Any,
    cells: list[dict],
    families: list[str],
    titles: dict[str, str],
    key: str,
    styles: dict[str, dict],
    labels: dict[str, str],
    size: tuple[float, float],
) -> tuple[Any, Any]:
    """One panel per family: the success rate (%) of ``cells`` against the initial
    rotation, one line per value of ``cells[i][key]`` in ``styles`` (drawn with its style,
    named by ``labels``). ``size``: width of a panel and height, inches."""
    fig, axes = plt.subplots(
        1, len(families), figsize=(size[0] * len(families), size[1]), sharey=True, squeeze=False
    )
    for ax, family in zip(axes[0], families, strict=True):
        for value, style in styles.items():
            chosen = [c for c in cells if c["family"] == family and c[key] == value]
            ax.plot(
                [c["angle_deg"] for c in chosen],
                [100 * c["success_rate"] for c in chosen],
                label=labels[value],
                **style,
            )
        ax.set_title(titles[family], fontsize=9)
        ax.set_xlabel("initial rotation (deg)")
        ax.set_xticks([0, 60, 120, 180])
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("success (%)")
    return fig, axes


def save_figure(fig: Any, path: Path, dpi: int = 110) -> Path:
    """Save ``fig`` to ``path`` and close it."""
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
