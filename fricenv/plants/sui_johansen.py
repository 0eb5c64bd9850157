"""Constants of Sui & Johansen (regularized MHE of slip and friction), in one place.

Every module that needs a number of that paper imports it from here; none writes it again.

========================  ===============================================================
name                      meaning (paper reference)
========================  ===============================================================
``MASS``, ``INERTIA``,    quarter-car mass [kg], wheel inertia [kg m^2], wheel radius [m],
``RADIUS``, ``LOAD``      vertical load [N] (Table I)
``SAMPLE_TIME``           wheel-speed sample time [s] (Section V)
``OMEGA_NOISE_VAR``       wheel-speed measurement noise variance [(rad/s)^2] (Section V)
``NOMINAL_SHAPE``         nominal Magic Formula parameters, eq. (18): a priori estimate of
                          the MHE and the fixed shape of a theta-only estimator
========================  ===============================================================
"""

from __future__ import annotations

import math
from types import MappingProxyType

MASS = 325.0  # [kg], Table I
INERTIA = 1.0  # [kg m^2], Table I
RADIUS = 0.345  # [m], Table I
LOAD = 3188.0  # [N], Table I
GRAVITY = 9.81  # [m/s^2]
SAMPLE_TIME = 0.01  # [s], Section V
OMEGA_NOISE_VAR = 0.2  # [(rad/s)^2], Section V
OMEGA_NOISE_STD = math.sqrt(OMEGA_NOISE_VAR)  # [rad/s]
# eq. (18): theta = 0.6, B = 12, C = 1.3, E = 0 (read-only).
NOMINAL_SHAPE = MappingProxyType({"theta": 0.6, "B": 12.0, "C": 1.3, "E": 0.0})
