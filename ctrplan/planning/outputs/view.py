"""Interactive 3-D view of a plan: a self-contained HTML file (plotly, no network needed).

The view shows the robot at each ordered waypoint of a plan, one waypoint at a time, chosen with
a slider along the trajectory: the standard-model centerline, the shape predicted for the motion
history the plan creates (:func:`ctrplan.mechanics.predict_tip`, Section V-B of Ha, Fagogenis &
Dupont 2019, doi:10.1109/TRO.2018.2878906), and the friction envelope, i.e. the centerlines and
tips of the 2^(n-1) bounding friction solutions (Section III, Eqs. (37)-(47)). The obstacles
(each as the triangles it gives, :mod:`ctrplan.obstacles`) and the targets are drawn at every
step, with the standard-model tip path over all waypoints for orientation.

Inputs are in SI units (m); the view shows mm. The file embeds plotly.js (about 4.8 MB), so it
opens offline. Building the view does no mechanics solves: it draws what the plan already has.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ...io.atomic import atomic_path

__all__ = ["PLAN_VIEW_FILE", "WaypointFrames", "plan_view_figure", "write_plan_view"]

#: File name of the interactive view in a plan's output folder.
PLAN_VIEW_FILE = "plan.html"
M_TO_MM = 1e3
# Coordinates are written in mm rounded to this many decimals (0.1 um): far below any bound the
# view shows, and it keeps the file small.
MM_DECIMALS = 4
# Points per great circle of sphere and capsule surfaces.
SPHERE_RESOLUTION = 24
OBSTACLE_COLOR = "rgb(140,140,140)"
OBSTACLE_OPACITY = 0.35
STANDARD_COLOR = "rgb(31,119,180)"
PREDICTED_COLOR = "rgb(255,127,14)"
FRICTION_COLOR = "rgb(214,39,40)"
TARGET_COLOR = "rgb(44,160,44)"


@dataclass(frozen=True, eq=False)
class WaypointFrames:
    """What the view shows at each of the K ordered waypoints of a plan (one slider step each).

    Attributes
    ----------
    standard : sequence of (array-like, shape (N_k, 3)) or None, length K
        Standard-model centerline at each ordered waypoint k [m], base first (None or empty
        where it is unknown: the step then shows no standard shape).
    friction_tips : sequence of array-like, shape (m_k, 3), length K, optional
        Tips of the bounding friction solutions at waypoint k [m] (m_k = 2^(n-1) when all were
        solved).
    friction_shapes : sequence of (sequence of array-like, shape (N, 3)), length K, optional
        Centerlines of those solutions at waypoint k [m] (innermost tube, base to tip); drawn
        as one trace per waypoint.
    predicted_tips : array-like, shape (K, 3), optional
        Tip predicted for the plan's motion history [m]; NaN rows are not drawn.
    predicted_shapes : sequence of (array-like, shape (N_k, 3)) or None, length K, optional
        Predicted centerline [m]; None where it is unknown.
    labels : sequence of str, length K, optional
        Slider label of each step (default: the waypoint index).
    notes : sequence of str, length K, optional
        Text added to the title at each step (e.g. the motion and the bound).
    """

    standard: Sequence
    friction_tips: Sequence | None = None
    friction_shapes: Sequence | None = None
    predicted_tips: object = None
    predicted_shapes: Sequence | None = None
    labels: Sequence[str] | None = None
    notes: Sequence[str] | None = None


def plan_view_figure(frames: WaypointFrames, *, obstacles: Sequence = (), targets=None, title: str = ""):
    """Build the plotly figure of :func:`write_plan_view` (same parameters, without ``path``).

    Returns
    -------
    plotly.graph_objects.Figure
        Static traces first (obstacles, the targets, the standard-model tip path), then per
        waypoint k, in order, the traces ``standard``, ``predicted``, ``predicted tip``,
        ``friction envelope`` and ``friction tips``, named ``"<name> (waypoint k)"`` and visible
        only at slider step k. ``layout.sliders[0].steps`` has one step per waypoint.
    """
    import plotly.graph_objects as go

    standard = frames.standard
    K = len(standard)
    friction_tips = _per_waypoint(frames.friction_tips, K, "friction_tips")
    friction_shapes = _per_waypoint(frames.friction_shapes, K, "friction_shapes")
    predicted_shapes = _per_waypoint(frames.predicted_shapes, K, "predicted_shapes")
    pred_tips = (np.full((K, 3), np.nan) if frames.predicted_tips is None
                 else np.asarray(frames.predicted_tips, dtype=float))
    if pred_tips.shape != (K, 3):
        raise ValueError(f"predicted_tips needs shape ({K}, 3) [m], got {pred_tips.shape}")
    labels = [str(k) for k in range(K)] if frames.labels is None else list(frames.labels)
    notes = [""] * K if frames.notes is None else list(frames.notes)
    if len(labels) != K or len(notes) != K:
        raise ValueError(f"labels and notes need one entry per waypoint ({K}), got {len(labels)} and {len(notes)}")

    from .figures import obstacle_triangles

    fig = go.Figure()
    for k, obstacle in enumerate(obstacles):
        verts, faces = obstacle_triangles(obstacle, k, SPHERE_RESOLUTION)
        x, y, z = _mm(verts)
        fig.add_trace(go.Mesh3d(x=x, y=y, z=z, i=faces[:, 0].tolist(), j=faces[:, 1].tolist(),
                                k=faces[:, 2].tolist(), color=OBSTACLE_COLOR, opacity=OBSTACLE_OPACITY,
                                flatshading=True, name=f"obstacle {k + 1} ({_obstacle_kind(obstacle)})",
                                showlegend=True, hoverinfo="name"))
    if targets is not None and np.asarray(targets).size:
        tgt = _points(targets, "targets")
        x, y, z = _mm(tgt)
        fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="markers+text", name="targets",
                                   text=[f"goal {g + 1}" for g in range(len(tgt))],
                                   marker=dict(symbol="diamond", size=6, color=TARGET_COLOR)))
    tips = np.array([_points(c, f"standard[{k}]")[-1] if c is not None and np.asarray(c).size else
                     np.full(3, np.nan) for k, c in enumerate(standard)]).reshape(-1, 3)
    x, y, z = _mm(tips)
    fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="lines+markers", name="standard tip path",
                               line=dict(color="rgba(31,119,180,0.35)", width=2),
                               marker=dict(size=2, color="rgba(31,119,180,0.5)")))
    n_static = len(fig.data)

    for k in range(K):
        visible = k == 0
        x, y, z = _mm(_points(standard[k], f"standard[{k}]"))
        fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="lines", name=f"standard (waypoint {k})",
                                   line=dict(color=STANDARD_COLOR, width=6), visible=visible))
        x, y, z = _mm(_points(predicted_shapes[k], f"predicted_shapes[{k}]"))
        fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="lines", name=f"predicted (waypoint {k})",
                                   line=dict(color=PREDICTED_COLOR, width=4, dash="dash"), visible=visible))
        x, y, z = _mm(pred_tips[k:k + 1][np.all(np.isfinite(pred_tips[k:k + 1]), axis=1)])
        fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="markers", name=f"predicted tip (waypoint {k})",
                                   marker=dict(size=5, color=PREDICTED_COLOR, symbol="circle"),
                                   visible=visible))
        shapes = () if friction_shapes[k] is None else friction_shapes[k]
        x, y, z = _joined([_points(s, f"friction_shapes[{k}]") for s in shapes])
        fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="lines", name=f"friction envelope (waypoint {k})",
                                   line=dict(color=FRICTION_COLOR, width=2), opacity=0.6,
                                   visible=visible))
        x, y, z = _mm(_points(friction_tips[k], f"friction_tips[{k}]"))
        fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="markers", name=f"friction tips (waypoint {k})",
                                   marker=dict(size=4, color=FRICTION_COLOR, symbol="x"),
                                   visible=visible))
    per = (len(fig.data) - n_static) // max(K, 1)

    def heading(k):
        return f"{title} - waypoint {labels[k]}" + (f": {notes[k]}" if notes[k] else "")

    steps = []
    for k in range(K):
        vis = [True] * n_static + [j // per == k for j in range(K * per)]
        steps.append(dict(method="update", label=labels[k],
                          args=[{"visible": vis}, {"title.text": heading(k)}]))
    fig.update_layout(
        title=dict(text=heading(0) if K else title),
        scene=dict(xaxis_title="x [mm]", yaxis_title="y [mm]", zaxis_title="z [mm]", aspectmode="data"),
        sliders=[dict(active=0, steps=steps, currentvalue=dict(prefix="waypoint "), pad=dict(t=30))],
        legend=dict(itemsizing="constant"), margin=dict(l=0, r=0, t=50, b=0),
    )
    return fig


def write_plan_view(path, frames: WaypointFrames, *, obstacles: Sequence = (), targets=None,
                    title: str = "") -> Path:
    """Write the interactive view of a plan to a self-contained HTML file, atomically.

    Parameters
    ----------
    path : str or Path
        Output HTML file (its folder must exist). It embeds plotly.js: no network is needed to
        open it.
    frames : WaypointFrames
        The standard, predicted and friction shapes and tips at each of the K ordered waypoints
        [m], with the slider's labels and notes.
    obstacles : sequence of Obstacle or dict
        :class:`ctrplan.obstacles.Obstacle` instances (any registered type, e.g. a scenario's
        ``obstacles``) or dicts with a registered ``type``
        (:func:`ctrplan.obstacles.obstacle_from_dict`); each is drawn as its
        :meth:`~ctrplan.obstacles.Obstacle.triangles` (:func:`~ctrplan.planning.outputs.figures.obstacle_triangles` at
        ``SPHERE_RESOLUTION``).
    targets : array-like, shape (G, 3), optional
        Goal tip positions [m].
    title : str

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        An array of the wrong shape, a per-waypoint sequence whose length is not K, or an
        obstacle of an unknown type, with a bad key or a missing mesh file.
    FileNotFoundError
        The output folder does not exist.
    """
    fig = plan_view_figure(frames, obstacles=obstacles, targets=targets, title=title)
    path = Path(path)
    html = fig.to_html(include_plotlyjs=True, full_html=True, config={"displaylogo": False})
    with atomic_path(path) as tmp:
        tmp.write_text(html, encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------- obstacles
def _obstacle_kind(obstacle) -> str:
    """The ``type`` of an obstacle or an obstacle dict (the class name for a duck-typed one)."""
    if isinstance(obstacle, dict):
        return str(obstacle.get("type", "?"))
    return str(getattr(obstacle, "type", type(obstacle).__name__))


# ---------------------------------------------------------------------------------- helpers
def _per_waypoint(values, K: int, label: str) -> list:
    if values is None:
        return [None] * K
    values = list(values)
    if len(values) != K:
        raise ValueError(f"{label} needs one entry per waypoint ({K}), got {len(values)}")
    return values


def _points(values, label: str) -> np.ndarray:
    if values is None:
        return np.zeros((0, 3))
    arr = np.asarray(values, dtype=float)
    if arr.size == 0:
        return arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{label} needs shape (N, 3) [m], got {arr.shape}")
    return arr


def _mm(xyz: np.ndarray) -> tuple[list, list, list]:
    """x, y, z lists in mm (plain lists: the HTML carries readable numbers; NaN -> null, a gap)."""
    mm = np.round(np.asarray(xyz, dtype=float).reshape(-1, 3) * M_TO_MM, MM_DECIMALS)
    return tuple([None if not np.isfinite(c) else float(c) for c in mm[:, i]] for i in range(3))


def _joined(lines: Sequence[np.ndarray]) -> tuple[list, list, list]:
    """Several polylines [m] as one trace in mm, separated by gaps."""
    gap = np.full((1, 3), np.nan)
    parts = [p for line in lines if line.size for p in (line, gap)]
    return _mm(np.concatenate(parts) if parts else np.zeros((0, 3)))
