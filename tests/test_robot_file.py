"""Robot model files: shipped models load with the paper's values; malformed files fail clearly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.errors import ModelFileError, PhysicalParameterError
from ctrplan.io.atomic import atomic_path, atomic_savez, atomic_write_bytes, atomic_write_text
from ctrplan.io.robot_file import file_hash, load_robot, robot_from_toml_text

MODEL_DIR = Path(__file__).resolve().parents[1] / "model"
SHIPPED = sorted(MODEL_DIR.glob("*.toml"))
TABLE2 = MODEL_DIR / "ha2019-table2-nominal.toml"
TABLE7 = MODEL_DIR / "ha2019-table7-calibrated.toml"

MINIMAL = """
name = "pair"
[[tubes]]
name = "outer"
k_xy_N_m2 = 5.07e-2
poisson_ratio = 0.3
inner_diameter_m = 1.1e-3
[[tubes.sections]]
length_m = 0.150
precurvature_per_m = [0.0, 6.0]
[[tubes]]
name = "inner"
k_xy_N_m2 = 5.07e-2
poisson_ratio = 0.3
outer_diameter_m = 1.0e-3
[[tubes.sections]]
length_m = 0.017
precurvature_per_m = [0.0, 0.0]
[[tubes.sections]]
length_m = 0.150
precurvature_per_m = [0.0, 6.0]
[[pairs]]
friction_coefficient = 0.2
[[joints]]
name = "alpha_2"
lower = -3.2
upper = 3.2
"""


def test_all_four_models_are_shipped():
    names = {p.name for p in SHIPPED}
    assert {"ha2019-table1-tube-pair.toml", "ha2019-table2-nominal.toml",
            "ha2019-table7-calibrated.toml", "ha2019-table5-path-history-pair.toml"} <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_model_loads_and_home_is_feasible(path):
    robot = load_robot(path)
    assert "Ha, Fagogenis & Dupont" in robot.source and "Table" in robot.source
    assert robot.metadata["sha256"] == file_hash(path)
    q_home = robot.joint_vector(robot.home_alpha, robot.home_beta)
    alpha, beta = robot.configuration(q_home)
    robot.check_configuration(alpha, beta)
    assert np.all(robot.clearances > 0)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_configurations_possible_agrees_with_check_configuration(path):
    """Seeded property: the vectorized test used by the batch solver accepts exactly the
    configurations that check_configuration accepts (random bases, some sorted, one NaN)."""
    robot = load_robot(path)
    n = robot.n_tubes
    rng = np.random.default_rng(11)
    length = max(t.length for t in robot.tubes)
    alpha = rng.uniform(-np.pi, np.pi, (2000, n))
    beta = -rng.uniform(0.0, 0.6 * length, (2000, n))
    beta[::5] = np.sort(beta[::5], axis=1)[:, ::-1]
    alpha[3, 0] = np.nan
    expected = []
    for a, b in zip(alpha, beta):
        try:
            robot.check_configuration(a, b)
            expected.append(True)
        except ValueError:
            expected.append(False)
    got = robot.configurations_possible(alpha, beta)
    assert 0 < got.sum() < got.size
    np.testing.assert_array_equal(got, expected)


def test_table2_values():
    robot = load_robot(TABLE2)
    # Clearances (ID_i - OD_(i+1)) / 2 of Table II [m].
    np.testing.assert_allclose(robot.clearances, [0.0425e-3, 0.0625e-3], rtol=1e-12)
    np.testing.assert_allclose([t.k_xy for t in robot.tubes], [5.07e-2, 5.07e-2, 1.45e-2])
    np.testing.assert_allclose([t.length for t in robot.tubes], [0.150, 0.167, 0.2704])
    assert robot.tubes[2].sections[1].precurvature == pytest.approx((0.0, 1000.0 / 55.0))
    assert robot.friction_coefficients == (0.2, 0.2)
    assert robot.joint_names == ["alpha_2", "alpha_3", "beta_3"]
    np.testing.assert_allclose(robot.joint_lower[2:], [-0.104])
    np.testing.assert_allclose(robot.joint_upper[2:], [-0.034])
    _, beta = robot.configuration([0.0, 0.0, -0.05])
    np.testing.assert_allclose(beta, [0.0, -0.017, -0.05])


def test_table7_mixed_curvature_units():
    """Table VII: y-curvature in mm^-1, x-curvature in m^-1 (paper-errata.md)."""
    robot = load_robot(TABLE7)
    ux, uy = robot.tubes[2].sections[1].precurvature
    assert ux == pytest.approx(-1.0 / 3.313, rel=1e-12)
    assert uy == pytest.approx(1.0 / 62.37e-3, rel=1e-12)
    assert robot.tubes[0].sections[0].precurvature[0] == pytest.approx(-1.0 / 291.3, rel=1e-12)
    np.testing.assert_allclose([t.k_xy for t in robot.tubes],
                               np.array([1.0, 0.9929, 0.1990]) * 5.07e-2, rtol=1e-12)
    assert robot.tubes[2].poisson_ratio == -0.1543
    assert robot.friction_coefficients == (0.22, 0.12)
    np.testing.assert_allclose(robot.clearances, [0.0425e-3, 0.0625e-3], rtol=1e-12)


def test_minimal_text_and_defaults():
    robot = robot_from_toml_text(MINIMAL)
    assert robot.n_tubes == 2 and robot.home_beta == (0.0, 0.0)
    assert robot.clearances == pytest.approx([0.05e-3])


def _error(text, exc=ModelFileError):
    with pytest.raises(exc) as info:
        robot_from_toml_text(text, file="bad.toml")
    return info.value


def test_unknown_key_names_file_and_key():
    err = _error(MINIMAL.replace("length_m = 0.017", "length_m = 0.017\nlenght_mm = 17"))
    assert err.file == "bad.toml" and err.key == "tubes[2].sections[1].lenght_mm"
    assert "unknown key" in str(err) and "length_m" in str(err) and "bad.toml" in str(err)


def test_missing_key_names_file_and_key():
    err = _error(MINIMAL.replace("poisson_ratio = 0.3\nouter_diameter_m", "outer_diameter_m"))
    assert err.key == "tubes[2].poisson_ratio" and "missing" in str(err)


def test_wrong_type_names_key_and_value():
    err = _error(MINIMAL.replace("length_m = 0.017", 'length_m = "0.017"'))
    assert err.key == "tubes[2].sections[1].length_m" and "'0.017'" in str(err)


@pytest.mark.parametrize("old,new,key", [
    ("length_m = 0.017", "length_m = -0.017", "tubes[2].sections[1].length_m"),
    ("length_m = 0.017", "length_m = 17.0", "tubes[2].sections[1].length_m"),  # millimetres
    ("precurvature_per_m = [0.0, 0.0]", "precurvature_per_m = [0.0]", "tubes[2].sections[1].precurvature_per_m"),
    ("friction_coefficient = 0.2", "friction_coefficient = -0.2", "pairs[1].friction_coefficient"),
    ('name = "alpha_2"', 'name = "alpha_3"', "joints[1].name"),
    ("upper = 3.2", "upper = -3.3", "joints[1].upper"),
    ("k_xy_N_m2 = 5.07e-2\npoisson_ratio = 0.3\ninner", "k_xy_relative = 1.0\npoisson_ratio = 0.3\ninner",
     "k_xy_reference_N_m2"),
    ("poisson_ratio = 0.3\ninner", "poisson_ratio = 0.7\ninner", "tubes[1].poisson_ratio"),
    ("length_m = 0.017", "length_m = nan", "tubes[2].sections[1].length_m"),
])
def test_bad_values(old, new, key):
    assert old in MINIMAL
    err = _error(MINIMAL.replace(old, new))
    assert err.key == key


def test_both_stiffness_keys_is_an_error():
    err = _error(MINIMAL.replace("k_xy_N_m2 = 5.07e-2\npoisson_ratio = 0.3\ninner",
                                 "k_xy_N_m2 = 5.07e-2\nk_xy_relative = 1.0\npoisson_ratio = 0.3\ninner"))
    assert err.key == "tubes[1].k_xy_N_m2" and "exactly one" in str(err)


def test_toml_syntax_error():
    err = _error(MINIMAL + "\n[[[oops")
    assert err.key == "<syntax>"


@pytest.mark.parametrize("change", [
    ("outer_diameter_m = 1.0e-3", "outer_diameter_m = 1.2e-3"),             # inner wider than bore
    ("friction_coefficient = 0.2", "friction_coefficient = 0.2\nclearance_m = 0.0"),
    ("friction_coefficient = 0.2", "friction_coefficient = 0.2\nclearance_m = -1e-5"),
])
def test_non_positive_clearance_names_both_tubes(change):
    err = _error(MINIMAL.replace(*change), exc=PhysicalParameterError)
    msg = str(err)
    assert msg.startswith("bad.toml:") and "outer" in msg and "inner" in msg


def test_load_robot_missing_file(tmp_path):
    with pytest.raises(ModelFileError, match="does not exist"):
        load_robot(tmp_path / "nope.toml")


def test_file_hash_changes_with_content(tmp_path):
    p = tmp_path / "r.toml"
    p.write_text(MINIMAL)
    h1 = file_hash(p)
    p.write_text(MINIMAL + "\n")
    assert len(h1) == 64 and file_hash(p) != h1


# --------------------------------------------------------------------------- atomic writes
def test_atomic_write_replaces_content(tmp_path):
    p = tmp_path / "out.txt"
    atomic_write_text(p, "one")
    atomic_write_text(p, "two")
    assert p.read_text() == "two"
    atomic_write_bytes(p, b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"
    assert [q.name for q in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_path_failure_leaves_old_file_and_no_temp(tmp_path):
    p = tmp_path / "out.txt"
    p.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(p) as tmp:
            assert tmp.parent == tmp_path and tmp != p
            tmp.write_text("half-writ")
            raise RuntimeError("interrupted")
    assert p.read_text() == "old"
    assert [q.name for q in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_path_new_file_failure_leaves_nothing(tmp_path):
    p = tmp_path / "new.txt"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(p) as tmp:
            tmp.write_text("x")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_atomic_path_missing_directory(tmp_path):
    with pytest.raises(FileNotFoundError):
        atomic_write_text(tmp_path / "no" / "such.txt", "x")


def test_atomic_savez_writes_at_the_given_name_and_a_failure_keeps_the_old_file(tmp_path):
    """The .npz lands exactly at ``path`` (numpy would append ``.npz`` to a bare name), and an
    array that fails while being written leaves the previous file and no temporary file."""
    p = tmp_path / "field.map"
    atomic_savez(p, values=np.arange(6.0).reshape(2, 3), key=np.array("k1"))
    with np.load(p) as z:
        np.testing.assert_array_equal(z["values"], np.arange(6.0).reshape(2, 3))
        assert str(z["key"]) == "k1"

    class Broken:
        def __array__(self, dtype=None, copy=None):
            raise RuntimeError("interrupted while writing")

    with pytest.raises(RuntimeError, match="interrupted"):
        atomic_savez(p, values=np.zeros(2), broken=Broken())
    with np.load(p) as z:
        assert str(z["key"]) == "k1" and z["values"].shape == (2, 3)
    assert [q.name for q in tmp_path.iterdir()] == ["field.map"]


def test_robot_to_toml_round_trips_every_shipped_model_with_model_and_registration():
    from ctrplan.io.robot_file import robot_from_toml_text, robot_to_toml

    reg = {"rotation_vector_rad": [0.01, -0.2, 0.3], "translation_m": [0.001, -0.002, 0.15]}
    for path in SHIPPED:
        robot = load_robot(path)
        back = robot_from_toml_text(robot_to_toml(robot, header='calibrated "x"\nline 2', model="friction",
                                                  registration=reg))
        assert back == robot, path.name
        assert back.metadata["model"] == "friction"
        assert back.metadata["tracker_registration"] == reg
    with pytest.raises(ValueError, match="unknown mechanics model .magic.; registered: standard, clearance, friction"):
        robot_to_toml(robot, model="magic")


def test_bound_calibration_and_prediction_validation_round_trip_and_are_checked(tmp_path):
    """The tables ``ctrplan discrepancy`` writes for planning come back from ``load_robot`` as
    written; an impossible value (a negative factor, a coverage above 1) is refused naming the
    file, the key and the value. Catches a calibration that planning silently never sees."""
    from ctrplan.io.robot_file import robot_to_toml

    robot = load_robot(MODEL_DIR / "ha2019-table1-tube-pair.toml")
    bound = {"method": "split-conformal", "target_coverage": 0.9, "factor": 1.2849400356625302,
             "noise_margin_m": 0.0008186517513246324, "test_coverage": 0.95, "test_coverage_low": 0.9,
             "test_coverage_high": 0.99, "failing": False, "data_file": "d.csv"}
    pred = {"standard_mean_m": 0.0014, "standard_max_m": 0.0024, "history_mean_m": 0.0012, "history_max_m": 0.0022,
            "history_beats_standard": True, "test_samples": 100, "data_file": "d.csv"}
    text = robot_to_toml(robot, bound_calibration=bound, prediction_validation=pred)
    path = tmp_path / "r.toml"
    path.write_text(text)
    back = load_robot(path)
    assert {k: back.metadata["bound_calibration"][k] for k in bound} == bound
    assert {k: back.metadata["prediction_validation"][k] for k in pred} == pred
    # as typed objects, the way planning reads them (and a scenario carries them)
    from ctrplan.calibration import CalibratedBound, PredictionValidation
    from ctrplan.io.robot_file import load_robot_calibration

    cal = load_robot_calibration(path)
    assert cal.bound == CalibratedBound(**bound) and cal.prediction == PredictionValidation(**pred)
    np.testing.assert_allclose(cal.bound.apply([0.0, 1e-3]), 1.2849400356625302 * (np.array([0.0, 1e-3])
                                                                                   + 0.0008186517513246324))
    plain = load_robot_calibration(MODEL_DIR / "ha2019-table1-tube-pair.toml")
    assert plain.bound is None and plain.prediction is None
    path.write_text(text.replace("factor = 1.2849400356625302", "factor = -1.0"))
    with pytest.raises(ModelFileError, match=r"r\.toml.*bound_calibration\.factor.*-1"):
        load_robot(path)
    path.write_text(text.replace("test_coverage = 0.95", "test_coverage = 95.0"))
    with pytest.raises(ModelFileError, match=r"bound_calibration\.test_coverage.*95"):
        load_robot(path)
