"""Robots built in code for the mechanics tests (independent of the model-file loader)."""

import numpy as np

from ctrplan.robot import Joint, Robot, Section, TranslationLink, Tube

PI = np.pi


def table1_pair(clearance=0.05e-3, mu=0.2):
    """Tube pair of Table I of Ha et al. 2019 (clearance and friction are parameters)."""
    k = 5.07e-2
    kappa = 1.0 / 0.150
    t1 = Tube("tube 1", (Section(0.150, (0.0, kappa)),), k_xy=k, poisson_ratio=0.3,
              inner_diameter=1.0e-3 + 2 * clearance)
    t2 = Tube("tube 2", (Section(0.017), Section(0.150, (0.0, kappa))), k_xy=k,
              poisson_ratio=0.3, outer_diameter=1.0e-3)
    return Robot("table1", (t1, t2), friction_coefficients=(mu,),
                 joints=(Joint("rotation", 1, -PI, PI),), home_beta=(0.0, -0.017),
                 source="Ha et al. 2019 Table I")


def table2_robot(mu=0.2):
    """Three-tube robot of Table II of Ha et al. 2019."""
    k1 = 1.0 / 0.265
    t1 = Tube("tube 1", (Section(0.150, (0.0, k1)),), k_xy=5.07e-2, poisson_ratio=0.3,
              outer_diameter=2.64e-3, inner_diameter=2.39e-3)
    t2 = Tube("tube 2", (Section(0.017), Section(0.150, (0.0, k1))), k_xy=5.07e-2,
              poisson_ratio=0.3, outer_diameter=2.305e-3, inner_diameter=1.95e-3)
    t3 = Tube("tube 3", (Section(0.184), Section(0.0864, (0.0, 1.0 / 0.055))), k_xy=1.45e-2,
              poisson_ratio=0.3, outer_diameter=1.825e-3)
    return Robot("table2", (t1, t2, t3), friction_coefficients=(mu, mu),
                 joints=(Joint("rotation", 1, -PI, PI), Joint("rotation", 2, -PI, PI),
                         Joint("translation", 2, -0.104, -0.034)),
                 home_beta=(0.0, -0.017, -0.034),
                 links=(TranslationLink(1, 0, -0.017),), source="Ha et al. 2019 Table II")
