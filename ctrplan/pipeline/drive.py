"""Stage 6 of a plan: the drive trajectory along the ordered path (:func:`drive_trajectory`)."""

from __future__ import annotations

from ..errors import JointLimitError
from .setup import PlanSetup

__all__ = ["drive_trajectory"]


def drive_trajectory(setup: PlanSetup, ordered):
    """Stage 6: the drive trajectory along an ordered path, checked against the drive limits.

    Parameters
    ----------
    setup : PlanSetup
        Its scenario's ``[drive]`` limits [rad or m per s, s^2, s^3] and control rate [Hz].
    ordered : OrderedPath
        Waypoints shape (K, n_joints) [rad or m] with their motions.

    Returns
    -------
    Trajectory or None
        Rest-to-rest ruckig segments, stopping between phases
        (:func:`ctrplan.trajectory.time_parameterize_robot`); None when the scenario has no
        ``[drive]`` table.

    Raises
    ------
    JointLimitError
        The sampled trajectory violates a drive limit (the first five violations are named).
    """
    from ..trajectory import check_trajectory, time_parameterize_robot

    sc = setup.scenario
    traj = time_parameterize_robot(setup.robot, ordered.q, ordered.motions, sc.drive) \
        if sc.drive is not None else None
    violations = check_trajectory(traj) if traj is not None else []
    if violations:
        raise JointLimitError(f"{sc.file}: the time-parameterized trajectory violates the drive limits: "
                              + "; ".join(str(v) for v in violations[:5]))
    return traj
