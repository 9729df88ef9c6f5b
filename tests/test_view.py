"""Interactive plan view (ctrplan.planning.outputs.view): a self-contained HTML file with one slider step per
waypoint, coordinates in mm, every obstacle type including an STL mesh; and it renders in a
headless Chromium without JavaScript errors (skipped where Chromium is absent)."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pytest

from ctrplan.obstacles import obstacle_from_dict
from ctrplan.planning.outputs.figures import obstacle_triangles
from ctrplan.planning.outputs.view import SPHERE_RESOLUTION, WaypointFrames, plan_view_figure, write_plan_view

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
K = 4
RENDER_TIMEOUT_S = 30
# A point of waypoint 2's standard centerline [m]; the view must carry it in mm.
KNOWN_POINT_M = (0.0123, -0.0045, 0.0678)
SPHERE = {"type": "sphere", "center_m": (0.01, 0.0, 0.08), "radius_m": 0.004}
BOX = {"type": "box", "center_m": (-0.01, 0.0, 0.06), "size_m": (0.004, 0.006, 0.008), "rpy_rad": (0.0, 0.0, 0.3)}
CAPSULE = {"type": "capsule", "a_m": (0.0, 0.02, 0.05), "b_m": (0.0, 0.02, 0.07), "radius_m": 0.002}


def _tetra_stl(folder: Path) -> Path:
    """A tetrahedron in millimetres (one vertex at (10, 0, 0) mm) written as STL."""
    import trimesh

    mesh = trimesh.Trimesh(vertices=[[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]],
                           faces=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    path = folder / "tetra.stl"
    mesh.export(path)
    return path


def _mesh(folder: Path) -> dict:
    return {"type": "mesh", "path": str(_tetra_stl(folder)), "scale": 0.001,
            "translation_m": (0.0, 0.0, 0.05), "rpy_rad": (0.0, 0.0, 0.0)}


def _plan(folder: Path) -> dict:
    """Keyword arguments of :func:`write_plan_view` and :func:`plan_view_figure`."""
    s = np.linspace(0.0, 0.1, 20)
    standard = [np.column_stack([0.02 * k * s**2, np.zeros_like(s), s]) for k in range(K)]
    standard[2][7] = KNOWN_POINT_M
    friction_shapes = [[c + [0.001 * e, 0.0, 0.0] for e in (-1, 1, -2, 2)] for c in standard]
    frames = WaypointFrames(standard, friction_shapes=friction_shapes,
                            friction_tips=[[f[-1] for f in fs] for fs in friction_shapes],
                            predicted_shapes=[c + [0.0, 0.0005, 0.0] for c in standard],
                            predicted_tips=np.array([c[-1] + [0.0, 0.0005, 0.0] for c in standard]),
                            notes=["start", "rotation", "translation", "rotation"])
    return dict(frames=frames, obstacles=[SPHERE, BOX, CAPSULE, _mesh(folder)],
                targets=np.array([[0.001, 0.0, 0.1]]), title="synthetic")


def _trace(fig, name):
    (trace,) = [t for t in fig.data if t.name == name]
    return trace


def test_html_is_self_contained_with_one_slider_step_per_waypoint(tmp_path):
    path = write_plan_view(tmp_path / "plan.html", **_plan(tmp_path))
    html = path.read_text(encoding="utf-8")
    assert not re.search(r"<script[^>]*src=[\"']?https?:", html), "the view must not load scripts from the network"
    assert len(html) > 2_000_000 and "Plotly" in html                # the plotly.js bundle is embedded
    assert len(re.findall(r'"method":\s*"update"', html)) == K
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


def test_traces_are_in_mm_and_each_step_shows_only_its_waypoint(tmp_path):
    plan = _plan(tmp_path)
    fig = plan_view_figure(**plan)
    x, y, z = (1e3 * c for c in KNOWN_POINT_M)
    std = _trace(fig, "standard (waypoint 2)")
    assert (std.x[7], std.y[7], std.z[7]) == pytest.approx((x, y, z), abs=1e-9)
    np.testing.assert_allclose(np.column_stack([std.x, std.y, std.z]), 1e3 * plan["frames"].standard[2], atol=1e-4)
    # the same numbers are in the HTML file as written (mm, not m)
    html = write_plan_view(tmp_path / "plan.html", **plan).read_text(encoding="utf-8")
    assert all(repr(round(v, 4)) in html for v in (x, y, z))
    # friction envelope: four centerlines in one trace separated by gaps; four tip markers
    env = _trace(fig, "friction envelope (waypoint 1)")
    assert sum(v is None for v in env.x) == 4 and len(env.x) == 4 * (20 + 1)
    tips = _trace(fig, "friction tips (waypoint 1)")
    np.testing.assert_allclose(np.column_stack([tips.x, tips.y, tips.z]),
                               1e3 * np.array(plan["frames"].friction_tips[1]))
    pred = _trace(fig, "predicted tip (waypoint 3)")
    np.testing.assert_allclose([pred.x[0], pred.y[0], pred.z[0]], 1e3 * plan["frames"].predicted_tips[3])
    target = _trace(fig, "targets")
    assert (target.x[0], target.z[0]) == pytest.approx((1.0, 100.0))
    steps = fig.layout.sliders[0].steps
    assert len(steps) == K
    names = [t.name for t in fig.data]
    for k, step in enumerate(steps):
        shown = [n for n, v in zip(names, step.args[0]["visible"]) if v and "waypoint" in n]
        assert shown and all(n.endswith(f"(waypoint {k})") for n in shown)
        assert len(shown) == 5
        assert [n for n, v in zip(names, step.args[0]["visible"]) if not v and "obstacle" in n] == []
    assert "translation" in steps[2].args[1]["title.text"]


def test_obstacles_are_triangulated_where_the_collision_checker_places_them(tmp_path):
    mesh = _mesh(tmp_path)
    fig = plan_view_figure(WaypointFrames([None]), obstacles=[SPHERE, BOX, mesh])
    tri = _trace(fig, "obstacle 3 (mesh)")
    verts, faces = obstacle_from_dict(mesh).triangles()
    np.testing.assert_allclose(np.column_stack([tri.x, tri.y, tri.z]), 1e3 * verts, atol=1e-4)
    assert len(tri.i) == 4 and max(tri.z) == pytest.approx(60.0)     # 10 mm tall, 50 mm up
    sph = _trace(fig, "obstacle 1 (sphere)")
    r = np.linalg.norm(np.column_stack([sph.x, sph.y, sph.z]) - 1e3 * np.array(SPHERE["center_m"]), axis=1)
    np.testing.assert_allclose(r, 4.0, atol=1e-3)
    # a closed convex surface: every edge shared by exactly two triangles
    _, f = obstacle_triangles(SPHERE, 0, SPHERE_RESOLUTION)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    assert set(np.unique(edges, axis=0, return_counts=True)[1]) == {2}
    v, f = obstacle_triangles(BOX, 1, SPHERE_RESOLUTION)
    assert v.shape == (8, 3) and f.shape == (12, 3)
    np.testing.assert_allclose(np.ptp(v[:, 2]), 0.008)


def test_bad_inputs_raise_value_errors_naming_the_input(tmp_path):
    with pytest.raises(ValueError, match=r"standard\[0\] needs shape \(N, 3\)"):
        plan_view_figure(WaypointFrames([np.zeros((5, 2))]))
    with pytest.raises(ValueError, match="predicted_tips needs shape"):
        plan_view_figure(WaypointFrames([np.zeros((5, 3))] * 2, predicted_tips=np.zeros((3, 3))))
    with pytest.raises(ValueError, match="friction_tips needs one entry per waypoint"):
        plan_view_figure(WaypointFrames([np.zeros((5, 3))] * 2, friction_tips=[np.zeros((2, 3))]))
    with pytest.raises(ValueError, match="labels and notes need one entry per waypoint"):
        plan_view_figure(WaypointFrames([np.zeros((5, 3))] * 2, notes=["start"]))
    with pytest.raises(ValueError, match="obstacle 0"):
        plan_view_figure(WaypointFrames([np.zeros((5, 3))]), obstacles=[{"type": "cone"}])


# ---------------------------------------------------------------------------------- browser
def _chromium_driver():
    if not CHROMIUM.is_file():
        pytest.skip(f"Chromium not found at {CHROMIUM}: install the Debian packages chromium and "
                    "chromium-driver to run the browser test")
    if not CHROMEDRIVER.is_file():
        pytest.skip(f"chromedriver not found at {CHROMEDRIVER}: install the Debian package chromium-driver")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--window-size=1000,800"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)


def _pixel_std(png: bytes) -> float:
    import matplotlib.image

    return float(np.std(matplotlib.image.imread(io.BytesIO(png), format="png")[..., :3]))


def check_renders_in_chromium(html_path: Path, shots: Path | None = None) -> dict:
    """Open ``html_path`` in headless Chromium, move the slider to the last step, and assert:
    no SEVERE browser-log entry, one plotly graph with its traces drawn, and a non-blank
    screenshot before and after the step (saved beside ``shots`` when given). Returns what it
    measured."""
    driver = _chromium_driver()
    try:
        from selenium.webdriver.support.ui import WebDriverWait

        driver.get(Path(html_path).resolve().as_uri())
        # plotly draws the 3-D scene into a WebGL canvas after the page's load event
        WebDriverWait(driver, RENDER_TIMEOUT_S).until(lambda d: d.execute_script(
            "const gd = document.querySelector('.js-plotly-plot');"
            "return !!(gd && gd._fullLayout && gd._fullLayout.scene && document.querySelector('.gl-container canvas'));"))
        n_traces = driver.execute_script("return document.querySelector('.js-plotly-plot')._fullData.length;")
        first = driver.get_screenshot_as_png()
        n_steps = driver.execute_script(
            "const gd = document.querySelector('.js-plotly-plot');"
            "const steps = gd.layout.sliders[0].steps; const last = steps[steps.length - 1];"
            "Plotly.update(gd, last.args[0], last.args[1]); return steps.length;")
        last = driver.get_screenshot_as_png()
        if shots is not None:
            Path(shots).with_suffix(".first.png").write_bytes(first)
            Path(shots).with_suffix(".last.png").write_bytes(last)
        severe = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
    finally:
        driver.quit()
    assert severe == [], severe
    assert n_traces > 0, "plotly did not draw the graph"
    stds = (_pixel_std(first), _pixel_std(last))
    assert min(stds) > 0.02, f"blank screenshot (pixel std {stds})"
    return {"n_traces": n_traces, "n_steps": n_steps, "pixel_std": stds}


def test_view_renders_in_headless_chromium_without_javascript_errors(tmp_path):
    path = write_plan_view(tmp_path / "plan.html", **_plan(tmp_path))
    measured = check_renders_in_chromium(path)
    assert measured["n_steps"] == K
