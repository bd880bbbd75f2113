"""Data shared by the command line, the tests and the benchmarks.

* :mod:`spectral_vs.data.view_pairs`: pairs of views of one scene, cut out of the real
  organized scans, with their true relative pose (:mod:`spectral_vs.data.scan_windows`:
  the windows they are cut out of), or rendered in the simulation
  (:mod:`spectral_vs.data.rendered_pairs`).
* :mod:`spectral_vs.data.scenes`: seeded synthetic table-top scenes with exact normals,
  and the milk carton's scan split into a model and a scene that share no point.
"""

from spectral_vs.data.rendered_pairs import sim_view_pairs
from spectral_vs.data.scans import SCANS, data_dir, scan_path
from spectral_vs.data.scenes import (
    MILK_MODEL,
    MILK_SCENE,
    box_with_ball,
    milk_split,
    synthetic_scene,
)
from spectral_vs.data.view_pairs import (
    MAX_TRANSLATION,
    NORMAL_NEIGHBORS,
    OVERLAP_RANGE,
    ROTATION_RANGE_DEG,
    WINDOW_SHARE,
    ViewPair,
    make_view_pair,
    random_transform,
    rotation_angle_deg,
    view_pairs,
)

__all__ = [
    "MAX_TRANSLATION",
    "MILK_MODEL",
    "MILK_SCENE",
    "NORMAL_NEIGHBORS",
    "OVERLAP_RANGE",
    "ROTATION_RANGE_DEG",
    "SCANS",
    "WINDOW_SHARE",
    "ViewPair",
    "box_with_ball",
    "data_dir",
    "make_view_pair",
    "milk_split",
    "random_transform",
    "rotation_angle_deg",
    "scan_path",
    "sim_view_pairs",
    "synthetic_scene",
    "view_pairs",
]
