"""The calibration set and the validation set of issue 32 ("one verdict for every
registration"): seeded registration problems with their ground truth.

Two disjoint sets, built the same way from different material:

* ``calibration``: the tuning objects of ``cases.py`` (``cases.OBJECTS``), the real scans
  of the table (``milk_cartoon_all_small_clorox.pcd``, with the carton ``milk.pcd``) and of
  the bunny (``bun0.pcd``), and toy castles of the calibration blocks;
* ``validation``: the held-out objects (``cases.HELDOUT_OBJECTS``), the real scan of the
  room (``five_people.pcd``) and toy castles of the validation blocks.

No object, block, mesh, real scan or seed is in both (``benchmarks/tests/
test_verdict_sets.py`` checks it on the specs). Each set covers:

* model-to-scan problems (kind ``align``: ``svs.align(model, scene)``) and view pairs
  (kind ``views``: ``svs.align_views(reference, current)``);
* depth noise: rendered scans get the Kinect axial model of Nguyen, Izadi and Lovell
  (2012), sigma_z = 1.2 mm + 1.9 mm (z - 0.4 m)^2 / m^2 along each pixel ray, and
  :data:`DROPPED_SHARE` of the pixels dropped (:func:`noisy_depth`);
* near-symmetric scenes: box-shaped objects (the jenga block, the domino, with their
  exact half turns as symmetries) and toy castles stacked from boxes whose only
  asymmetry is one flag block (:func:`castle_boxes`);
* scans in a robot base frame rather than the camera's (``base_frame``, ``scan_base``:
  the camera case moved by a rigid transform, the sensor origin moved with it);
* view pairs overlapping 30% to 100% (windows of one organized scan);
* problems without a right answer: views of two different scenes (a real scan against a
  rendered one, a castle against a table of objects) and the model of an object absent
  from the scene (``share_nothing``, ``wrong_object``);
* wrong settings: a voxel 10 times larger and 10 times smaller than the derived one
  (``wrong_voxel``; the small one capped by ``max_seconds`` on small clouds).

"Right" is a rotation error under 5 degrees and a translation error under 10 mm: for
objects at the model centroid, the smallest over the object's exact symmetries
(``cases.pose_error``); for view pairs at the reference's centroid
(:func:`reference_centroid`), where the library's verdict bounds the error too, and to the
same 5 degrees and 10 mm at every scale (docs/views.md holds every view pair, the room's up
to 9.8 m deep included, to 5 degrees and 10 mm). A problem without a
right answer has ``T_true = None``: every answer to it is wrong.

A set is a list of :class:`Spec` (cheap, no cloud); :func:`build_case` makes the clouds
of one spec, the same arrays on every run with the same inputs. The real scans are read
from ``$SPECTRAL_VS_DATA`` or ``../shared/data`` beside the repository.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import cases as case_lib
import numpy as np

import spectral_vs as svs
from spectral_vs import data

SETS = ("calibration", "validation")
KINDS = ("align", "views")
RIGHT_DEG = 5.0
RIGHT_M = 0.010
#: Share of the pixels of a rendered scan that read as missing.
DROPPED_SHARE = 0.03
#: Nguyen, Izadi, Lovell (2012): sigma_z = a + b (z - z0)^2, metres.
NGUYEN_A_M, NGUYEN_B_PER_M, NGUYEN_Z0_M = 0.0012, 0.0019, 0.4
#: Model samples of a toy castle (larger than an object: more surface).
CASTLE_SAMPLES = 8000
#: Size of the rendered view pairs, pixels (the servo's camera).
VIEW_PAIR_SIZE = (320, 240)
#: CPU budget of an alignment at a voxel 10 times too small, seconds.
SMALL_VOXEL_MAX_SECONDS = 10.0
ANGLES = (10.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0)
VERDICT_ROOT_SEED = 3232

#: Per set: the cases.py families of full models, single views and clutter, the objects,
#: the real scans, the box-shaped object.
MATERIAL = {
    "calibration": {
        "full": "full",
        "single": "partial",
        "clutter": "clutter",
        "objects": tuple(case_lib.OBJECTS),
        "scan": "table",
        "box": "jenga",
    },
    "validation": {
        "full": "heldout_full",
        "single": "heldout_partial",
        "clutter": "heldout_clutter",
        "objects": tuple(case_lib.HELDOUT_OBJECTS),
        "scan": "room",
        "box": "domino",
    },
}

#: Block sizes of each set's toy castles, (length, width, height) in mm: the two sets'
#: blocks differ in every size, so no block is in both.
CASTLE_BLOCKS_MM = {
    "calibration": {
        "tower": (60, 60, 120),
        "wall": (150, 30, 70),
        "beam": (150, 44, 20),
        "merlon": (24, 24, 24),
        "flag": (12, 20, 45),
    },
    "validation": {
        "tower": (70, 52, 100),
        "wall": (130, 40, 55),
        "beam": (130, 56, 26),
        "merlon": (30, 28, 18),
        "flag": (16, 16, 40),
    },
}

#: Cases per family and kind (the same in both sets).
FAMILY_COUNTS = {
    "align": {
        "full": 21,
        "single_view": 28,
        "clutter": 24,
        "base_frame": 20,
        "boxes": 12,
        "castle": 24,
        "real": 12,
        "wrong_object": 24,
        "wrong_voxel": 16,
    },
    "views": {
        "scan": 30,
        "scan_640": 10,
        "scan_base": 12,
        "rendered": 24,
        "rendered_castle": 16,
        "share_nothing": 18,
        "wrong_voxel": 8,
    },
}
#: Families whose problems have no right answer.
NO_TRUTH_FAMILIES = ("share_nothing", "wrong_object")
#: First cases.py index of each family's cases (so that two families never draw the same
#: cases.py case, and none is a case of the other benchmarks, which use indices 0-5).
CASE_INDEX_BASE = {
    "full": 100,
    "single_view": 100,
    "clutter": 100,
    "base_frame": 200,
    "boxes": 300,
    "real": 400,
    "wrong_object": 500,
    "wrong_voxel": 600,
}


# --- Specs and cases -----------------------------------------------------------------------


@dataclass(frozen=True)
class Spec:
    """What to build: one problem of a set (no clouds).

    Attributes
    ----------
    set_name, kind, family : str
        The set, ``"align"`` or ``"views"``, the family label.
    index : int
        Position in its family.
    seed : int
        The seed every random draw of the problem derives from.
    args : dict
        The builder's arguments (object, angle, overlap, voxel factor, ...).
    objects : tuple of str
        Every object or block that may appear in the problem (the whole pool for clutter).
    scenes : tuple of str
        The scenes it is cut from: ``scan:<name>`` for a real scan, ``render:<seed>`` for a
        rendered or sampled one.
    has_truth : bool
        False when no answer is right.
    """

    set_name: str
    kind: str
    family: str
    index: int
    seed: int
    args: dict = field(default_factory=dict)
    objects: tuple[str, ...] = ()
    scenes: tuple[str, ...] = ()
    has_truth: bool = True

    @property
    def case_id(self) -> str:
        return f"{self.set_name[:3]}-{self.kind}-{self.family}-{self.index:03d}"


@dataclass(frozen=True, eq=False)
class VerdictCase:
    """One registration problem; metres.

    ``source`` is the model (align) or the reference view (views), ``target`` the scene or
    the current view. ``T_true`` maps source coordinates into the target's (None: no
    answer is right); ``T_true @ S`` is as right for every ``S`` of ``symmetries``
    (source-frame transforms fixing ``center``, identity first). Errors are measured at
    ``center`` (source coordinates). ``sensor_origin`` is the target's sensor in target
    coordinates (NaN: no sensor, a resampled full copy); ``reference_origin`` the
    reference view's in its own. ``settings`` are extra keyword settings of the call.
    """

    spec: Spec
    source: svs.PointCloud
    target: svs.PointCloud
    T_true: np.ndarray | None
    symmetries: np.ndarray
    center: np.ndarray
    sensor_origin: np.ndarray
    reference_origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    settings: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    @property
    def case_id(self) -> str:
        return self.spec.case_id

    @property
    def has_truth(self) -> bool:
        return self.T_true is not None


def reference_centroid(reference: svs.PointCloud) -> np.ndarray:
    """Where a view pair's error is measured: the reference's centroid, as an object's is
    at the model's (the library's verdict bounds the pose's error there too). At the
    reference camera's origin, 0.5-1 m from the surfaces it registers, a 1.7 degree error
    alone would move the point by 15-30 mm."""
    return np.asarray(reference.points, dtype=float).mean(axis=0)


def derived_seed(set_name: str, kind: str, family: str, index: int) -> int:
    """A 32-bit seed from the set, the kind, the family and the index."""
    names = [f"{k}:{f}" for k in KINDS for f in FAMILY_COUNTS[k]]
    key = [SETS.index(set_name), KINDS.index(kind), names.index(f"{kind}:{family}"), index]
    return int(np.random.SeedSequence([VERDICT_ROOT_SEED, *key]).generate_state(1)[0])


def _case_spec(cases_family: str, obj: str, angle: float, index: int) -> case_lib.CaseSpec:
    return case_lib.CaseSpec(cases_family, obj, float(angle), index)


def _object_spec(set_name: str, family: str, i: int, variant: str, obj: str, **args) -> Spec:
    """A spec built from a cases.py case (full, single view or clutter) of ``obj``."""
    material = MATERIAL[set_name]
    cases_family = material[variant]
    angle = ANGLES[i % len(ANGLES)]
    spec = _case_spec(cases_family, obj, angle, CASE_INDEX_BASE[family] + i)
    pool = material["objects"]
    objects = pool if variant == "clutter" or family == "wrong_object" else (obj,)
    return Spec(
        set_name,
        "align",
        family,
        i,
        spec.seed,
        {
            "builder": "object",
            "cases_family": cases_family,
            "object": obj,
            "angle": angle,
            "cases_index": spec.index,
            "variant": variant,
            **args,
        },
        tuple(objects),
        (f"render:{spec.seed}",),
        family not in NO_TRUTH_FAMILIES,
    )


def _cycled(items: tuple, i: int):
    return items[i % len(items)]


def align_specs(set_name: str) -> list[Spec]:
    """Every model-to-scan problem of a set."""
    m, counts, out = MATERIAL[set_name], FAMILY_COUNTS["align"], []
    objects = m["objects"]
    for i in range(counts["full"]):
        out.append(_object_spec(set_name, "full", i, "full", _cycled(objects, i)))
    for i in range(counts["single_view"]):
        out.append(_object_spec(set_name, "single_view", i, "single", _cycled(objects, i)))
    for i in range(counts["clutter"]):
        out.append(_object_spec(set_name, "clutter", i, "clutter", _cycled(objects, i)))
    for i in range(counts["base_frame"]):
        variant = ("single", "clutter")[i % 2]
        out.append(
            _object_spec(set_name, "base_frame", i, variant, _cycled(objects, i // 2), frame="base")
        )
    for i in range(counts["boxes"]):
        out.append(_object_spec(set_name, "boxes", i, ("single", "clutter")[i % 2], m["box"]))
    for i in range(counts["wrong_object"]):
        variant = ("single", "clutter")[i % 2]
        out.append(
            _object_spec(
                set_name, "wrong_object", i, variant, _cycled(objects, i // 2), wrong_object=True
            )
        )
    for i in range(counts["wrong_voxel"]):
        variant = ("single", "full")[(i // 2) % 2]
        out.append(
            _object_spec(
                set_name,
                "wrong_voxel",
                i,
                variant,
                _cycled(objects, i // 2),
                voxel_factor=(10.0, 0.1)[i % 2],
            )
        )
    out += [_castle_spec(set_name, i) for i in range(counts["castle"])]
    out += [_real_spec(set_name, i) for i in range(counts["real"])]
    return out


def castle_names(set_name: str) -> tuple[str, ...]:
    """The block names of a set's castles."""
    return tuple(f"{set_name}_{block}" for block in CASTLE_BLOCKS_MM[set_name])


def _castle_spec(set_name: str, i: int) -> Spec:
    seed = derived_seed(set_name, "align", "castle", i)
    args = {"builder": "castle", "angle": ANGLES[i % len(ANGLES)]}
    return Spec(
        set_name, "align", "castle", i, seed, args, castle_names(set_name), (f"render:{seed}",)
    )


def _real_spec(set_name: str, i: int) -> Spec:
    """Calibration: the milk carton in its scan, the bunny scan, a table view onto the
    table's frame, in turn. Validation: a room view onto the room's frame."""
    angle = ANGLES[i % len(ANGLES)]
    index = CASE_INDEX_BASE["real"] + i
    if set_name == "calibration" and i % 3 < 2:
        family, obj, scene = (("milk", "milk", "scan:table"), ("bunny_scan", "bunny", "scan:bun0"))[
            i % 3
        ]
        spec = _case_spec(family, family, angle, index)
        args = {
            "builder": "object",
            "cases_family": family,
            "object": family,
            "angle": angle,
            "cases_index": index,
            "variant": "real",
        }
        return Spec(set_name, "align", "real", i, spec.seed, args, (obj,), (scene,))
    scan = MATERIAL[set_name]["scan"]
    seed = derived_seed(set_name, "align", "real", i)
    args = {"builder": "scan_frame", "scan": scan}
    return Spec(set_name, "align", "real", i, seed, args, (), (f"scan:{scan}",))


def _overlap(i: int, count: int) -> float:
    """Overlaps spread evenly over [0.3, 1.0] across a family."""
    return 0.3 + 0.7 * (i + 0.5) / count


def view_specs(set_name: str) -> list[Spec]:
    """Every view pair of a set."""
    counts, scan, out = FAMILY_COUNTS["views"], MATERIAL[set_name]["scan"], []
    pool = MATERIAL[set_name]["objects"]

    def add(family: str, i: int, args: dict, objects=(), scenes=()) -> None:
        seed = derived_seed(set_name, "views", family, i)
        scenes = tuple(s if s != "render" else f"render:{seed}" for s in scenes)
        out.append(
            Spec(
                set_name,
                "views",
                family,
                i,
                seed,
                args,
                tuple(objects),
                scenes,
                family not in NO_TRUTH_FAMILIES,
            )
        )

    for family, downscale in (("scan", 2), ("scan_640", 1), ("scan_base", 2)):
        for i in range(counts[family]):
            args = {
                "builder": "scan_pair",
                "scan": scan,
                "downscale": downscale,
                "overlap": _overlap(i, counts[family]),
                "frame": "base" if family == "scan_base" else "camera",
            }
            add(family, i, args, scenes=(f"scan:{scan}",))
    for i in range(counts["rendered"]):
        add("rendered", i, {"builder": "rendered_pair", "scene": "clutter"}, pool, ("render",))
    for i in range(counts["rendered_castle"]):
        add(
            "rendered_castle",
            i,
            {"builder": "rendered_pair", "scene": "castle"},
            castle_names(set_name),
            ("render",),
        )
    combos = ("scan_vs_clutter", "castle_vs_scan", "castle_vs_clutter")
    for i in range(counts["share_nothing"]):
        combo = _cycled(combos, i)
        objects = (pool if "clutter" in combo else ()) + (
            castle_names(set_name) if "castle" in combo else ()
        )
        scenes = ((f"scan:{scan}",) if "scan" in combo else ()) + ("render",)
        add(
            "share_nothing",
            i,
            {"builder": "share_nothing", "combo": combo, "scan": scan},
            objects,
            scenes,
        )
    for i in range(counts["wrong_voxel"]):
        args = {
            "builder": "scan_pair",
            "scan": scan,
            "downscale": 2,
            "frame": "camera",
            "overlap": _overlap(i, counts["wrong_voxel"]),
            "voxel_factor": (10.0, 0.1)[i % 2],
        }
        add("wrong_voxel", i, args, scenes=(f"scan:{scan}",))
    return out


def specs(set_name: str, per_family: int | None = None) -> list[Spec]:
    """The specs of a set, align first; ``per_family`` keeps the first few of each family."""
    if set_name not in SETS:
        raise ValueError(f"set_name must be one of {SETS}, got {set_name!r}")
    out = align_specs(set_name) + view_specs(set_name)
    if per_family is None:
        return out
    taken: dict[tuple[str, str], int] = {}
    kept = []
    for s in out:
        key = (s.kind, s.family)
        if taken.get(key, 0) < per_family:
            kept.append(s)
            taken[key] = taken.get(key, 0) + 1
    return kept


# --- Depth noise and rendering -------------------------------------------------------------


def nguyen_sigma_m(depth_m: np.ndarray) -> np.ndarray:
    """Axial standard deviation of a Kinect's depth at ``depth_m`` (Nguyen et al. 2012)."""
    return NGUYEN_A_M + NGUYEN_B_PER_M * np.square(np.asarray(depth_m) - NGUYEN_Z0_M)


def noisy_depth(
    depth_m: np.ndarray, rng: np.random.Generator, dropped_share: float = DROPPED_SHARE
) -> np.ndarray:
    """A planar depth image with the Nguyen axial noise and ``dropped_share`` of its pixels
    missing (NaN). Noise on the planar depth moves each back-projected point along its
    pixel's ray."""
    noisy = depth_m + nguyen_sigma_m(depth_m) * rng.standard_normal(depth_m.shape)
    noisy[rng.random(depth_m.shape) < dropped_share] = np.nan
    return noisy


Body = tuple[np.ndarray, np.ndarray, np.ndarray]  # vertices, faces, T_world_body


def render_scan(
    bodies: list[Body],
    table: bool,
    T_world_camera: np.ndarray,
    size: tuple[int, int],
    rng: np.random.Generator,
) -> svs.PointCloud:
    """The noisy depth scan of ``bodies`` (and the table top at z = 0) in the camera frame,
    normals from the depth image, turned toward the camera."""
    from spectral_vs.sim.camera import CameraIntrinsics, depth_to_cloud

    r = case_lib.renderer()
    r.reset()
    for vertices, faces, T in bodies:
        r.add_mesh(vertices, faces, T)
    if table:
        r.add_box(case_lib.TABLE_HALF, (0.0, 0.0, -case_lib.TABLE_HALF[2]))
    intrinsics = CameraIntrinsics(*size)
    depth, _ = r.render(T_world_camera, intrinsics)
    return depth_to_cloud(noisy_depth(depth, rng), intrinsics)


def _moved(cloud: svs.PointCloud, T: np.ndarray) -> svs.PointCloud:
    points = case_lib.apply(T, np.asarray(cloud.points))
    normals = np.asarray(cloud.normals) @ T[:3, :3].T
    return svs.PointCloud(np.ascontiguousarray(points), np.ascontiguousarray(normals))


def _stream(seed: int, stream: int) -> np.random.Generator:
    """An independent generator of a case's seed: 1 noise, 2 base frame, 3 wrong model."""
    return np.random.default_rng([seed, stream])


# --- Model-to-scan problems ---------------------------------------------------------------------


def _noisy_scene(case: case_lib.Case, rng: np.random.Generator) -> case_lib.Case:
    """A cases.py single view or clutter case (rendered without noise) rendered again with
    the Nguyen noise, in the same world frame."""
    info = case.info
    if "objects" in info:  # clutter: every object at its pose, and the table
        names, poses = info["objects"], info["poses"]
    else:
        names, poses = [case.object], [info["T_scene_object"]]
    bodies = []
    for name, T in zip(names, poses, strict=True):
        mesh = case_lib.load_mesh(name)
        bodies.append((mesh.vertices, mesh.faces, np.asarray(T)))
    T_wc = np.asarray(info["T_world_camera"])
    scan = _moved(render_scan(bodies, "objects" in info, T_wc, case_lib.CAMERA_SIZE, rng), T_wc)
    return replace(
        case,
        scene_points=np.asarray(scan.points),
        scene_normals=np.asarray(scan.normals),
        info=info | {"scan_points": len(scan), "noise": "nguyen"},
    )


def _base_transform(T_world_camera: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """T_base_camera of a robot whose base stands 0.5-0.9 m from the table's centre,
    0-0.3 m below its top, turned toward it within 30 degrees."""
    azimuth = rng.uniform(-math.pi, math.pi)
    distance, height = rng.uniform(0.5, 0.9), -rng.uniform(0.0, 0.3)
    position = np.array([distance * math.cos(azimuth), distance * math.sin(azimuth), height])
    yaw = azimuth + math.pi + rng.uniform(-math.pi / 6, math.pi / 6)
    T_world_base = case_lib.pose(case_lib.axis_angle(np.array([0.0, 0.0, 1.0]), yaw), position)
    return np.linalg.inv(T_world_base) @ T_world_camera


def in_base_frame(case: VerdictCase, T_base_target: np.ndarray) -> VerdictCase:
    """The case with its target (scene, current view) moved by ``T_base_target``: the
    target's points, normals and sensor origin, and the truth (the source is unchanged)."""
    T_true = None if case.T_true is None else T_base_target @ case.T_true
    origin = case_lib.apply(T_base_target, case.sensor_origin[None])[0]
    return replace(
        case,
        target=_moved(case.target, T_base_target),
        T_true=T_true,
        sensor_origin=origin,
        info=case.info | {"T_base_target": T_base_target.tolist()},
    )


def _from_cases_case(spec: Spec, case: case_lib.Case) -> VerdictCase:
    return VerdictCase(
        spec=spec,
        source=case.model_cloud(),
        target=case.scene_cloud(),
        T_true=case.T_true,
        symmetries=case.symmetries,
        center=case.model_center,
        sensor_origin=np.asarray(case.viewpoint, dtype=float),
        info={"cases_id": case.case_id, "object": case.object, "angle_deg": case.angle_deg}
        | {k: v for k, v in case.info.items() if k in ("objects", "visible_fraction")},
    )


def _cases_case(spec: Spec) -> case_lib.Case:
    a = spec.args
    cspec = _case_spec(a["cases_family"], a["object"], a["angle"], a["cases_index"])
    if a["variant"] in ("single", "clutter"):
        builder = case_lib.partial_case if a["variant"] == "single" else case_lib.clutter_case
        case = builder(cspec, noise=False)
        return case_lib.in_camera_frame(_noisy_scene(case, _stream(spec.seed, 1)))
    return case_lib.make_case(cspec)


def _wrong_model(spec: Spec, case: case_lib.Case) -> tuple[str, svs.PointCloud]:
    """The name and full model of an object of the set that the scene does not hold."""
    rng = _stream(spec.seed, 3)
    present = set(case.info.get("objects", [case.object]))
    names = [n for n in MATERIAL[spec.set_name]["objects"] if n not in present]
    name = names[int(rng.integers(len(names)))]
    points, normals = case_lib.sample_surface(case_lib.load_mesh(name), case_lib.MODEL_SAMPLES, rng)
    return name, svs.PointCloud(points, normals)


def object_case(spec: Spec) -> VerdictCase:
    """A problem from a cases.py case: noisy single views and clutter in the camera frame
    (or a robot base frame), wrong models, wrong voxels."""
    case = _cases_case(spec)
    out = _from_cases_case(spec, case)
    a = spec.args
    if a.get("wrong_object"):
        name, model = _wrong_model(spec, case)
        out = replace(
            out,
            source=model,
            T_true=None,
            symmetries=np.eye(4)[None],
            center=np.asarray(model.points).mean(axis=0),
            info=out.info | {"wrong_model": name},
        )
    if a.get("frame") == "base":
        T_wc = np.asarray(case.info["T_world_camera"])
        out = in_base_frame(out, _base_transform(T_wc, _stream(spec.seed, 2)))
    if "voxel_factor" in a:
        derived = svs.alignment_voxel_size(out.source, out.target)
        settings = {"voxel_size": a["voxel_factor"] * derived}
        if a["voxel_factor"] < 1.0:
            settings["max_seconds"] = SMALL_VOXEL_MAX_SECONDS
        out = replace(out, settings=settings, info=out.info | {"derived_voxel_m": derived})
    return out


# --- Toy castles ---------------------------------------------------------------------------

#: Corner k of a box is (+-1, +-1, +-1) with bits (x, y, z) = (k >> 2, k >> 1, k) & 1; the
#: triangles below turn counter-clockwise seen from outside.
_BOX_CORNERS = np.array([[(k >> 2) & 1, (k >> 1) & 1, k & 1] for k in range(8)]) * 2.0 - 1.0
_BOX_FACES = np.array(
    [
        [0, 1, 3],
        [0, 3, 2],
        [4, 7, 5],
        [4, 6, 7],
        [0, 4, 5],
        [0, 5, 1],
        [2, 7, 6],
        [2, 3, 7],
        [0, 2, 6],
        [0, 6, 4],
        [1, 7, 3],
        [1, 5, 7],
    ]
)


def boxes_mesh(boxes: list[tuple[np.ndarray, np.ndarray]]) -> case_lib.Mesh:
    """The mesh of axis-aligned boxes given as (centre, half sizes), one part each (faces
    where two boxes touch are hidden surface for ``cases.sample_surface``)."""
    vertices = np.vstack([c + h * _BOX_CORNERS for c, h in boxes])
    faces = np.vstack([_BOX_FACES + 8 * i for i in range(len(boxes))])
    parts = np.repeat(np.arange(len(boxes)), len(_BOX_FACES))
    return case_lib._with_geometry(vertices, faces, parts)


def castle_boxes(set_name: str, rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """A toy castle of the set's blocks (each scaled by 0.85-1.15), standing on z = 0: two
    towers, a wall between them, a beam on the wall, the same merlons on both towers and
    one flag on one tower, the only part that tells the castle from its half turn about
    the vertical and from its mirror image."""
    size = {
        k: rng.uniform(0.85, 1.15) * np.array(v) / 1000.0
        for k, v in CASTLE_BLOCKS_MM[set_name].items()
    }
    tower, wall, beam, merlon, flag = (size[k] for k in ("tower", "wall", "beam", "merlon", "flag"))
    boxes = []

    def add(center, full_size) -> None:
        boxes.append((np.asarray(center, dtype=float), 0.5 * np.asarray(full_size)))

    add((0.0, 0.0, wall[2] / 2), wall)
    add((0.0, 0.0, wall[2] + beam[2] / 2), (wall[0], beam[1], beam[2]))
    x_tower = wall[0] / 2 + tower[0] / 2
    grid = int(rng.integers(1, 3))  # 1 or 2 x 2 merlons per tower
    for side in (-1.0, 1.0):
        add((side * x_tower, 0.0, tower[2] / 2), tower)
        for i in range(grid):
            for j in range(grid):
                dx = (i - (grid - 1) / 2) * (tower[0] - merlon[0])
                dy = (j - (grid - 1) / 2) * (tower[1] - merlon[1])
                add((side * x_tower + dx, dy, tower[2] + merlon[2] / 2), merlon)
    top = tower[2] + merlon[2] if grid == 1 else tower[2]
    side = 1.0 if rng.random() < 0.5 else -1.0
    add((side * x_tower, 0.0, top + flag[2] / 2), flag)
    return boxes


def _perturbed(
    rng: np.random.Generator, angle_deg: float, points, normals, T_scene_object, center
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The model given to the aligner: the object turned by ``angle_deg`` about a random
    axis through its placed centre and shifted up to ``cases.MAX_OFFSET`` away from its
    place, as cases.py perturbs its models. Returns model points, normals, T_true
    (scene <- model) and the centre in model coordinates."""
    placed = case_lib.apply(T_scene_object, center[None])[0]
    R = case_lib.axis_angle(case_lib.random_unit(rng), math.radians(angle_deg))
    delta = case_lib.rotation_about(R, placed)
    delta[:3, 3] += rng.uniform(0.0, case_lib.MAX_OFFSET) * case_lib.random_unit(rng)
    A = np.linalg.inv(delta) @ T_scene_object
    return (
        case_lib.apply(A, points),
        normals @ A[:3, :3].T,
        delta,
        case_lib.apply(A, center[None])[0],
    )


def _look_at_from(target, rng, elevation_deg, distance_m) -> np.ndarray:
    elevation = math.radians(rng.uniform(*elevation_deg))
    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    direction = np.array(
        [
            math.cos(elevation) * math.cos(azimuth),
            math.cos(elevation) * math.sin(azimuth),
            math.sin(elevation),
        ]
    )
    return case_lib.look_at(target + rng.uniform(*distance_m) * direction, target)


def _castle_scene(set_name: str, rng: np.random.Generator) -> tuple[case_lib.Mesh, np.ndarray]:
    """A castle mesh and its pose on the table (random yaw, near the centre)."""
    mesh = boxes_mesh(castle_boxes(set_name, rng))
    yaw = case_lib.axis_angle(np.array([0.0, 0.0, 1.0]), rng.uniform(-math.pi, math.pi))
    return mesh, case_lib.pose(yaw, np.array([*rng.uniform(-0.05, 0.05, 2), 0.0]))


def castle_case(spec: Spec) -> VerdictCase:
    """A full castle model onto one noisy 640 x 480 view of the castle on the table, in the
    camera frame."""
    rng = np.random.default_rng(spec.seed)
    mesh, T_world_castle = _castle_scene(spec.set_name, rng)
    points, normals = case_lib.sample_surface(mesh, CASTLE_SAMPLES, rng)
    center = points.mean(axis=0)
    target = case_lib.apply(T_world_castle, center[None])[0]
    T_wc = _look_at_from(target, rng, (25.0, 70.0), (0.5, 0.9))
    scan = render_scan(
        [(mesh.vertices, mesh.faces, T_world_castle)],
        True,
        T_wc,
        case_lib.CAMERA_SIZE,
        _stream(spec.seed, 1),
    )
    T_camera_castle = np.linalg.inv(T_wc) @ T_world_castle
    model, model_normals, T_true, model_center = _perturbed(
        rng, spec.args["angle"], points, normals, T_camera_castle, center
    )
    return VerdictCase(
        spec=spec,
        source=svs.PointCloud(np.ascontiguousarray(model), np.ascontiguousarray(model_normals)),
        target=scan,
        T_true=T_true,
        symmetries=np.eye(4)[None],
        center=model_center,
        sensor_origin=np.zeros(3),
        info={"boxes": len(mesh.planes), "scan_points": len(scan), "angle_deg": spec.args["angle"]},
    )


# --- Real frames ---------------------------------------------------------------------------


@functools.lru_cache(maxsize=2)
def _frame_scene(scan: str) -> tuple[np.ndarray, svs.PointCloud]:
    """An organized scan and its finite points of even u + v with normals (20 neighbours,
    toward the sensor at the origin): the scene a view of odd pixels is aligned onto."""
    frame = svs.load_organized(data.scan_path(scan, case_lib.data_dir()))
    v, u = np.mgrid[: frame.shape[0], : frame.shape[1]]
    keep = ((u + v) % 2 == 0) & np.all(np.isfinite(frame), axis=2)
    cloud = svs.estimate_normals(
        svs.PointCloud(np.ascontiguousarray(frame[keep])), k_neighbors=20, viewpoint=np.zeros(3)
    )
    return frame, cloud


def scan_frame_case(spec: Spec) -> VerdictCase:
    """A view cut from a real frame (``data.make_view_pair``'s current: odd pixels of half
    the image, moved 5-60 degrees and up to 0.15 m) onto the frame's even pixels."""
    frame, scene = _frame_scene(spec.args["scan"])
    pair = data.make_view_pair(frame, seed=spec.seed)
    model = pair.current
    return VerdictCase(
        spec=spec,
        source=model,
        target=scene,
        T_true=np.linalg.inv(pair.T_current_reference),
        symmetries=np.eye(4)[None],
        center=np.asarray(model.points).mean(axis=0),
        sensor_origin=np.zeros(3),
        info={"scan": spec.args["scan"], "model_points": len(model)},
    )


# --- View pairs ----------------------------------------------------------------------------


def _pair_from_scan(spec: Spec, overlap: float, downscale: int) -> data.ViewPair:
    """Windows of a real scan; a window of 40% of the image where 30-36% overlap would not
    fit in windows of half of it."""
    share = data.WINDOW_SHARE if overlap >= 0.36 else 0.4
    path = data.scan_path(spec.args["scan"], case_lib.data_dir())
    return data.make_view_pair(
        path, overlap=overlap, downscale=downscale, window_share=share, seed=spec.seed
    )


def scan_pair_case(spec: Spec) -> VerdictCase:
    """Two windows of one real scan, the current moved; optionally in a robot base frame,
    optionally with a wrong voxel."""
    a = spec.args
    pair = _pair_from_scan(spec, a["overlap"], a["downscale"])
    out = VerdictCase(
        spec=spec,
        source=pair.reference,
        target=pair.current,
        T_true=pair.T_current_reference,
        symmetries=np.eye(4)[None],
        center=reference_centroid(pair.reference),
        sensor_origin=np.asarray(pair.current_viewpoint, dtype=float),
        info={"overlap": pair.overlap, "scan": a["scan"], "downscale": a["downscale"]},
    )
    if a.get("frame") == "base":
        rng = _stream(spec.seed, 2)
        direction = case_lib.random_unit(rng)
        T_base = case_lib.pose(case_lib.random_rotation(rng), rng.uniform(0.5, 1.5) * direction)
        out = in_base_frame(out, T_base)
    if "voxel_factor" in a:
        derived = svs.view_scale(pair.reference, pair.current).voxel_size
        settings = {"voxel_size": a["voxel_factor"] * derived}
        if a["voxel_factor"] < 1.0:
            settings["max_seconds"] = SMALL_VOXEL_MAX_SECONDS
        out = replace(out, settings=settings, info=out.info | {"derived_voxel_m": derived})
    return out


def _clutter_bodies(set_name: str, rng: np.random.Generator) -> tuple[list[Body], tuple]:
    """3-5 objects of the set upright on the table (2-3 of the larger held-out ones)."""
    pool = MATERIAL[set_name]["objects"]
    low, high, area = (
        (3, 6, case_lib.CLUTTER_AREA)
        if set_name == "calibration"
        else (2, 4, case_lib.HELDOUT_CLUTTER_AREA)
    )
    names = tuple(rng.choice(pool, size=int(rng.integers(low, high)), replace=False))
    meshes = [case_lib.load_mesh(n) for n in names]
    poses = case_lib._place_on_table(meshes, rng, area=area)
    return [(m.vertices, m.faces, T) for m, T in zip(meshes, poses, strict=True)], names


def _scene_bodies(set_name: str, scene: str, rng: np.random.Generator) -> list[Body]:
    if scene == "castle":
        mesh, T = _castle_scene(set_name, rng)
        return [(mesh.vertices, mesh.faces, T)]
    return _clutter_bodies(set_name, rng)[0]


def _two_cameras(rng: np.random.Generator, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference and current cameras 0.55-0.95 m from ``target`` at 30-75 degrees of
    elevation, the current 10-60 degrees of azimuth away, each looking at a point up to
    5 cm off the target."""
    elevation = rng.uniform(30.0, 75.0, size=2)
    azimuth0 = rng.uniform(0.0, 360.0)
    azimuth = azimuth0 + np.array([0.0, rng.choice([-1.0, 1.0]) * rng.uniform(10.0, 60.0)])
    cameras = []
    for e, a in zip(np.radians(elevation), np.radians(azimuth), strict=True):
        direction = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        look = target + rng.uniform(-0.05, 0.05, 3) * np.array([1.0, 1.0, 0.5])
        cameras.append(case_lib.look_at(look + rng.uniform(0.55, 0.95) * direction, look))
    return cameras[0], cameras[1]


def rendered_views(
    set_name: str, scene: str, rng: np.random.Generator, noise_rng: np.random.Generator
) -> tuple[svs.PointCloud, svs.PointCloud, np.ndarray]:
    """Two noisy 320 x 240 views of one rendered scene (a table of objects or a castle)
    in their camera frames, and T_current_reference."""
    bodies = _scene_bodies(set_name, scene, rng)
    T_w_ref, T_w_cur = _two_cameras(rng, np.array([0.0, 0.0, 0.05]))
    reference = render_scan(bodies, True, T_w_ref, VIEW_PAIR_SIZE, noise_rng)
    current = render_scan(bodies, True, T_w_cur, VIEW_PAIR_SIZE, noise_rng)
    return reference, current, np.linalg.inv(T_w_cur) @ T_w_ref


def rendered_pair_case(spec: Spec) -> VerdictCase:
    """Two views of one rendered scene."""
    rng = np.random.default_rng(spec.seed)
    reference, current, T = rendered_views(
        spec.set_name, spec.args["scene"], rng, _stream(spec.seed, 1)
    )
    return VerdictCase(
        spec=spec,
        source=reference,
        target=current,
        T_true=T,
        symmetries=np.eye(4)[None],
        center=reference_centroid(reference),
        sensor_origin=np.zeros(3),
        info={"scene": spec.args["scene"], "rotation_deg": case_lib.rotation_angle_deg(T[:3, :3])},
    )


def share_nothing_case(spec: Spec) -> VerdictCase:
    """Views of two different scenes: a real scan window against a rendered table of
    objects, a rendered castle against a real scan window, a castle against a table."""
    combo, rng = spec.args["combo"], np.random.default_rng(spec.seed)
    noise = _stream(spec.seed, 1)
    first, second = combo.split("_vs_")
    views = []
    for which, role in ((first, "reference"), (second, "current")):
        if which == "scan":
            pair = data.make_view_pair(
                data.scan_path(spec.args["scan"], case_lib.data_dir()),
                downscale=2,
                seed=spec.seed,
            )
            views.append(
                (pair.reference, np.zeros(3))
                if role == "reference"
                else (pair.current, np.asarray(pair.current_viewpoint))
            )
        else:
            reference, _, _ = rendered_views(spec.set_name, which, rng, noise)
            views.append((reference, np.zeros(3)))
    (source, _), (target, origin) = views
    return VerdictCase(
        spec=spec,
        source=source,
        target=target,
        T_true=None,
        symmetries=np.eye(4)[None],
        center=reference_centroid(source),
        sensor_origin=origin,
        info={"combo": combo},
    )


# --- Building and scoring ------------------------------------------------------------------

BUILDERS = {
    "object": object_case,
    "castle": castle_case,
    "scan_frame": scan_frame_case,
    "scan_pair": scan_pair_case,
    "rendered_pair": rendered_pair_case,
    "share_nothing": share_nothing_case,
}


def build_case(spec: Spec) -> VerdictCase:
    """The clouds of ``spec``: the same arrays on every run with the same inputs."""
    return BUILDERS[spec.args["builder"]](spec)


def pose_errors(case: VerdictCase, T: np.ndarray) -> tuple[float, float] | None:
    """(rotation error in degrees, translation error at the case's centre in metres) of an
    estimated source-to-target transform, the smallest over the symmetries
    (``cases.pose_error``); None without a truth."""
    if case.T_true is None:
        return None
    truth = SimpleNamespace(
        model_center=case.center, T_true=case.T_true, symmetries=case.symmetries
    )
    return case_lib.pose_error(truth, np.asarray(T, dtype=float))


def is_right(case: VerdictCase, T: np.ndarray) -> bool:
    """Within 5 degrees and 10 mm of the truth (never, without one)."""
    errors = pose_errors(case, T)
    return errors is not None and errors[0] < RIGHT_DEG and errors[1] < RIGHT_M


def nearest_truth(case: VerdictCase, T: np.ndarray) -> np.ndarray:
    """The symmetric truth ``T_true @ S`` nearest the estimate (rotation first)."""
    T = np.asarray(T, dtype=float)
    candidates = [case.T_true @ S for S in case.symmetries]
    return min(candidates, key=lambda C: case_lib.rotation_angle_deg(C[:3, :3] @ T[:3, :3].T))


def rotation_log(R: np.ndarray) -> np.ndarray:
    """The rotation vector (axis times angle, radians) of a rotation matrix."""
    angle = math.radians(case_lib.rotation_angle_deg(R))
    skew = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-8:
        return skew
    if angle < math.pi - 1e-3:
        return skew * (angle / math.sin(angle))
    # Near a half turn sin(angle) loses the axis: take it from the symmetric part,
    # (R + R^T) / 2 = cos(angle) I + (1 - cos(angle)) a a^T, its largest column.
    outer = (0.5 * (R + R.T) - math.cos(angle) * np.eye(3)) / (1.0 - math.cos(angle))
    axis = outer[:, int(np.argmax(np.diag(outer)))]
    axis /= np.linalg.norm(axis)
    if axis @ skew < 0.0:
        axis = -axis
    return angle * axis


def left_error(T_true: np.ndarray, T_est: np.ndarray) -> np.ndarray:
    """The 6-vector (rotation, translation) of the error of ``T_est`` as a left
    perturbation, T_true = exp(e) T_est to first order: (log(R_true R_est^T),
    t_true - R_true R_est^T t_est)."""
    R = T_true[:3, :3] @ T_est[:3, :3].T
    return np.concatenate([rotation_log(R), T_true[:3, 3] - R @ T_est[:3, 3]])
