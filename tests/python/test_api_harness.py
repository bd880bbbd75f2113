"""The whole-range harness of the public API (tests/python/api_harness.py, issue 34), run in
a child process: every public callable with values at, inside and beyond its documented
ranges must return a finite answer or raise a documented exception, within 10 s and 1 GB a
call. A crash or a hang of the child names the call that caused it.

Examples per callable: SPECTRAL_VS_API_HARNESS_EXAMPLES, else half of
SPECTRAL_VS_HARNESS_EXAMPLES (the examples of test_properties.py's harness of one function,
for 89 callables here: ``make fuzz`` sets 2000, 1000 here, about 6 minutes on two cores),
else 20 (about 15 s); the harness scales them down for its slow calls (the alignments, the
servo, the global rotation search). The child's whole run is bounded by
SPECTRAL_VS_HARNESS_TIMEOUT seconds (default 120 + 1 s per example).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import api_harness

HARNESS = Path(api_harness.__file__).resolve()


def examples() -> int:
    if "SPECTRAL_VS_API_HARNESS_EXAMPLES" in os.environ:
        return int(os.environ["SPECTRAL_VS_API_HARNESS_EXAMPLES"])
    if "SPECTRAL_VS_HARNESS_EXAMPLES" in os.environ:
        return max(2, int(os.environ["SPECTRAL_VS_HARNESS_EXAMPLES"]) // 2)
    return 20


EXAMPLES = examples()
TIMEOUT = float(os.environ.get("SPECTRAL_VS_HARNESS_TIMEOUT", str(120 + 1.0 * EXAMPLES)))


def test_every_public_callable_has_an_entry_or_a_reasoned_exclusion():
    api_harness.check_coverage()
    assert api_harness.EXCLUDED == {} or all(api_harness.EXCLUDED.values())
    assert set(api_harness.TABLE) | set(api_harness.EXCLUDED) == set(api_harness.public_callables())


def last_call(path: Path) -> str:
    recorded = api_harness.read_last_call(path)
    return f"{recorded.get('entry')}: {recorded.get('call')}"


def test_public_api_over_whole_ranges(tmp_path):
    report, last = tmp_path / "report.jsonl", tmp_path / "last_call.json"
    command = [sys.executable, str(HARNESS), "--examples", str(EXAMPLES)]
    command += ["--report", str(report), "--last-call", str(last)]
    # Its own session: on a timeout the supervisor and its worker are killed together.
    child = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        errors="replace",
        start_new_session=True,
    )
    try:
        output, _ = child.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        child.communicate()
        raise AssertionError(
            f"the harness did not finish within {TIMEOUT:g} s; last call: {last_call(last)}"
        ) from None
    if child.returncode < 0:
        raise AssertionError(
            f"the harness died by signal {signal.Signals(-child.returncode).name}; "
            f"last call: {last_call(last)}"
        )
    lines = [json.loads(line) for line in report.read_text().splitlines() if line.strip()]
    findings = [line for line in lines if "finding" in line]
    summary = [
        line
        for line in output.splitlines()
        if line.startswith(("api_harness:", "  [", "      after:"))
    ]
    assert child.returncode == 0 and not findings, (
        f"the harness exited with status {child.returncode}, {len(findings)} findings "
        f"(each names its call):\n" + "\n".join(summary or output.splitlines()[-40:])
    )
