"""A plan's figures and output files (ctrplan.planning.outputs) and the shared figure helpers
(ctrplan.plots)."""

import csv
import json

import numpy as np
import pytest

import ctrplan.io.atomic as atomic
import ctrplan.planning.outputs.figures as plan_figures
import ctrplan.plots as plots
from ctrplan.planning.outputs.figures import (BoundProfile, plot_bound_along_path, plot_joint_trajectories,
                                             plot_robot_shapes)
from ctrplan.planning.outputs.folder import format_summary, path_columns, write_plan_outputs
from ctrplan.plots import plot_xy
from ctrplan.drive import DriveLimits, JointLimits
from ctrplan.trajectory import time_parameterize

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
NAMES = ["alpha_2", "alpha_3", "beta_3"]
KINDS = ["rotation", "rotation", "translation"]
WAYPOINTS = np.array([[3.0, -1.0, -0.090], [-3.0, 0.5, -0.090], [-3.0, 0.5, -0.050], [-2.0, 0.2, -0.050]])
MOTIONS = ["start", "rotation", "translation", "rotation"]


@pytest.fixture(scope="module")
def traj():
    joints = JointLimits(tuple(NAMES), tuple(KINDS), [-np.pi, -np.pi, -0.104], [np.pi, np.pi, -0.034],
                         [True, True, False])
    return time_parameterize(WAYPOINTS, MOTIONS, joints,
                             DriveLimits(100.0, [1.0, 1.5, 0.01], [2.0, 3.0, 0.05], [20.0, 30.0, 1.0]))


def _is_png(path):
    data = path.read_bytes()
    return len(data) > 1000 and data.startswith(PNG_MAGIC)


def _no_temp_files(folder):
    return [p.name for p in folder.iterdir() if p.name.endswith(".tmp")] == []


def _shapes():
    s = np.linspace(0.0, 0.1, 30)
    return [np.column_stack([0.02 * k * s**2, np.zeros_like(s), s]) for k in range(4)]


@pytest.fixture
def figures(monkeypatch):
    """The matplotlib Figures the plot functions write, in order (``save_figure`` still writes)."""
    captured = []
    save = plots.save_figure

    def spy(fig, path):
        captured.append(fig)
        return save(fig, path)

    monkeypatch.setattr(plots, "save_figure", spy)
    monkeypatch.setattr(plan_figures, "save_figure", spy)
    return captured


def _lines_with_label(ax, label):
    return [ln for ln in ax.get_lines() if ln.get_label() == label]


# ---------------------------------------------------------------------------------- plots
def test_robot_shapes_with_every_obstacle_type(tmp_path, figures):
    """The PNG is written, and the figure shows one 3-D axes in mm with one centerline per
    waypoint, equal to the input in mm (catches a dropped shape, a wrong unit or axis swap),
    the friction tips as one marker set, and every obstacle drawn."""
    obstacles = [
        {"type": "sphere", "center_m": [0.02, 0.0, 0.08], "radius_m": 0.005},
        {"type": "capsule", "a_m": [-0.02, 0.0, 0.05], "b_m": [-0.02, 0.01, 0.09], "radius_m": 0.003},
        {"type": "box", "center_m": [0.0, 0.03, 0.06], "size_m": [0.01, 0.02, 0.005],
         "rpy_rad": [0.1, 0.2, 0.3]},
        {"type": "mesh", "vertices": [[0, 0, 0.1], [0.01, 0, 0.1], [0, 0.01, 0.1], [0, 0, 0.11]],
         "faces": [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]},
    ]
    tips = [np.array([[0.0, 0.0, 0.1], [0.001, 0.0, 0.1]]), np.zeros((0, 3))]
    out = plot_robot_shapes(tmp_path / "shapes.png", _shapes(), obstacles, tips, "test")
    assert out == tmp_path / "shapes.png" and _is_png(out)
    assert _no_temp_files(tmp_path)
    (fig,) = figures
    (ax,) = fig.axes
    assert ax.name == "3d" and ax.get_title() == "test"
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()) == ("x [mm]", "y [mm]", "z [mm]")
    lines = ax.get_lines()
    assert len(lines) == len(_shapes())
    for line, shape in zip(lines, _shapes()):
        np.testing.assert_allclose(np.column_stack(line.get_data_3d()), shape * 1e3, rtol=1e-12)
    # first and last waypoint labelled; friction tips: one scatter with the two non-empty tips
    assert [ln.get_label() for ln in lines][::3] == ["waypoint 0", "waypoint 3"]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts == ["waypoint 0", "waypoint 3", "friction-model tips"]
    scatters = [c for c in ax.collections if c.get_label() == "friction-model tips"]
    assert len(scatters) == 1 and len(scatters[0].get_offsets()) == 2
    # sphere and capsule are surfaces, box and mesh polygon sets: four obstacle collections
    assert len(ax.collections) == 1 + len(obstacles)


def test_robot_shapes_accepts_obstacle_dataclasses(tmp_path):
    from ctrplan.obstacles import obstacle_from_dict

    obstacles = [obstacle_from_dict({"type": "sphere", "center_m": [0.0, 0.0, 0.05], "radius_m": 0.004}),
                 obstacle_from_dict({"type": "box", "center_m": [0.01, 0.0, 0.05], "size_m": [0.01, 0.01, 0.01]})]
    assert _is_png(plot_robot_shapes(tmp_path / "s.png", _shapes(), obstacles))


def test_robot_shapes_with_a_mesh_file(tmp_path):
    import trimesh

    trimesh.creation.box(extents=(10.0, 10.0, 10.0)).export(tmp_path / "cube.stl")
    obstacle = {"type": "mesh", "path": str(tmp_path / "cube.stl"), "scale": 1e-3,
                "translation_m": [0.0, 0.0, 0.05], "rpy_rad": [0.0, 0.0, 0.5]}
    assert _is_png(plot_robot_shapes(tmp_path / "m.png", _shapes(), [obstacle]))


def test_unknown_obstacle_raises_and_writes_nothing(tmp_path):
    with pytest.raises(ValueError, match="obstacle 0: unknown type 'cone'"):
        plot_robot_shapes(tmp_path / "x.png", _shapes(), [{"type": "cone"}])
    assert list(tmp_path.iterdir()) == []


def _profiles(s, bound_mm, tl_mm, motions, given_mm=None):
    """Two plans' profiles in SI from figures in mm."""
    labels = ("bound-aware plan", "bound-blind plan")
    return [BoundProfile(s[j], bound_mm[j] * 1e-3, tl_mm[j] * 1e-3, motions[j],
                         given_last=None if given_mm is None else given_mm[j] * 1e-3, label=labels[j])
            for j in range(len(s))]


def test_bound_along_two_plans_and_one_plan(tmp_path, figures):
    """One panel per plan; each shows its bound (given in m) in mm, the translation-last bound only
    where there is one, the limit line, the plan's maximum in the title and a y label with its
    unit. Catches plans drawn into one panel or swapped, a unit conversion applied twice or
    not at all, a missing limit."""
    s = [np.linspace(0, 1, 4), np.linspace(0, 1, 3)]
    bound = [np.array([0.5, 1.0, 0.8, 0.6]), np.array([0.5, 2.5, 1.1])]
    tl = [np.array([np.nan, np.nan, 0.4, np.nan]), np.full(3, np.nan)]
    motions = [MOTIONS, ["start", "rotation", "translation"]]
    profiles = _profiles(s, bound, tl, motions)
    assert _is_png(plot_bound_along_path(tmp_path / "b2.png", profiles, threshold=1.5e-3))
    assert _is_png(plot_bound_along_path(tmp_path / "b1.png", BoundProfile(s[0], bound[0] * 1e-3, tl[0] * 1e-3,
                                                                            MOTIONS)))
    two, one = figures
    assert len(two.axes) == 2 and len(one.axes) == 1
    assert two.axes[0].get_ylabel() == "tip error bound [mm]"
    for j, ax in enumerate(two.axes):
        (line,) = _lines_with_label(ax, "friction bound")
        np.testing.assert_array_equal(line.get_xdata(), s[j])
        np.testing.assert_allclose(line.get_ydata(), bound[j], rtol=1e-12)
        (limit,) = _lines_with_label(ax, "limit 1.5 mm")
        assert list(limit.get_ydata()) == pytest.approx([1.5, 1.5], rel=1e-12)
        assert ax.get_xlabel() == "path parameter s [-]"
    assert two.axes[0].get_title() == "bound-aware plan (max 1 mm)"
    assert two.axes[1].get_title() == "bound-blind plan (max 2.5 mm)"
    (tl_line,) = _lines_with_label(two.axes[0], "translation-last bound")
    np.testing.assert_allclose(tl_line.get_ydata(), tl[0], rtol=1e-12)
    assert _lines_with_label(two.axes[1], "translation-last bound") == []   # all NaN: not drawn
    # one shaded span per motion phase (3 phases in plan 0, 2 in plan 1)
    assert [len(ax.patches) for ax in two.axes] == [3, 2]
    assert one.axes[0].get_title() == "plan (max 1 mm)"
    with pytest.raises(ValueError, match="plan 1"):
        plot_bound_along_path(tmp_path / "bad.png", _profiles(s, [bound[0], bound[0]], tl, motions))
    with pytest.raises(ValueError, match="at least one"):
        plot_bound_along_path(tmp_path / "none.png", [])


def test_bound_along_path_leads_with_the_bound_given_the_last_motion(tmp_path, figures):
    """With the bound given the last motion (what the plan optimized), the title leads with its
    maximum and gives the friction bound's second, and the curve is drawn as given: catches a
    title that quotes the full friction bound of the shared goal for both plans."""
    s = [np.linspace(0, 1, 4), np.linspace(0, 1, 3)]
    bound = [np.array([0.5, 5.29, 0.8, 0.6]), np.array([0.5, 5.29, 1.1])]
    tl = [np.array([np.nan, np.nan, 0.4, np.nan]), np.full(3, np.nan)]
    given = [np.array([0.5, 3.1, 0.4, 0.6]), np.array([0.5, 4.9, 1.1])]
    motions = [MOTIONS, ["start", "rotation", "translation"]]
    assert _is_png(plot_bound_along_path(tmp_path / "g.png", _profiles(s, bound, tl, motions, given)))
    (fig,) = figures
    assert fig.axes[0].get_title().startswith("bound-aware plan: max 3.1 mm given the last motion")
    assert fig.axes[1].get_title().startswith("bound-blind plan: max 4.9 mm given the last motion")
    assert "friction bound max 5.29 mm" in fig.axes[0].get_title()
    for j, ax in enumerate(fig.axes):
        (line,) = _lines_with_label(ax, "bound given the last motion")
        np.testing.assert_allclose(line.get_ydata(), given[j], rtol=1e-12)
    with pytest.raises(ValueError, match="given_last"):
        plot_bound_along_path(tmp_path / "bad.png", _profiles(s, bound, tl, motions, [given[0], given[0][:2]]))


def test_joint_trajectories_and_xy(tmp_path, traj, figures):
    """Joint plot: a 3 x 3 grid (joints x position / velocity / acceleration) whose curves are
    the trajectory in deg or mm (per s, per s^2) against t, with the unit in each y label.
    Generic plot: one axes, one curve equal to its input, the given labels. Catches a missing
    joint or derivative, a swapped column, a rotation shown in rad or a translation in m."""
    assert _is_png(plot_joint_trajectories(tmp_path / "joints.png", traj))
    assert _is_png(plot_xy(tmp_path / "xy.png", traj.t, traj.position[:, 2] * 1e3,
                           xlabel="time t [s]", ylabel="beta_3 [mm]"))
    joints, xy = figures
    assert len(joints.axes) == 9
    grid = np.array(joints.axes).reshape(3, 3)
    units = {"rotation": ("deg", np.degrees(1.0)), "translation": ("mm", 1e3)}
    for i, (name, kind) in enumerate(zip(NAMES, KINDS)):
        unit, scale = units[kind]
        for col, (values, suffix) in enumerate(((traj.position, ""), (traj.velocity, "/s"),
                                                (traj.acceleration, "/s^2"))):
            ax = grid[i, col]
            assert ax.get_ylabel() == f"{name} [{unit}{suffix}]"
            (line,) = ax.get_lines()
            np.testing.assert_array_equal(line.get_xdata(), traj.t)
            np.testing.assert_allclose(line.get_ydata(), values[:, i] * scale, rtol=1e-12)
    assert [ax.get_xlabel() for ax in grid[-1]] == ["time t [s]"] * 3
    (ax,) = xy.axes
    (line,) = ax.get_lines()
    np.testing.assert_array_equal(line.get_xdata(), traj.t)
    np.testing.assert_array_equal(line.get_ydata(), traj.position[:, 2] * 1e3)
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time t [s]", "beta_3 [mm]")
    with pytest.raises(ValueError, match="3 joint names"):
        plot_joint_trajectories(tmp_path / "j.png", traj, joint_names=["a"])


# ---------------------------------------------------------------------------------- report
def _rows():
    rows = []
    for k, (q, m) in enumerate(zip(WAYPOINTS, MOTIONS)):
        rows.append({"motion": m, "q": q, "tip": [0.001 * k, 0.0, 0.1],
                     "bound_position_m": 1e-3 * (k + 1), "bound_angle_rad": 0.01,
                     "bound_kind": "translation_last" if m == "translation" else "friction"})
    return rows


SUMMARY = {"max_bound_mm": np.float64(1.25), "planner": "RRTstar", "solved": np.bool_(True),
           "bound_per_waypoint_mm": np.array([0.5, np.nan])}


def test_write_plan_outputs(tmp_path, traj):
    out = tmp_path / "run"
    figures = {"joints.png": lambda p: plot_joint_trajectories(p, traj)}
    written = write_plan_outputs(out, _rows(), traj, SUMMARY, figures=figures)
    assert set(written) == {"path.csv", "trajectory.csv", "summary.json", "joints.png"}
    assert _is_png(out / "joints.png") and _no_temp_files(out)

    with open(out / "path.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == path_columns(NAMES)
    assert [r["motion"] for r in rows] == MOTIONS
    assert [float(r["beta_3"]) for r in rows] == list(WAYPOINTS[:, 2])  # full precision
    assert rows[2]["bound_kind"] == "translation_last" and float(rows[3]["tip_x"]) == 0.003

    with open(out / "trajectory.csv", newline="") as fh:
        table = list(csv.reader(fh))
    assert table[0][:4] == ["t", "alpha_2", "alpha_2_vel", "alpha_2_acc"] and len(table[0]) == 10
    assert len(table) == len(traj.t) + 1
    last = np.array(table[-1], dtype=float)
    assert last[0] == traj.t[-1] and last[7] == traj.waypoints[-1, 2]

    summary = json.loads((out / "summary.json").read_text())
    assert summary["max_bound_mm"] == 1.25 and summary["solved"] is True
    assert summary["bound_per_waypoint_mm"] == [0.5, None]
    assert summary["duration_s"] == pytest.approx(traj.duration) and summary["n_segments"] == 3


def test_failure_inside_the_atomic_writer_leaves_no_partial_file(tmp_path, traj, monkeypatch):
    def broken_replace(src, dst):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(atomic.os, "replace", broken_replace)
    with pytest.raises(OSError, match="simulated"):
        write_plan_outputs(tmp_path, _rows(), traj, SUMMARY)
    assert list(tmp_path.iterdir()) == []


def test_interrupted_run_keeps_the_previous_files(tmp_path, traj):
    write_plan_outputs(tmp_path, _rows(), traj, SUMMARY)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    rows = _rows()
    del rows[2]["bound_kind"]  # fails while building path.csv
    with pytest.raises(ValueError, match="path row 2: missing key 'bound_kind'"):
        write_plan_outputs(tmp_path, rows, traj, {"max_bound_mm": 9.0})
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_figure_failure_leaves_no_summary(tmp_path, traj):
    def broken(path):
        raise RuntimeError("plot failed")

    with pytest.raises(RuntimeError):
        write_plan_outputs(tmp_path, _rows(), traj, SUMMARY, figures={"f.png": broken})
    assert not (tmp_path / "summary.json").exists() and not (tmp_path / "f.png").exists()


def test_rows_with_joint_columns_and_bad_values(tmp_path):
    row = {"motion": "start", "alpha_2": 0.1, "alpha_3": 0.2, "beta_3": -0.05, "tip_x": 0.0,
           "tip_y": 0.0, "tip_z": 0.1, "bound_position_m": 0.001, "bound_angle_rad": 0.0,
           "bound_kind": "friction"}
    write_plan_outputs(tmp_path, [row], None, {}, joint_names=NAMES)
    assert not (tmp_path / "trajectory.csv").exists()
    assert (tmp_path / "path.csv").read_text().splitlines()[1].startswith("0,start,0.1,0.2,-0.05,")
    with pytest.raises(ValueError, match="bound_kind"):
        write_plan_outputs(tmp_path, [dict(row, bound_kind="other")], None, {}, joint_names=NAMES)
    with pytest.raises(ValueError, match="joint_names"):
        write_plan_outputs(tmp_path, [row], None, {})


def test_format_summary_prints_units():
    text = format_summary({"max_bound_mm": 1.25, "max_bound_m": 0.0012, "bound_angle_rad": np.pi / 2,
                           "duration_s": 3.5, "n_segments": 3, "planner": "RRTstar",
                           "limits": {"control_rate_hz": 500.0}})
    lines = text.splitlines()
    assert "max bound: 1.25 mm" in lines and "max bound: 1.2 mm" in lines
    assert "bound angle: 90 deg" in lines and "duration: 3.5 s" in lines
    assert "n segments: 3" in lines and "planner: RRTstar" in lines
    assert "  control rate: 500 Hz" in lines


def test_library_figures_leave_the_users_backend_alone(tmp_path):
    """Figures are drawn on a bare Agg canvas: a user's matplotlib backend is the same after the
    library wrote a figure (catches ``matplotlib.use`` inside the library, which switches an
    interactive figure window to Agg), and no module of the package imports pyplot or calls
    ``matplotlib.use``."""
    import ast
    from pathlib import Path

    import matplotlib

    from ctrplan import studies

    rows = [studies.StudyRow(Path(name), studies.StudyStatus.PLANNED, "", 1.0, tmp_path, max_bound_m=a,
                             blind_max_bound_m=b) for name, a, b in (("a.toml", 3.1e-3, 4.9e-3),
                                                                     ("b.toml", 4.0e-3, 4.2e-3))]
    with matplotlib.rc_context({"backend": "svg"}):
        studies._plot(rows, tmp_path / "bounds.png")
        assert matplotlib.get_backend() == "svg"
    assert (tmp_path / "bounds.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    offenders = []
    for path in (Path(studies.__file__).parent).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] + ([node.module] if isinstance(node, ast.ImportFrom) else [])
                if any(n and n.startswith("matplotlib.pyplot") for n in names) or (
                        isinstance(node, ast.ImportFrom) and node.module == "matplotlib"
                        and any(a.name == "pyplot" for a in node.names)):
                    offenders.append(f"{path.name}:{node.lineno} imports pyplot")
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "use"
                    and isinstance(node.func.value, ast.Name) and node.func.value.id == "matplotlib"):
                offenders.append(f"{path.name}:{node.lineno} calls matplotlib.use")
    assert not offenders, offenders
