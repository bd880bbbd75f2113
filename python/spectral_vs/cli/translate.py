"""``spectral-vs translate``: the translation between two clouds by phase correlation."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

import spectral_vs as svs
from spectral_vs.cli.common import (
    _positive_float,
    read_cloud,
)


def add_parser(commands: Any, formatter: Any) -> None:
    """Add the subcommand to ``commands``, the parser's subparsers."""
    translate = commands.add_parser(
        "translate", help="translation between two clouds (PCD/PLY) by 3D phase correlation"
    )
    translate.add_argument("moving", type=Path, help="cloud to move (.pcd or .ply)")
    translate.add_argument("target", type=Path, help="cloud to move it onto (.pcd or .ply)")
    translate.add_argument(
        "--voxel-size", type=_positive_float, default=0.008, help="voxel edge in metres"
    )
    translate.add_argument(
        "--occupancy",
        choices=["binary", "count", "trilinear"],
        default="trilinear",
        help="voxel values: the paper's binary grid or a weighted one (default: trilinear)",
    )
    translate.add_argument("--json", action="store_true", help="print machine-readable JSON")
    translate.set_defaults(run=run_translate)


def estimate_translation(
    moving: svs.PointCloud,
    target: svs.PointCloud,
    voxel_size: float,
    occupancy: str = "trilinear",
) -> tuple[svs.TranslationEstimate, svs.GridSpec]:
    """Translation of ``moving`` onto ``target`` by phase correlation on a shared grid."""
    spec = svs.make_grid_spec(moving, target, voxel_size)
    correlation = svs.PhaseCorrelation(spec)
    correlation.set_target(svs.voxelize(target, spec, occupancy=occupancy))
    return correlation.estimate(svs.voxelize(moving, spec, occupancy=occupancy)), spec


def run_translate(args: argparse.Namespace) -> int:
    """Translation between two point cloud files."""
    moving = read_cloud(args.moving, "MOVING")
    target = read_cloud(args.target, "TARGET")
    start = time.perf_counter()
    estimate, spec = estimate_translation(moving, target, args.voxel_size, args.occupancy)
    elapsed = time.perf_counter() - start
    result = {
        "translation_m": list(map(float, estimate.shift)),
        "translation_voxels": list(map(float, estimate.shift_voxels)),
        "peak": float(estimate.peak),
        "grid_dims": list(map(int, spec.dims)),
        "time_s": elapsed,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        t_mm = 1000 * np.asarray(estimate.shift)
        print(f"translation [mm]: {np.array2string(t_mm, precision=2)}  (moves MOVING onto TARGET)")
        print(f"peak {estimate.peak:.3f}, grid {result['grid_dims']}, {1000 * elapsed:.1f} ms")
    return 0


# ----------------------------------------------------------------------------- servo-sim
