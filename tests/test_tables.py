"""CSV schema: round trips, and errors naming file, column and row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from ctrplan.errors import DataFileError
from ctrplan.io.tables import (config_columns, load_ha_trajectory, read_configurations,
                               read_measurements, write_table)
from ctrplan.history import rotation_directions

HA_DATA = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
           / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt").resolve()


def _frame(k=4, n=3, seed=0):
    rng = np.random.default_rng(seed)
    data = {}
    for i in range(1, n + 1):
        data[f"alpha_{i}"] = rng.uniform(-np.pi, np.pi, k)
    for i in range(1, n + 1):
        data[f"beta_{i}"] = rng.uniform(-0.1, 0.0, k)
    for i in range(1, n):
        data[f"eta_{i}"] = rng.choice([-1, 0, 1], k)
    t = rng.normal(size=(k, 3))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    for j, c in enumerate("xyz"):
        data[f"tip_{c}"] = rng.uniform(-0.1, 0.2, k)
        data[f"tangent_{c}"] = t[:, j]
    return pd.DataFrame(data)


def _csv(tmp_path, text, name="t.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_config_columns():
    assert config_columns(2, with_eta=True) == ["alpha_1", "alpha_2", "beta_1", "beta_2", "eta_1"]
    with pytest.raises(ValueError):
        config_columns(0)


def test_round_trip_and_column_order(tmp_path):
    frame = _frame()
    shuffled = frame[list(reversed(frame.columns))].assign(note="x", status="ok", time=np.arange(4.0))
    p = tmp_path / "c.csv"
    write_table(p, shuffled)
    header = p.read_text().splitlines()[0].split(",")
    assert header[:7] == ["time", "alpha_1", "alpha_2", "alpha_3", "beta_1", "beta_2", "beta_3"]
    assert header[-2:] == ["status", "note"]
    alpha, beta, eta, back = read_configurations(p, 3)
    np.testing.assert_array_equal(alpha, frame[["alpha_1", "alpha_2", "alpha_3"]].to_numpy())
    np.testing.assert_array_equal(beta, frame[["beta_1", "beta_2", "beta_3"]].to_numpy())
    np.testing.assert_array_equal(eta, frame[["eta_1", "eta_2"]].to_numpy())
    assert eta.dtype.kind == "i" and list(back["status"]) == ["ok"] * 4
    m = read_measurements(p, 3)
    np.testing.assert_array_equal(m.tip, frame[["tip_x", "tip_y", "tip_z"]].to_numpy())
    np.testing.assert_array_equal(m.tangent, frame[["tangent_x", "tangent_y", "tangent_z"]].to_numpy())
    assert m.rotation is None and m.time.shape == (4,)
    assert [q.name for q in tmp_path.iterdir()] == ["c.csv"]          # no temp file left


def test_eta_optional(tmp_path):
    p = tmp_path / "c.csv"
    write_table(p, _frame().drop(columns=["eta_1", "eta_2"]))
    assert read_configurations(p, 3)[2] is None


def test_missing_column(tmp_path):
    p = tmp_path / "c.csv"
    write_table(p, _frame().drop(columns=["beta_2"]))
    with pytest.raises(DataFileError, match=r"c\.csv: missing column 'beta_2'"):
        read_configurations(p, 3)


def test_missing_tip_column_in_measurements(tmp_path):
    p = tmp_path / "c.csv"
    write_table(p, _frame().drop(columns=["tip_z"]))
    read_configurations(p, 3)                                           # fine as configurations
    with pytest.raises(DataFileError, match="missing column 'tip_z'"):
        read_measurements(p, 3)


@pytest.mark.parametrize("cell,what", [("", "empty cell"), ("nan", "not a finite number"),
                                       ("abc", "non-numeric value 'abc'")])
def test_bad_cells_name_row_and_column(tmp_path, cell, what):
    p = _csv(tmp_path, f"alpha_1,beta_1,tip_x,tip_y,tip_z\n0,0,0,0,0.1\n0.1,{cell},0,0,0.1\n")
    with pytest.raises(DataFileError) as info:
        read_configurations(p, 1)
    msg = str(info.value)
    assert "t.csv" in msg and "'beta_1'" in msg and "row 2" in msg and what in msg


def test_millimetres_detected(tmp_path):
    p = _csv(tmp_path, "alpha_1,beta_1,tip_x,tip_y,tip_z\n0,-17.0,0,0,0.1\n")
    with pytest.raises(DataFileError, match="'beta_1', row 1.*looks like millimetres"):
        read_configurations(p, 1)
    p = _csv(tmp_path, "alpha_1,beta_1,tip_x,tip_y,tip_z\n0,-0.017,0,0,0.1\n0,-0.017,53.1,0,154.6\n")
    for reader in (read_configurations, read_measurements):      # every schema column is checked
        with pytest.raises(DataFileError, match="'tip_x', row 2 .*value 53.1 looks like millimetres"):
            reader(p, 1)
    with pytest.raises(DataFileError, match="looks like millimetres"):
        write_table(tmp_path / "w.csv", pd.DataFrame({"beta_1": [-17.0]}))
    assert not (tmp_path / "w.csv").exists()


def test_write_table_names_non_numeric_and_out_of_unit_cells(tmp_path):
    """Schema columns are checked whatever their dtype: text in a numeric column (object dtype)
    is named with its row, and an integer column in millimetres is caught like a float one."""
    out = tmp_path / "w.csv"
    with pytest.raises(DataFileError, match=r"'beta_1', row 2 \(line 3\): non-numeric value 'x'"):
        write_table(out, pd.DataFrame({"beta_1": [-0.017, "x"]}))
    with pytest.raises(DataFileError, match=r"'tip_z', row 1 \(line 2\): value 155.0 looks like millimetres"):
        write_table(out, pd.DataFrame({"tip_z": np.array([155], dtype=np.int64)}))
    assert not out.exists()
    write_table(out, pd.DataFrame({"beta_1": [-0.017, np.nan], "status": ["ok", "error"]}))
    assert out.read_text().splitlines()[1:] == ["-0.017,\"ok\"", ",\"error\""]


def test_degrees_detected(tmp_path):
    p = _csv(tmp_path, "alpha_1,beta_1\n180.0,0\n")
    with pytest.raises(DataFileError, match="looks like degrees"):
        read_configurations(p, 1)


def test_bad_eta(tmp_path):
    p = _csv(tmp_path, "alpha_1,alpha_2,beta_1,beta_2,eta_1\n0,0,0,0,1\n0,0,0,0,2\n")
    with pytest.raises(DataFileError, match="'eta_1', row 2.*expected -1"):
        read_configurations(p, 2)


def test_columns_for_more_tubes_than_robot(tmp_path):
    p = tmp_path / "c.csv"
    write_table(p, _frame(n=3))
    with pytest.raises(DataFileError, match="'alpha_3' does not fit a robot with 2 tubes"):
        read_configurations(p, 2)


def test_missing_and_empty_file(tmp_path):
    with pytest.raises(DataFileError, match="does not exist"):
        read_configurations(tmp_path / "none.csv", 1)
    with pytest.raises(DataFileError, match="empty"):
        read_configurations(_csv(tmp_path, ""), 1)


def test_rotation_columns_and_checks(tmp_path):
    frame = _frame(k=3).drop(columns=["tangent_x", "tangent_y", "tangent_z"])
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    for i in range(3):
        for j in range(3):
            frame[f"R_{i + 1}{j + 1}"] = R[i, j]
    p = tmp_path / "r.csv"
    write_table(p, frame)
    m = read_measurements(p, 3)
    np.testing.assert_allclose(m.tangent, np.tile(R[:, 2], (3, 1)))
    assert m.rotation.shape == (3, 3, 3)
    write_table(p, frame.assign(R_11=2.0))
    with pytest.raises(DataFileError, match="not a rotation matrix"):
        read_measurements(p, 3)
    write_table(p, frame.drop(columns=["R_22"]))
    with pytest.raises(DataFileError, match="missing column 'R_22'"):
        read_measurements(p, 3)


def test_non_unit_tangent(tmp_path):
    p = tmp_path / "c.csv"
    write_table(p, _frame().assign(tangent_x=5.0))
    with pytest.raises(DataFileError, match="tangent has norm"):
        read_measurements(p, 3)


def test_rotation_directions_hysteresis():
    rel = np.array([0.0, 0.0, 0.1, 0.2, 0.1995, 0.25, 0.1, 0.0, 0.0005, 0.3])
    alpha = np.column_stack([np.zeros_like(rel), rel])
    eta = rotation_directions(alpha, tol=1e-3)[:, 0]
    np.testing.assert_array_equal(eta, [0, 0, 1, 1, 1, 1, -1, -1, -1, 1])


def test_load_ha_trajectory_synthetic(tmp_path):
    """Unit conversion and axis swap on two made-up rows of the same format."""
    sensor = np.array([[-0.6, 0.0, -0.8], [0.0, 1.0, 0.0], [0.8, 0.0, -0.6]])   # rows: x, y, z
    rows = []
    for k in range(2):
        rows.append([0.1 * k, 0.0, 0.1 * k, -0.2 * k, 0.0, -17.0, -100.0 + k,
                     50.0, 1.0, 150.0, *sensor.ravel()])
    p = tmp_path / "traj.txt"
    np.savetxt(p, rows, delimiter="\t")
    df = load_ha_trajectory(p)
    np.testing.assert_allclose(df["beta_3"], [-0.100, -0.099])
    np.testing.assert_allclose(df[["tip_x", "tip_y", "tip_z"]].iloc[0], [0.050, 0.001, 0.150])
    np.testing.assert_allclose(df[["tangent_x", "tangent_y", "tangent_z"]].iloc[0], [0.6, 0.0, 0.8])
    R = df[[f"R_{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]].to_numpy().reshape(-1, 3, 3)
    assert np.linalg.det(R[0]) == pytest.approx(1.0)
    assert list(df["sequence"]) == [0, 0] and list(df["eta_1"]) == [0, 1] and list(df["eta_2"]) == [0, -1]


def test_load_ha_trajectory_bad_file(tmp_path):
    p = _csv(tmp_path, "1 2 3\n4 5 6\n", "bad.txt")
    with pytest.raises(DataFileError, match="columns"):
        load_ha_trajectory(p)


def test_measured_ha_trajectory(tmp_path):
    if not HA_DATA.is_file():
        pytest.skip(f"measured trajectory not present at {HA_DATA}")
    df = load_ha_trajectory(HA_DATA)
    assert len(df) == 1307
    assert df["beta_2"].eq(-0.017).all()
    assert df["beta_3"].min() == pytest.approx(-0.104323) and df["beta_3"].max() < -0.0339
    t = df[["tangent_x", "tangent_y", "tangent_z"]].to_numpy()
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-3)
    # Home: planar configuration bent toward +x; the tangent lies in the xz plane, forward.
    assert t[0] @ np.array([0.0, 1.0, 0.0]) == pytest.approx(0.0, abs=0.02)
    assert t[0, 0] > 0.5 and t[0, 2] > 0.5
    # Tangent and tip bend the same way (the tracker is roughly aligned with the robot base).
    p = df[["tip_x", "tip_y", "tip_z"]].to_numpy()
    far = np.hypot(p[:, 0], p[:, 1]) > 0.02
    daz = np.angle(np.exp(1j * (np.arctan2(t[:, 1], t[:, 0]) - np.arctan2(p[:, 1], p[:, 0]))))
    assert np.degrees(np.median(np.abs(daz[far]))) < 25.0
    # Round trip through the project schema.
    out = tmp_path / "ha.csv"
    write_table(out, df)
    m = read_measurements(out, 3)
    np.testing.assert_allclose(m.tip, p)
    assert m.eta.shape == (1307, 2)
    # The data must never be copied into the repository.
    assert not any(Path(__file__).resolve().parents[1].rglob("jointTipTrajectory*"))
