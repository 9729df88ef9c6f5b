"""Small scenario files of the Table VII robot for tests: one builder instead of one per test module."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TABLE7 = REPO / "model" / "ha2019-table7-calibrated.toml"
START = "{alpha_2 = 0.0, alpha_3 = 0.0, beta_3 = -0.07}"
DRIVE = """[drive]
control_rate_hz = 250.0
max_velocity = {alpha_2 = 1.0, alpha_3 = 1.0, beta_3 = 0.01}
max_acceleration = {alpha_2 = 4.0, alpha_3 = 4.0, beta_3 = 0.04}
max_jerk = {alpha_2 = 40.0, alpha_3 = 40.0, beta_3 = 0.4}
"""


def write_scenario(folder: Path, goal_q: str, *, name: str = "probe", start_q: str = START, obstacles: str = "",
                   planner: str = "", bound_field: str = "resolution = [4, 4, 3]") -> Path:
    """``folder/<name>.toml``: the Table VII robot from ``start_q`` to one joint goal ``goal_q``
    (TOML inline tables of the three joints [rad, m]), with the given ``[[obstacles]]`` tables,
    ``[planner]`` and ``[bound_field]`` bodies and the drive limits of the shipped scenarios."""
    text = f"""name = "{name}"
robot = "{TABLE7.as_posix()}"

[start]
q = {start_q}

[[goals]]
type = "joint"
q = {goal_q}
{obstacles}
[planner]
{planner}

[bound_field]
{bound_field}

{DRIVE}"""
    path = Path(folder) / f"{name}.toml"
    path.write_text(text)
    return path
