"""The configuration grids of Section IV-D of Ha, Fagogenis & Dupont 2019 (three-tube robot of
Table II) and a denser one for the same robot, and the paper's Table VIII times."""

from __future__ import annotations

import numpy as np

PAPER_TIMES_S = {"standard": 0.23, "clearance": 5.3, "friction": 11.7}  # Table VIII, MATLAB, i5-3470


def grid_4x4x4(robot):
    """Uniform 4x4x4 grid: angles over one period (no duplicated endpoint), translation
    between its limits."""
    names = robot.joint_names
    axes = []
    for j in robot.joints:
        if j.kind == "rotation":
            axes.append(np.linspace(-np.pi, np.pi, 4, endpoint=False))
        else:
            axes.append(np.linspace(j.lower, j.upper, 4))
    mesh = np.meshgrid(*axes, indexing="ij")
    return names, np.stack([m.ravel() for m in mesh], axis=1)


def grid_8x8x8():
    """An 8x8x8 grid for the same robot, denser than Section IV-D's: alpha_2 and alpha_3 in steps
    of 45 deg from 0, beta_1 = 0, beta_2 = -17 mm and beta_3 = -120.4 mm plus 8 even steps of
    tube 3's curved-section exposure from 0 to 86.4 mm. Returns a list of 512 (alpha (3,) [rad],
    beta (3,) [m]) pairs, beta_3 varying fastest."""
    out = []
    for a2 in np.radians(np.arange(0, 360, 45)):
        for a3 in np.radians(np.arange(0, 360, 45)):
            for e in np.linspace(0.0, 86.4e-3, 8):
                out.append((np.array([0.0, a2, a3]), np.array([0.0, -0.017, -0.1204 + e])))
    return out
