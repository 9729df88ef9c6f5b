"""ctrplan: friction-bounded motion planning for concentric tube robots.

Mechanics from Ha, Fagogenis & Dupont, "Modeling Tube Clearance and Bounding the Effect of
Friction in Concentric Tube Robot Kinematics", IEEE T-RO 35(2):353-370, 2019,
doi:10.1109/TRO.2018.2878906.
"""

from .errors import *  # noqa: F401,F403
from .robot import Joint, Robot, Section, TranslationLink, Tube  # noqa: F401

__version__ = "0.1.0"
