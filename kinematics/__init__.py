"""Kinematics of servodesk's machines: pure numpy, no I/O (thesis chapter 4).

``dh`` Denavit–Hartenberg chains (section 4.2), ``xyz_fixed`` X-Y-Z fixed
angles (section 4.3), ``unimate`` the Unimate 2000B with its closed-form
inverse (sections 4.4–4.5).
"""

from kinematics import dh, unimate, xyz_fixed
from kinematics.unimate import Unreachable

__all__ = ["Unreachable", "dh", "unimate", "xyz_fixed"]
