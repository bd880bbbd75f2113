"""View pairs rendered in the simulation (:func:`sim_view_pairs`): the wrist camera of the
simulated iiwa at its home pose and at seeded start poses, with the true relative pose
(:class:`~spectral_vs.data.view_pairs.ViewPair`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from spectral_vs.data.view_pairs import ViewPair

if TYPE_CHECKING:
    from spectral_vs.sim import SimParams


def sim_view_pairs(
    count: int,
    *,
    start_set: str = "large",
    seed: int = 0,
    params: SimParams | None = None,
    min_view_share: float = 0.3,
) -> list[ViewPair]:
    """``count`` rendered pairs of the simulated table: the wrist camera's view at the
    home pose (reference) and at the seeded start poses of
    :func:`spectral_vs.experiment.start_poses` (current).

    The ground truth is ``T_current_reference = inv(T_world_current) T_world_reference``
    from the simulation's camera poses; both views are in their camera frames with normals
    toward the camera (``robot.capture()``), the current's viewpoint at the origin.

    Parameters
    ----------
    count : int
        Number of pairs, >= 1.
    start_set : str
        A key of ``spectral_vs.experiment.START_SETS`` (``"moderate"`` or ``"large"``).
    seed : int
        Seed of the start poses.
    min_view_share : float
        Least share of the reference's points in the current camera's field of view
        (``PyBulletRobot.view_check``, occlusion ignored), in (0, 1].
    params : spectral_vs.sim.SimParams, optional
        The simulation (kinematic, 320 x 240, the iiwa at ``sim.HOME_Q`` by default); the
        reference is rendered at its start configuration ``params.q_start``.

    Returns
    -------
    list of ViewPair

    Raises
    ------
    ValueError
        If ``count`` < 1 or ``start_set`` is unknown.
    ImportError
        Without PyBullet.
    """
    from spectral_vs import sim
    from spectral_vs.experiment import start_poses

    params = params if params is not None else sim.SimParams()
    size = (params.camera.intrinsics.width, params.camera.intrinsics.height)
    pairs = []
    with sim.PyBulletRobot(params) as robot:
        q_home = robot.joint_positions() if params.q_start is None else params.q_start
        # As the extreme set: only starts that keep 30% of the reference's points in view
        # (two views that share less are not the same scene seen twice).
        accept = robot.view_check(min_share=min_view_share, q_reference=q_home)
        starts = start_poses(robot.kinematics, start_set, count, seed, q_home, accept)
        robot.reset_joint_positions(q_home)
        reference, T_world_reference = robot.capture(), robot.camera_pose()
        for q, _, _ in starts:
            robot.reset_joint_positions(q)
            current, T_world_current = robot.capture(), robot.camera_pose()
            pairs.append(
                ViewPair(
                    name="sim",
                    reference=reference,
                    current=current,
                    T_current_reference=np.linalg.inv(T_world_current) @ T_world_reference,
                    current_viewpoint=np.zeros(3),
                    overlap=None,
                    image_size=size,
                )
            )
    return pairs
