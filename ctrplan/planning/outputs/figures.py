"""Figures of a plan: robot shapes and obstacles, the friction bound along the path, joint
trajectories (``robot_shapes.png``, ``bound_along_path.png``, ``joint_trajectories.png``).

Matplotlib figures rendered by the Agg canvas (:func:`ctrplan.plots.new_figure`: no pyplot, no
window, no change to the user's backend), each written as one PNG atomically
(:func:`ctrplan.plots.save_figure`). Inputs are in SI units (m, rad); figures show mm and degrees,
with units in the axis labels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import matplotlib
import numpy as np
from matplotlib.patches import Patch
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ...obstacles import as_obstacle
from ...plots import M_TO_MM, new_figure, save_figure
from ...trajectory import ROTATION, TRANSLATION, Trajectory

__all__ = ["plot_robot_shapes", "BoundProfile", "plot_bound_along_path", "plot_joint_trajectories",
           "obstacle_triangles", "SPHERE_RESOLUTION"]

# Background colour of each motion phase in time and path plots.
PHASE_COLORS = {ROTATION: "tab:blue", TRANSLATION: "tab:orange"}
PHASE_ALPHA = 0.12
#: Resolution of curved obstacle surfaces in the figures (points per great circle;
#: :meth:`ctrplan.obstacles.Obstacle.triangles`).
SPHERE_RESOLUTION = 16
# Obstacle faces: grey, shaded by their orientation, see-through.
OBSTACLE_COLOR = "0.55"
OBSTACLE_ALPHA = 0.35


# ---------------------------------------------------------------------------------- robot shapes
def plot_robot_shapes(path, shapes: Sequence, obstacles: Sequence = (), friction_tips: Sequence = (),
                      title: str = "", *, labels: Sequence[str] | None = None) -> Path:
    """3-D robot centerlines at the waypoints, obstacles and the tips of the friction solutions.

    Parameters
    ----------
    path : str or Path
        Output PNG.
    shapes : sequence of array-like, shape (K_j, 3)
        Centerline of the robot at each waypoint [m]; drawn in mm, coloured from first to last.
    obstacles : sequence of Obstacle or dict
        :class:`ctrplan.obstacles.Obstacle` instances (any registered type) or dicts with a
        registered ``type`` (:func:`ctrplan.obstacles.obstacle_from_dict`); each is drawn as its
        :meth:`~ctrplan.obstacles.Obstacle.triangles` [m], shown in mm.
    friction_tips : sequence of array-like, shape (m_j, 3)
        Tip positions of the friction-model solutions at waypoint j [m]; drawn as markers.
    title : str
    labels : sequence of str, optional
        Legend entry per shape (default: only first and last are labelled ``waypoint k``).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        A shape or tip array with the wrong shape, or an obstacle of an unknown type or with a bad
        key (the message starts with ``obstacle k``, k 0-based).
    """
    fig = new_figure((7.5, 6.5))
    ax = fig.add_subplot(projection="3d")
    pts_mm = []
    colors = matplotlib.colormaps["viridis"](np.linspace(0.0, 1.0, max(len(shapes), 1)))
    for j, shape in enumerate(shapes):
        xyz = _points(shape, f"shapes[{j}]") * M_TO_MM
        pts_mm.append(xyz)
        if labels is not None:
            label = labels[j]
        else:
            label = f"waypoint {j}" if j in (0, len(shapes) - 1) else None
        ax.plot(xyz[:, 0], xyz[:, 1], xyz[:, 2], color=colors[j], lw=1.5, label=label)
    for j, tips in enumerate(friction_tips):
        xyz = _points(tips, f"friction_tips[{j}]") * M_TO_MM
        if xyz.size == 0:
            continue
        pts_mm.append(xyz)
        ax.scatter(xyz[:, 0], xyz[:, 1], xyz[:, 2], marker="x", s=18, color="tab:red",
                   label="friction-model tips" if j == 0 else None)
    for k, obstacle in enumerate(obstacles):
        pts_mm.append(_draw_obstacle(ax, obstacle, k) * M_TO_MM)
    _equal_3d(ax, pts_mm)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    if title:
        ax.set_title(title)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", fontsize="small")
    return save_figure(fig, path)


def _points(values, label: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.size == 0:
        return arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{label} needs shape (N, 3) [m], got {arr.shape}")
    return arr


def _draw_obstacle(ax, obstacle, k: int) -> np.ndarray:
    """Draw one obstacle (its triangles, in mm); return its vertices [m], shape (V, 3)."""
    verts, faces = obstacle_triangles(obstacle, k, SPHERE_RESOLUTION)
    ax.add_collection3d(Poly3DCollection(verts[faces] * M_TO_MM, facecolors=OBSTACLE_COLOR, linewidths=0.0,
                                         alpha=OBSTACLE_ALPHA, shade=True))
    return verts


def obstacle_triangles(obstacle, k: int, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of an obstacle or obstacle dict as both drawings use them
    (:meth:`~ctrplan.obstacles.Obstacle.triangles`): the figures at :data:`SPHERE_RESOLUTION`, the
    3-D view (:mod:`~ctrplan.planning.outputs.view`) at its own.

    Parameters
    ----------
    obstacle : Obstacle or mapping
    k : int
        Its index in the list drawn (0-based, as in the scenario's ``obstacles``), for messages.
    resolution : int
        Segments of a round outline (points per great circle of a sphere).

    Returns
    -------
    vertices : ndarray, shape (V, 3)
        [m], base frame.
    faces : ndarray of int, shape (F, 3)

    Raises
    ------
    ValueError
        Any problem (unknown type, bad key, triangles of the wrong shape); the message starts
        with ``obstacle k``.
    """
    try:
        verts, faces = as_obstacle(obstacle).triangles(resolution)
    except (ValueError, TypeError, AttributeError) as exc:
        raise ValueError(f"obstacle {k}: {exc}") from None
    verts = np.asarray(verts, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    if verts.ndim != 2 or verts.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"obstacle {k}: triangles need vertices (V, 3) and faces (F, 3), got {verts.shape} "
                         f"and {faces.shape}")
    return verts, faces


def _equal_3d(ax, pts_mm):
    pts = np.concatenate([p.reshape(-1, 3) for p in pts_mm]) if pts_mm else np.zeros((0, 3))
    if pts.shape[0] == 0:
        return
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = 0.5 * (lo + hi), 0.5 * max(float(np.max(hi - lo)), 1e-3)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))


# ---------------------------------------------------------------------------------- bound
@dataclass(frozen=True, eq=False)
class BoundProfile:
    """The friction-induced tip error bound along one plan's ordered waypoints, as
    :func:`plot_bound_along_path` draws it (SI; the figure shows mm).

    Attributes
    ----------
    s : array-like, shape (K,)
        Path parameter of each waypoint (e.g. normalized arc length) [-, or the unit the
        figure's ``s_label`` names].
    bound : array-like, shape (K,)
        Tip error bound b(q) at each waypoint [m] (friction model, Section III of Ha, Fagogenis &
        Dupont 2019).
    translation_last : array-like, shape (K,)
        Bound at each waypoint when reached by a translation last [m]; NaN where not available.
    motions : sequence of str, length K
        Motion that reaches each waypoint (``"start"``, ``"rotation"``, ``"translation"``); the
        interval before waypoint k is shaded by ``motions[k]``.
    given_last : array-like, shape (K,), optional
        Bound given the last motion at each waypoint [m]: the translation-last bound along a
        translation phase, the friction bound along a rotation (what the plan's cost
        integrates).
    label : str
        Title of the plan's panel.
    """

    s: object
    bound: object
    translation_last: object
    motions: Sequence[str]
    given_last: object = None
    label: str = "plan"


def plot_bound_along_path(path, profiles, *, threshold: float | None = None, s_label: str = "path parameter s [-]",
                          title: str = "") -> Path:
    """Friction-induced tip error bound along one or more plans, side by side (one panel each).

    Each panel's title leads with the largest bound the plan optimized: the bound given the last
    motion when the profile has it (Section V-B of Ha, Fagogenis & Dupont 2019), then the
    largest friction bound; else the largest friction bound.

    Parameters
    ----------
    path : str or Path
        Output PNG.
    profiles : BoundProfile or sequence of BoundProfile
        One per plan [m].
    threshold : float, optional
        Allowed bound, drawn as a horizontal line [m].
    s_label : str
        Label of the horizontal axis, with its unit.
    title : str

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        No profile, or the arrays of one profile of different lengths (naming the plan).
    """
    profiles = [profiles] if isinstance(profiles, BoundProfile) else list(profiles)
    n_plans = len(profiles)
    if n_plans == 0:
        raise ValueError("need at least one plan's bound profile")
    threshold_mm = None if threshold is None else threshold * M_TO_MM
    fig = new_figure((5.5 * n_plans, 4.0))
    axes = fig.subplots(1, n_plans, sharey=True, squeeze=False)
    for j, ax in enumerate(axes[0]):
        prof = profiles[j]
        s = np.asarray(prof.s, dtype=float)
        b = np.asarray(prof.bound, dtype=float) * M_TO_MM
        tl = np.asarray(prof.translation_last, dtype=float) * M_TO_MM
        motions = list(prof.motions)
        if not (b.shape == tl.shape == s.shape and len(motions) == s.size):
            raise ValueError(f"plan {j} ({prof.label}): s, bound, translation_last and motions need equal "
                             f"lengths, got {s.shape}, {b.shape}, {tl.shape}, {len(motions)}")
        _shade_phases(ax, [(s[k - 1], s[k], motions[k]) for k in range(1, s.size)])
        ax.plot(s, b, "o-", ms=3, color="tab:red", label="friction bound")
        if np.any(np.isfinite(tl)):
            ax.plot(s, tl, "s--", ms=3, color="tab:purple", label="translation-last bound")
        if threshold_mm is not None:
            ax.axhline(threshold_mm, color="k", ls=":", lw=1, label=f"limit {threshold_mm:.3g} mm")
        peak = np.nanmax(b) if np.any(np.isfinite(b)) else float("nan")
        name = prof.label
        if prof.given_last is None:
            ax.set_title(f"{name} (max {peak:.3g} mm)")
        else:
            g = np.asarray(prof.given_last, dtype=float) * M_TO_MM
            if g.shape != s.shape:
                raise ValueError(f"plan {j} ({name}): given_last needs the length of s, got {g.shape} and {s.shape}")
            ax.plot(s, g, "-", lw=2.5, alpha=0.5, color="tab:green", label="bound given the last motion")
            top = np.nanmax(g) if np.any(np.isfinite(g)) else float("nan")
            ax.set_title(f"{name}: max {top:.3g} mm given the last motion\n(friction bound max {peak:.3g} mm)",
                         fontsize="medium")
        ax.set_xlabel(s_label)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("tip error bound [mm]")
    handles = {}  # one legend entry per label over all panels
    for ax in axes[0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    axes[0, -1].legend(handles=list(handles.values()) + _phase_handles(), fontsize="small")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


# ---------------------------------------------------------------------------------- trajectory
def plot_joint_trajectories(path, traj: Trajectory, joint_names: Sequence[str] | None = None,
                            joint_kinds: Sequence[str] | None = None, *, title: str = "") -> Path:
    """Position, velocity and acceleration of every joint over time, motion phases shaded.

    Rotations are shown in degrees (deg, deg/s, deg/s^2), translations in millimetres
    (mm, mm/s, mm/s^2).

    Parameters
    ----------
    path : str or Path
        Output PNG.
    traj : ctrplan.trajectory.Trajectory
        Arrays ``t`` (T,) [s] and ``position``, ``velocity``, ``acceleration`` (T, n_joints)
        [rad or m, per s, per s^2].
    joint_names, joint_kinds : sequence of str, length n_joints, optional
        Default: ``traj.joint_names`` and ``traj.joint_kinds``.
    title : str

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        If names or kinds do not match the number of joints.
    """
    n = traj.position.shape[1]
    names = list(traj.joint_names if joint_names is None else joint_names)
    kinds = list(traj.joint_kinds if joint_kinds is None else joint_kinds)
    if len(names) != n or len(kinds) != n:
        raise ValueError(f"need {n} joint names and kinds, got {len(names)} and {len(kinds)}")
    fig = new_figure((12, 2.2 * n + 0.8))
    axes = fig.subplots(n, 3, sharex=True, squeeze=False)
    phases = [(s.t_start, s.t_end, s.motion) for s in traj.segments]
    for i in range(n):
        scale, unit = (np.degrees(1.0), "deg") if kinds[i] == ROTATION else (M_TO_MM, "mm")
        for col, (values, suffix) in enumerate(((traj.position, ""), (traj.velocity, "/s"),
                                                (traj.acceleration, "/s^2"))):
            ax = axes[i, col]
            _shade_phases(ax, phases)
            ax.plot(traj.t, values[:, i] * scale, color="k", lw=1.0)
            ax.set_ylabel(f"{names[i]} [{unit}{suffix}]")
            ax.grid(alpha=0.3)
    for col, label in enumerate(("position", "velocity", "acceleration")):
        axes[0, col].set_title(label)
        axes[-1, col].set_xlabel("time t [s]")
    axes[0, -1].legend(handles=_phase_handles(), fontsize="small", loc="upper right")
    fig.suptitle(title or f"joint trajectories, duration {traj.duration:.3f} s")
    return save_figure(fig, path)


# ---------------------------------------------------------------------------------- phases
def _shade_phases(ax, phases):
    for start, end, motion in phases:
        if motion in PHASE_COLORS and end > start:
            ax.axvspan(start, end, color=PHASE_COLORS[motion], alpha=PHASE_ALPHA, lw=0)


def _phase_handles():
    return [Patch(color=c, alpha=3 * PHASE_ALPHA, label=f"{m} phase") for m, c in PHASE_COLORS.items()]
