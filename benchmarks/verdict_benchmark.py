"""The verdict of issue 32 on its calibration and validation sets (benchmarks/verdict_sets.py).

Every problem of both sets is registered once, one thread in one process, and recorded
(one JSON line per problem in ``benchmarks/results/verdict.jsonl``: the estimate's errors,
whether it is right, the raw ``score``, and ``confidence``, ``reliable``, ``status``,
``covariance`` when the result has them; a stopped run resumes where it stopped). Then:

* **Calibration** (calibration set only), per kind (``align``, ``views``): the isotonic
  regression of P(right | score) (pool adjacent violators; answers the library's gates
  refuse, status ``max_seconds`` / ``bad_scale`` / ``no_support``, left out), reduced to at most
  :data:`MAX_KNOTS` knots (score, probability) from (0, p0) to (1, p1) for piecewise-linear
  interpolation; the threshold on that calibrated confidence that keeps the most right
  answers while at most 1% of the reliable ones are wrong; the factor k of the covariance
  that makes the mean NEES of the right answers 6. Written to
  ``benchmarks/results/verdict_calibration.json`` and printed as C++ for the library.
* **Validation** (validation set only; nothing is fitted there), per kind and family: ROC
  AUC of ``score`` and of ``confidence``, the expected calibration error of
  ``confidence``, the share of reliable answers that are wrong, the share of right answers
  that are reliable, the problems without a right answer that came back reliable, and the
  mean NEES of the right answers. Read twice when the results carry the verdict's fields
  (``reliable``, ``confidence``, ``covariance``): as the library returned them
  (``library``), and with the calibration above applied to ``score`` (``fitted``:
  reliable = confidence >= threshold, not ambiguous, determined, not floating, status not
  ``max_seconds`` / ``bad_scale`` / ``no_support``; NEES with the covariance times k),
  what the library returns once the knots are pasted. Without those fields only the
  second: the offline emulation, marked ``emulated`` in every table. Written to
  ``benchmarks/results/verdict_validation.json``, ``docs/figures/verdict_reliability.png``
  (reliability diagrams), stdout, and between ``<!-- verdict:begin -->`` and
  ``<!-- verdict:end -->`` of ``--doc`` (docs/trust.md by default) when it has them.

The raw score: ``result.score`` when the result has one; before that, ``align``'s
``confidence`` and, for ``align_views``, ``svs.verify_pose(reference, current, T,
voxel_size=result.scale.voxel_size, sensor_origin=<current's>).confidence``.

Usage (one command; about 4 minutes of one core: 3.5 min at commit ed7245d)::

    nice -n 10 python benchmarks/verdict_benchmark.py              # both sets, then report
    python benchmarks/verdict_benchmark.py --quick                 # 2 per family, writes nothing
    python benchmarks/verdict_benchmark.py --set calibration       # one set (resumes)
    python benchmarks/verdict_benchmark.py --report-only           # tables from the JSONL
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

if __name__ == "__main__":  # one thread; not when the tests import the functions
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cases as case_lib
import report as report_lib
import verdict_sets as sets_lib
from report import auc, markdown, pct

import spectral_vs as svs

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "results" / "verdict.jsonl"
CALIBRATION = ROOT / "benchmarks" / "results" / "verdict_calibration.json"
VALIDATION = ROOT / "benchmarks" / "results" / "verdict_validation.json"
FIGURE = ROOT / "docs" / "figures" / "verdict_reliability.png"
DOC = ROOT / "docs" / "trust.md"
MARKER = "verdict"
MAX_KNOTS = 12
MAX_WRONG_SHARE = 0.01
TARGET_MEAN_NEES = 6.0
ECE_BINS = 10
QUICK_PER_FAMILY = 2


# --- Running one problem -------------------------------------------------------------------


def _field(result, name: str):
    """A verdict field of the result, None when the installed library lacks it."""
    value = getattr(result, name, None)
    return None if callable(value) else value


def _call(case: sets_lib.VerdictCase):
    """Register the case as a user would: one thread, the target's sensor origin."""
    origin = case.sensor_origin
    if case.spec.kind == "align":
        view = (
            {"sensor_origin": origin, "scene_view": "single_view"}
            if np.all(np.isfinite(origin))
            else {"scene_view": "all_sides"}
        )
        return svs.align(case.source, case.target, threads=1, **view, **case.settings)
    return svs.align_views(
        case.source,
        case.target,
        sensor_origin=origin,
        reference_sensor_origin=case.reference_origin,
        threads=1,
        **case.settings,
    )


def _estimate(case: sets_lib.VerdictCase, result) -> np.ndarray:
    name = "T_scene_model" if case.spec.kind == "align" else "T_current_reference"
    return np.asarray(getattr(result, name), dtype=float)


def raw_score(case: sets_lib.VerdictCase, result, T: np.ndarray) -> tuple[float, str]:
    """The uncalibrated score and where it came from."""
    score = _field(result, "score")
    if score is not None:
        return float(score), "result.score"
    if case.spec.kind == "align":
        return float(result.confidence), "align confidence"
    origin = case.sensor_origin
    verified = svs.verify_pose(
        case.source, case.target, T, voxel_size=result.scale.voxel_size, sensor_origin=origin
    )
    return float(verified.confidence), "verify_pose confidence"


def _verdict_fields(result) -> dict:
    """The verdict's fields when present (None otherwise), and what today's result says."""
    covariance = _field(result, "covariance")
    alternatives = _field(result, "alternatives")
    reliable = _field(result, "reliable")
    return {
        "api": "verdict" if reliable is not None else "before verdict",
        "confidence": None if reliable is None else float(result.confidence),
        "reliable": None if reliable is None else bool(reliable),
        "status": None if reliable is None else _field(result, "status"),
        "determined": _field(result, "determined"),
        "rests": _field(result, "rests"),  # align only: False for a floating pose
        "ambiguous": bool(_field(result, "ambiguous") or False),
        "alternatives": 0 if alternatives is None else len(alternatives),
        "covariance": None if covariance is None else np.asarray(covariance).tolist(),
    }


def _alternative_fields(case: sets_lib.VerdictCase, result, T: np.ndarray) -> dict:
    """Per alternative: its score, whether it is right, and whether it is the returned
    answer again up to an exact symmetry of the object (then not a different answer)."""
    name = "T_scene_model" if case.spec.kind == "align" else "T_current_reference"
    out = []
    for alternative in _field(result, "alternatives") or []:
        A = np.asarray(getattr(alternative, name), dtype=float)
        again = SimpleNamespace(model_center=case.center, T_true=T, symmetries=case.symmetries)
        rotation, translation = case_lib.pose_error(again, A)
        out.append(
            {
                "score": _field(alternative, "score"),
                "symmetric": _field(alternative, "symmetric"),
                "right": bool(sets_lib.is_right(case, A)),
                "symmetric_twin": bool(
                    rotation < sets_lib.RIGHT_DEG and translation < sets_lib.RIGHT_M
                ),
            }
        )
    return {"alternative_poses": out}


def _truth_fields(case: sets_lib.VerdictCase, T: np.ndarray) -> dict:
    errors = sets_lib.pose_errors(case, T)
    if errors is None:
        return {
            "right": False,
            "rotation_error_deg": None,
            "translation_error_m": None,
            "error_vector": None,
        }
    truth = sets_lib.nearest_truth(case, T)
    return {
        "right": bool(sets_lib.is_right(case, T)),
        "rotation_error_deg": errors[0],
        "translation_error_m": errors[1],
        "error_vector": sets_lib.left_error(truth, T).tolist(),
    }


def _extra_fields(case: sets_lib.VerdictCase, result) -> dict:
    """What today's results say beside the score, for comparison."""
    if case.spec.kind == "align":
        return {
            "fitness": float(result.fitness),
            "voxel_size_m": float(result.voxel_size),
            "stop_reason": result.stop_reason,
        }
    return {
        "support_score": float(result.support.score),
        "voxel_size_m": float(result.scale.voxel_size),
        "view_status": result.status,
    }


def _case_fields(case: sets_lib.VerdictCase) -> dict:
    s = case.spec
    return {
        "case_id": s.case_id,
        "set": s.set_name,
        "kind": s.kind,
        "family": s.family,
        "seed": s.seed,
        "has_truth": case.has_truth,
        "source_points": len(case.source),
        "target_points": len(case.target),
        "settings": case.settings,
        "info": {k: v for k, v in case.info.items() if not k.startswith("T_")},
    }


def run_case(spec: sets_lib.Spec) -> dict:
    """Build and register one problem; its record (CPU seconds of the call alone)."""
    start = time.process_time()
    case = sets_lib.build_case(spec)
    record = _case_fields(case) | {"build_cpu_s": time.process_time() - start}
    start = time.process_time()
    try:
        result = _call(case)
    except (ValueError, RuntimeError, MemoryError) as error:
        return record | {
            "error": f"{type(error).__name__}: {error}",
            "score": None,
            "right": False,
            "cpu_s": time.process_time() - start,
        }
    cpu = time.process_time() - start
    T = _estimate(case, result)
    score, source = raw_score(case, result, T)
    return (
        record
        | {"cpu_s": cpu, "score": score, "score_source": source}
        | _verdict_fields(result)
        | _truth_fields(case, T)
        | _alternative_fields(case, result, T)
        | _extra_fields(case, result)
    )


def run_sets(set_names: list[str], per_family: int | None, out: Path | None) -> list[dict]:
    """Every problem of the sets; with ``out``, records already there are kept and skipped
    and new ones appended as they come."""
    done = {r["case_id"]: r for r in read_records(out)} if out else {}
    commit, build = report_lib.commit(), report_lib.core_sha256()
    records = []
    for set_name in set_names:
        for spec in sets_lib.specs(set_name, per_family):
            if spec.case_id in done:
                records.append(done[spec.case_id])
                continue
            record = run_case(spec) | {"commit": commit, "build": build}
            records.append(record)
            if out:
                with out.open("a") as stream:
                    stream.write(json.dumps(report_lib.rounded(record)) + "\n")
            print(_progress_line(record), flush=True)
    return records


def _progress_line(r: dict) -> str:
    if r.get("error"):
        return f"{r['case_id']:36s} error {r['error'][:80]}"
    errors = (
        "no truth"
        if r["rotation_error_deg"] is None
        else f"{r['rotation_error_deg']:7.2f} deg {1000 * r['translation_error_m']:8.1f} mm"
    )
    return (
        f"{r['case_id']:36s} {'right' if r['right'] else 'WRONG'} {errors}  "
        f"score {r['score']:.3f}  {r['cpu_s']:.2f} s"
    )


def read_records(path: Path | None) -> list[dict]:
    if path is None or not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


# --- Isotonic calibration ------------------------------------------------------------------


def pav(x: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """Isotonic (non-decreasing) least-squares fit of y on x by pool adjacent violators.

    Equal x values are pooled first (one fitted value per distinct x). Returns the
    distinct x (sorted), their fitted values, and their weights (summed ``w``)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    w = np.ones_like(x) if w is None else np.asarray(w, dtype=float)
    xs, inverse = np.unique(x, return_inverse=True)
    weights = np.bincount(inverse, weights=w)
    means = np.bincount(inverse, weights=w * y) / weights
    blocks: list[list[float]] = []  # [weighted sum, weight, count of distinct x]
    for m, wt in zip(means, weights, strict=True):
        blocks.append([m * wt, wt, 1])
        while len(blocks) > 1 and blocks[-2][0] / blocks[-2][1] > blocks[-1][0] / blocks[-1][1]:
            s, wt2, n = blocks.pop()
            blocks[-1][0] += s
            blocks[-1][1] += wt2
            blocks[-1][2] += n
    fitted = np.concatenate([np.full(int(n), s / wt) for s, wt, n in blocks])
    return xs, fitted, weights


def _block_knots(xs: np.ndarray, fitted: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """One knot per block of equal fitted values (its weighted mean score), framed by
    (0, first value) and (1, last value)."""
    knots = [(0.0, fitted[0])]
    starts = np.flatnonzero(np.r_[True, np.diff(fitted) != 0.0])
    for a, b in zip(starts, np.r_[starts[1:], len(xs)], strict=True):
        knots.append((float(np.average(xs[a:b], weights=weights[a:b])), float(fitted[a])))
    knots.append((1.0, fitted[-1]))
    merged: list[tuple[float, float]] = []
    for k in knots:  # a block at score 0 or 1 is the end knot itself
        if merged and k[0] <= merged[-1][0] + 1e-12:
            merged[-1] = (merged[-1][0], max(merged[-1][1], k[1]))
        else:
            merged.append(k)
    merged[-1] = (1.0, merged[-1][1])
    return np.array(merged)


def reduce_knots(knots: np.ndarray, xs, fitted, weights, max_knots: int = MAX_KNOTS) -> np.ndarray:
    """Drop interior knots one at a time, each time the one whose removal changes the
    interpolated curve least at the data (weighted squared error against the isotonic
    fit), until ``max_knots`` remain. A subset of monotone knots stays monotone."""
    knots = knots.copy()
    while len(knots) > max_knots:
        costs = []
        for i in range(1, len(knots) - 1):
            trial = np.delete(knots, i, axis=0)
            curve = np.interp(xs, trial[:, 0], trial[:, 1])
            costs.append(float(np.sum(weights * (curve - fitted) ** 2)))
        knots = np.delete(knots, 1 + int(np.argmin(costs)), axis=0)
    return knots


def fit_calibration(scores: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Knots (score, probability) of P(right | score): the isotonic fit, kept within
    [1 / (N + 2), (N + 1) / (N + 2)] for N answers: a finite sample never warrants a
    probability of exactly 0 or 1 (Laplace's rule at the ends)."""
    xs, fitted, weights = pav(scores, right.astype(float))
    n = float(len(scores))
    fitted = np.clip(fitted, 1.0 / (n + 2.0), (n + 1.0) / (n + 2.0))
    return reduce_knots(_block_knots(xs, fitted, weights), xs, fitted, weights)


def calibrated(scores: np.ndarray, knots: np.ndarray) -> np.ndarray:
    return np.interp(scores, knots[:, 0], knots[:, 1])


#: Statuses the library never calls reliable, whatever the confidence.
GATED_STATUSES = ("max_seconds", "bad_scale", "no_support")


def eligible(record: dict) -> bool:
    """Whether an answer can be reliable at all: not ambiguous, determined (the scene pins
    the pose down), not floating (it rests when the scene has a support plane), and not
    stopped by the library's gates (time, voxel scale, no support) when the results name
    them."""
    return (
        not record.get("ambiguous", False)
        and record.get("determined") is not False
        and record.get("rests") is not False
        and record.get("status") not in GATED_STATUSES
    )


def reliable_shares(conf, right, can_be_reliable, threshold: float) -> dict:
    """Counts and shares of the answers taken as reliable at ``threshold``."""
    reliable = (conf >= threshold) & can_be_reliable
    n_reliable, n_right = int(reliable.sum()), int(right.sum())
    wrong = int((reliable & ~right).sum())
    return {
        "reliable": n_reliable,
        "wrong_reliable": wrong,
        "wrong_share_of_reliable": wrong / n_reliable if n_reliable else None,
        "right_share_reliable": int((reliable & right).sum()) / n_right if n_right else None,
    }


def choose_threshold(
    conf, right, can_be_reliable, max_wrong_share: float = MAX_WRONG_SHARE
) -> float:
    """The threshold on the confidence that keeps the most right answers reliable with at
    most ``max_wrong_share`` of the reliable ones wrong (ties: the higher threshold; only
    answers in ``can_be_reliable`` count); above
    every confidence when none qualifies."""
    best, best_kept = math.nextafter(float(np.max(conf, initial=1.0)), math.inf), -1
    for t in np.unique(conf)[::-1]:
        shares = reliable_shares(conf, right, can_be_reliable, float(t))
        if shares["reliable"] == 0 or shares["wrong_share_of_reliable"] > max_wrong_share:
            continue
        kept = shares["reliable"] - shares["wrong_reliable"]
        if kept > best_kept:
            best, best_kept = float(t), kept
    return best


def squared_mahalanobis(error: np.ndarray, covariance: np.ndarray) -> float:
    """e^T C^-1 e (a pseudo-inverse for a singular C)."""
    return float(error @ np.linalg.pinv(covariance, hermitian=True) @ error)


#: Families left out of the covariance's fit: a voxel ten times too small pairs points
#: only within a tenth of the sane distance, and its residuals, truncated there, say
#: nothing of the error (such answers score low: none of them is reliable).
NOT_FOR_COVARIANCE = ("wrong_voxel",)


def inflation_factor(records: list[dict], kind: str) -> float | None:
    """The library's k for ``kind`` with which the mean NEES e^T (k C)^-1 e is 6 over the
    right answers (the families of NOT_FOR_COVARIANCE left out): the factor that makes
    the result's covariance so, times the k it was computed with."""
    values = [
        squared_mahalanobis(np.array(r["error_vector"]), np.array(r["covariance"]))
        for r in records
        if r["right"] and r.get("covariance") is not None and r["family"] not in NOT_FOR_COVARIANCE
    ]
    if not values:
        return None
    return float(current_inflation(kind) * np.mean(values) / TARGET_MEAN_NEES)


# --- Metrics -------------------------------------------------------------------------------


def _bins(conf: np.ndarray) -> np.ndarray:
    return np.minimum((conf * ECE_BINS).astype(int), ECE_BINS - 1)


def expected_calibration_error(conf: np.ndarray, right: np.ndarray) -> float | None:
    """Sum over 10 equal-width bins of (bin share) x |mean confidence - share right|."""
    if len(conf) == 0:
        return None
    index = _bins(conf)
    total = 0.0
    for b in np.unique(index):
        sel = index == b
        total += sel.mean() * abs(conf[sel].mean() - right[sel].mean())
    return float(total)


#: The two readings of the validation set: the verdict the installed library returned, and
#: the calibration fitted here applied to the raw score (what the library returns once the
#: knots are pasted; the offline emulation when the results have no verdict).
MODES = ("library", "fitted")


def with_verdict(records: list[dict], calibration: dict, mode: str) -> list[dict]:
    """Records with ``confidence`` and ``reliable`` of ``mode`` and ``verdict_source``:
    ``library`` (the result's own), ``emulated`` (the fitted knots and threshold applied
    to the score; reliable = confidence >= threshold, not ambiguous, not gated), or
    ``error`` (no answer: never reliable). In ``library`` mode, records without the
    verdict's fields are emulated."""
    out = []
    for r in records:
        r = dict(r)
        if r.get("score") is None:
            r |= {"confidence": None, "reliable": False, "verdict_source": "error"}
        elif mode == "library" and r.get("reliable") is not None:
            r["verdict_source"] = "library"
        else:
            fit = calibration[r["kind"]]
            conf = float(calibrated(np.array([r["score"]]), np.array(fit["knots"]))[0])
            reliable = conf >= fit["threshold"] and eligible(r)
            r |= {"confidence": conf, "reliable": bool(reliable), "verdict_source": "emulated"}
        out.append(r)
    return out


def nees_values(records: list[dict], k: float | None, every_family: bool = False) -> list[float]:
    """NEES of the right answers with a covariance, the covariance scaled by ``k``; the
    families of NOT_FOR_COVARIANCE only with ``every_family``."""
    scale = 1.0 if k is None else k
    return [
        squared_mahalanobis(np.array(r["error_vector"]), scale * np.array(r["covariance"]))
        for r in records
        if r["right"]
        and r.get("covariance") is not None
        and (every_family or r["family"] not in NOT_FOR_COVARIANCE)
    ]


def current_inflation(kind: str) -> float:
    """The k the installed library computes its covariances with (1 before it had one)."""
    return svs.covariance_inflation(kind) if hasattr(svs, "covariance_inflation") else 1.0


def _share(part: np.ndarray, whole: np.ndarray) -> float | None:
    return float((part & whole).sum() / whole.sum()) if whole.any() else None


def group_metrics(rows: list[dict], k: float | None) -> dict:
    """The validation figures of one group of records (verdicts already attached); NEES
    with the covariance times ``k``."""
    scored = [r for r in rows if r.get("score") is not None]
    right = np.array([r["right"] for r in scored], dtype=bool)
    score = np.array([r["score"] for r in scored])
    conf = np.array([r["confidence"] for r in scored])
    reliable = np.array([r["reliable"] for r in rows], dtype=bool)
    is_right = np.array([r["right"] for r in rows], dtype=bool)
    no_truth = np.array([not r["has_truth"] for r in rows], dtype=bool)
    ambiguous = np.array([r.get("ambiguous", False) for r in rows], dtype=bool)
    # A group of one family (the wrong voxels' own row) keeps it; "all" leaves those out.
    nees = nees_values(rows, k, every_family=len({r["family"] for r in rows}) == 1)
    return {
        "cases": len(rows),
        "errors": len(rows) - len(scored),
        "right": int(is_right.sum()),
        "no_truth": int(no_truth.sum()),
        "auc_score": auc(score, right),
        "auc_confidence": auc(conf, right),
        "ece": expected_calibration_error(conf, right),
        "reliable": int(reliable.sum()),
        "wrong_share_of_reliable": _share(~is_right, reliable),
        "right_share_reliable": _share(reliable, is_right),
        "right_share_ambiguous": _share(ambiguous, is_right),
        "no_truth_reliable": int((reliable & no_truth).sum()),
        "mean_nees": float(np.mean(nees)) if nees else None,
        "median_nees": float(np.median(nees)) if nees else None,
        "nees_count": len(nees),
    }


# --- Calibration and validation from the records -------------------------------------------


def _calibration_rows(records: list[dict], kind: str) -> list[dict]:
    """The calibration set's answers of a kind, but those the library's gates already
    refuse (``max_seconds``, ``bad_scale``, ``no_support``): a voxel ten times too large
    scores 1.0 and is wrong, and would pull P(right | 1.0) down for every answer the
    gates let through."""
    return [
        r
        for r in records
        if r["set"] == "calibration"
        and r["kind"] == kind
        and r.get("score") is not None
        and r.get("status") not in GATED_STATUSES
    ]


def _arrays(rows: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scores, right, and whether each answer can be reliable at all."""
    return (
        np.array([r["score"] for r in rows]),
        np.array([r["right"] for r in rows], dtype=bool),
        np.array([eligible(r) for r in rows], dtype=bool),
    )


def calibrate(records: list[dict]) -> dict:
    """Per kind: knots, threshold (and its shares on the calibration set), k."""
    out = {}
    for kind in sets_lib.KINDS:
        rows = _calibration_rows(records, kind)
        if not rows:
            continue
        scores, right, can = _arrays(rows)
        knots = fit_calibration(scores, right)
        conf = calibrated(scores, knots)
        # The library's one threshold on the probability of being right; the lowest that
        # keeps at most 1% of reliable answers wrong here is reported beside it.
        threshold = float(svs.RELIABLE_CONFIDENCE)
        lowest = choose_threshold(conf, right, can)
        out[kind] = {
            "cases": len(rows),
            "right": int(right.sum()),
            "knots": knots.tolist(),
            "threshold": threshold,
            "threshold_at_most_1pct_wrong": lowest,
            "calibration_shares": reliable_shares(conf, right, can, threshold),
            "calibration_shares_at_most_1pct_wrong": reliable_shares(conf, right, can, lowest),
            "right_share_eligible": _share(can, right),
            "covariance_inflation": inflation_factor(rows, kind),
            "ece_on_calibration": expected_calibration_error(conf, right),
        }
    return out


def shared_threshold(records: list[dict], calibration: dict) -> dict | None:
    """One threshold for both kinds (the library reads one, ``kReliableConfidence``): the
    same rule on both kinds' calibrated confidences pooled, and its shares per kind."""
    kinds = [k for k in sets_lib.KINDS if k in calibration]
    if not kinds:
        return None
    parts = {k: _arrays(_calibration_rows(records, k)) for k in kinds}
    conf = {k: calibrated(p[0], np.array(calibration[k]["knots"])) for k, p in parts.items()}
    threshold = choose_threshold(
        np.concatenate([conf[k] for k in kinds]),
        np.concatenate([parts[k][1] for k in kinds]),
        np.concatenate([parts[k][2] for k in kinds]),
    )
    shares = {k: reliable_shares(conf[k], parts[k][1], parts[k][2], threshold) for k in kinds}
    return {"threshold": threshold, "shares": shares}


def validate(records: list[dict], calibration: dict, mode: str) -> dict:
    """Per kind, all families together and each family: :func:`group_metrics`."""
    rows = with_verdict([r for r in records if r["set"] == "validation"], calibration, mode)
    out = {}
    for kind in sets_lib.KINDS:
        of_kind = [r for r in rows if r["kind"] == kind]
        if not of_kind or kind not in calibration:
            continue
        # The library's covariance as it comes; the fitted one times the fitted k.
        fitted = calibration[kind]["covariance_inflation"]
        k = 1.0 if mode == "library" or fitted is None else fitted / current_inflation(kind)
        sources = sorted({r["verdict_source"] for r in of_kind} - {"error"})
        groups = {"all": of_kind} | {
            f: [r for r in of_kind if r["family"] == f]
            for f in sets_lib.FAMILY_COUNTS[kind]
            if any(r["family"] == f for r in of_kind)
        }
        out[kind] = {
            "verdict_source": sources,
            "groups": {name: group_metrics(g, k) for name, g in groups.items()},
            "confident_wrong": _confident_wrong(of_kind),
            "ambiguous_right": _ambiguity(of_kind),
        }
    return out


def _ambiguity(rows: list[dict]) -> dict:
    """Right answers flagged ambiguous: how many, and how many only by alternatives that
    are the same answer up to an exact symmetry, or by a right alternative."""
    flagged = [r for r in rows if r["right"] and r.get("ambiguous")]
    alternatives = [r.get("alternative_poses") or [] for r in flagged]
    return {
        "right": sum(r["right"] for r in rows),
        "flagged": len(flagged),
        "only_symmetric_twins": sum(
            bool(a) and all(x["symmetric_twin"] for x in a) for a in alternatives
        ),
        "only_right_alternatives": sum(
            bool(a) and all(x["right"] for x in a) for a in alternatives
        ),
        "without_alternatives": sum(not a for a in alternatives),
    }


def _confident_wrong(rows: list[dict]) -> list[dict]:
    """The wrong answers taken as reliable or scored over 0.9, highest score first."""
    bad = [
        r
        for r in rows
        if r.get("score") is not None and not r["right"] and (r["reliable"] or r["score"] > 0.9)
    ]
    bad.sort(key=lambda r: -r["score"])
    return [
        {
            "case_id": r["case_id"],
            "score": r["score"],
            "confidence": r["confidence"],
            "reliable": r["reliable"],
            "rotation_error_deg": r.get("rotation_error_deg"),
            "translation_error_m": r.get("translation_error_m"),
        }
        for r in bad
    ]


# --- Output --------------------------------------------------------------------------------


def machine() -> dict:
    """nproc, the CPU model and the commit, for the record beside every table."""
    # GNU nproc honours OMP_NUM_THREADS, which this script sets to 1: ask without it.
    env = {k: v for k, v in os.environ.items() if not k.startswith("OMP_")}
    try:
        nproc = subprocess.run(
            ["nproc"], capture_output=True, text=True, check=True, env=env
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        nproc = str(os.cpu_count())
    return {
        "nproc": int(nproc.strip()),
        "cpu": report_lib.cpu_model(),
        "commit": report_lib.commit(),
    }


def cpp_snippet(calibration: dict, shared: dict | None, stamp: str) -> str:
    """The fitted calibration as C++ for cpp/src/alignment/calibration_maps.inc (its names:
    kObjectMap, kViewMap of ``{score, probability}`` knots, the inflations) and the
    threshold for kReliableConfidence (verdict.hpp)."""
    names = {"align": ("kObjectMap", "kObjectInflation"), "views": ("kViewMap", "kViewInflation")}
    lines = [f"// Fitted by benchmarks/verdict_benchmark.py on its calibration set ({stamp})"]
    for kind, fit in calibration.items():
        knots = names[kind][0]
        pairs = ", ".join(f"{{{s:.4f}, {p:.4f}}}" for s, p in fit["knots"])
        lines.append(f"constexpr Knot {knots}[] = {{{pairs}}};")
    for kind, fit in calibration.items():
        k = fit["covariance_inflation"]
        value = f"{k:.4g};" if k is not None else "1.0;  // no covariance in the results yet"
        lines.append(f"constexpr double {names[kind][1]} = {value}")
    per_kind = ", ".join(
        f"{kind} alone {fit['threshold']:.4f}" for kind, fit in calibration.items()
    )
    if shared is not None:
        lines.append(
            f"inline constexpr double kReliableConfidence = {shared['threshold']:.4f};"
            f"  // one for both kinds; {per_kind}"
        )
    return "\n".join(lines)


def _f(x, digits: int = 3) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def calibration_table(calibration: dict, shared: dict | None) -> str:
    rows = []
    for kind, fit in calibration.items():
        shares = fit["calibration_shares"]
        both = shared["shares"][kind] if shared else None
        rows.append(
            [
                kind,
                f"{fit['cases']} ({fit['right']})",
                str(len(fit["knots"])),
                _f(fit["threshold"]),
                f"{pct(shares['wrong_share_of_reliable'])} / {pct(shares['right_share_reliable'])}",
                "-"
                if both is None
                else f"{pct(both['wrong_share_of_reliable'])} / "
                f"{pct(both['right_share_reliable'])}",
                pct(fit["right_share_eligible"]),
                _f(fit["ece_on_calibration"]),
                _f(fit["covariance_inflation"], 2),
            ]
        )
    shared_label = "-" if shared is None else f"{shared['threshold']:.3f}"
    header = [
        "kind",
        "cases (right)",
        "knots",
        "threshold",
        "wrong among reliable / right taken as reliable",
        f"the same at one threshold for both kinds ({shared_label})",
        "right answers not ambiguous nor gated (the ceiling)",
        "ECE",
        "covariance factor k",
    ]
    return markdown(header, rows)


def validation_table(validation: dict) -> str:
    header = [
        "kind",
        "family",
        "cases (right / no truth / errors)",
        "AUC score",
        "AUC confidence",
        "ECE",
        "wrong among reliable (<= 1%)",
        "right taken as reliable (>= 90%)",
        "right flagged ambiguous",
        "no-truth reliable (0)",
        "NEES mean / median (3-12)",
        "verdict",
    ]
    rows = []
    for kind, v in validation.items():
        source = "/".join(v["verdict_source"])
        for name, g in v["groups"].items():
            rows.append(
                [
                    kind,
                    f"**{name}**" if name == "all" else name,
                    f"{g['cases']} ({g['right']} / {g['no_truth']} / {g['errors']})",
                    _f(g["auc_score"]),
                    _f(g["auc_confidence"]),
                    _f(g["ece"]),
                    pct(g["wrong_share_of_reliable"]),
                    pct(g["right_share_reliable"]),
                    pct(g["right_share_ambiguous"]),
                    str(g["no_truth_reliable"]),
                    f"{_f(g['mean_nees'], 1)} / {_f(g['median_nees'], 1)}",
                    source,
                ]
            )
    return markdown(header, rows)


def knots_table(calibration: dict) -> str:
    rows = [
        [kind, " ".join(f"({s:.3f}, {p:.3f})" for s, p in fit["knots"])]
        for kind, fit in calibration.items()
    ]
    return markdown(["kind", "knots (score, P(right))"], rows)


def confident_wrong_text(validation: dict) -> str:
    lines = []
    for kind, v in validation.items():
        for r in v["confident_wrong"]:
            errors = (
                "no right answer"
                if r["rotation_error_deg"] is None
                else f"{r['rotation_error_deg']:.1f} deg, {1000 * r['translation_error_m']:.1f} mm"
            )
            verdict = "reliable" if r["reliable"] else "not reliable"
            lines.append(
                f"- `{r['case_id']}` ({kind}): score {r['score']:.3f}, confidence "
                f"{r['confidence']:.3f}, {verdict}; {errors}"
            )
    return "\n".join(lines) if lines else "None."


def ambiguity_text(validation: dict) -> str:
    lines = []
    for kind, v in validation.items():
        a = v["ambiguous_right"]
        lines.append(
            f"- {kind}: {a['flagged']} of {a['right']} right answers flagged ambiguous; of "
            f"those, {a['only_symmetric_twins']} only by alternatives that are the same answer "
            f"up to an exact symmetry, {a['only_right_alternatives']} only by right "
            f"alternatives, {a['without_alternatives']} without any alternative listed."
        )
    return "\n".join(lines)


MODE_TITLES = {
    "library": "the verdict of the installed library, as it returned it (NEES with its "
    "covariance as returned)",
    "fitted": "the calibration fitted above applied to the raw score: reliable = confidence "
    ">= its kind's threshold, not ambiguous, determined, not floating, status not max_seconds / "
    "bad_scale / no_support "
    "(NEES with the covariance times the fitted k). `emulated` marks these figures: the "
    "offline emulation, what the library returns once the knots are pasted",
}


def tables(calibration: dict, shared: dict | None, validations: dict, stamp: str) -> str:
    parts = [
        stamp,
        "Calibration (calibration set only):",
        calibration_table(calibration, shared),
        knots_table(calibration),
    ]
    for mode, validation in validations.items():
        parts += [
            f"Validation (validation set only, nothing fitted there): {MODE_TITLES[mode]}.",
            validation_table(validation),
            "Wrong answers taken as reliable or scored over 0.9:",
            confident_wrong_text(validation),
        ]
    parts += ["Right answers flagged ambiguous (validation):", ambiguity_text(validation)]
    return "\n\n".join(parts)


def write_doc(path: Path, text: str) -> bool:
    """The tables between the verdict markers of ``path``, when it has them."""
    return report_lib.replace_block(path, MARKER, text)


def reliability_panel(ax, conf: np.ndarray, right: np.ndarray, title: str) -> None:
    """Observed share right against the confidence of 10 equal bins, with counts."""
    ax.plot([0, 1], [0, 1], ":", color="grey", label="perfect calibration")
    right = np.asarray(right, dtype=float)
    index = _bins(conf)
    for b in np.unique(index):
        sel = index == b
        y = right[sel].mean()
        ax.bar((b + 0.5) / ECE_BINS, y, width=0.9 / ECE_BINS, color="tab:blue", alpha=0.5)
        ax.plot(conf[sel].mean(), y, "o", color="tab:red")
        ax.annotate(str(int(sel.sum())), ((b + 0.5) / ECE_BINS, y), ha="center", va="bottom")
    ax.set(title=title, xlim=(0, 1), ylim=(0, 1.1), xlabel="confidence", ylabel="share right")
    ax.legend(loc="upper left", fontsize=8)


def plot_reliability(rows_by_mode: dict[str, list[dict]], path: Path) -> None:
    """Per mode (row) and kind (column): the reliability diagram of the validation set
    (bars: share right per confidence bin, dots at the bin's mean confidence; counts)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = list(rows_by_mode)
    fig, axes = plt.subplots(
        len(modes), len(sets_lib.KINDS), figsize=(10, 4.2 * len(modes)), squeeze=False
    )
    for i, mode in enumerate(modes):
        for j, kind in enumerate(sets_lib.KINDS):
            rows = [
                r
                for r in rows_by_mode[mode]
                if r["kind"] == kind and r.get("confidence") is not None
            ]
            conf = np.array([r["confidence"] for r in rows])
            right = np.array([r["right"] for r in rows])
            title = f"{kind}, {mode} ({len(rows)} answers)"
            reliability_panel(axes[i][j], conf, right, title)
    fig.tight_layout()
    report_lib.save_figure(fig, path)


def report(records: list[dict], write: bool, doc: Path) -> None:
    """Calibration, validation, tables; with ``write``, the JSON files, figure and doc."""
    host = machine()
    commits = sorted({r.get("commit", "unknown") for r in records})
    builds = sorted({r.get("build", "unknown") for r in records})
    stamp = (
        f"Commit `{', '.join(commits)}` (build {', '.join(builds)}), {host['cpu']}, "
        f"nproc {host['nproc']}, one thread; "
        "`nice -n 10 python benchmarks/verdict_benchmark.py`."
    )
    calibration = calibrate(records)
    shared = shared_threshold(records, calibration)
    has_library = any(r.get("reliable") is not None for r in records)
    modes = MODES if has_library else ("fitted",)
    validations = {mode: validate(records, calibration, mode) for mode in modes}
    text = tables(calibration, shared, validations, stamp)
    print(text)
    print("\n" + cpp_snippet(calibration, shared, stamp))
    if not write:
        return
    head = {
        "commits": commits,
        "builds": builds,
        "machine": host,
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    calibration_out = head | {
        "kinds": calibration,
        "shared_threshold": shared,
        "cpp": cpp_snippet(calibration, shared, stamp),
    }
    CALIBRATION.write_text(json.dumps(report_lib.rounded(calibration_out), indent=1) + "\n")
    validation_out = head | {"modes": validations}
    VALIDATION.write_text(json.dumps(report_lib.rounded(validation_out), indent=1) + "\n")
    validation_rows = [r for r in records if r["set"] == "validation"]
    if validation_rows and calibration:
        plot_reliability({m: with_verdict(validation_rows, calibration, m) for m in modes}, FIGURE)
    if write_doc(doc, text):
        print(f"wrote the tables into {doc}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"{QUICK_PER_FAMILY} problems per family, writes nothing",
    )
    parser.add_argument("--set", choices=("calibration", "validation", "both"), default="both")
    parser.add_argument("--report-only", action="store_true", help="tables from the JSONL")
    parser.add_argument("--fresh", action="store_true", help="discard the JSONL's records first")
    parser.add_argument("--doc", type=Path, default=DOC, help="docs page with verdict markers")
    args = parser.parse_args()
    if args.report_only:
        report(read_records(RECORDS), write=True, doc=args.doc)
        return 0
    names = list(sets_lib.SETS) if args.set == "both" else [args.set]
    if args.quick:
        report(run_sets(names, QUICK_PER_FAMILY, None), write=False, doc=args.doc)
        return 0
    if args.fresh:
        RECORDS.unlink(missing_ok=True)
    start = time.perf_counter()
    run_sets(names, None, RECORDS)
    print(f"ran in {time.perf_counter() - start:.0f} s wall")
    report(read_records(RECORDS), write=True, doc=args.doc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
