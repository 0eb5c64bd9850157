"""Constants of Liu, Leung, Tang & Jia (calibration of a force-moment sensor on a planar payload), in one place.

Every module that needs a number of that paper imports it from here; none writes it again.

===========================  ===============================================================
name                         meaning (paper reference)
===========================  ===============================================================
``MASS``, ``INERTIA``        payload mass [kg], moment of inertia about G [kg m^2] (Section 4, item 1)
``RHO_X``, ``RHO_Y``         sensor interface from G in the body frame [m] (Section 4, item 2)
``CALIBRATION``              the calibration matrix S (Section 4, item 4)
``TABLE1_TIMES``,            the time-varying S of Table 1: diagonal (s11, s22, s33) from these
``TABLE1_DIAGONALS``         start times [s], off-diagonal entries those of ``CALIBRATION``
``WRENCH_TERMS``             the multi-sine wrench, eq. (13): per element (M, f_x, f_y) the terms
                             (amplitude, angular frequency [rad/s], phase [rad], is_cosine)
``WRENCH_NOISE_REL``         sensor noise, 5 % of each wrench element's amplitude (Section 4)
``THETA_NOISE_DEG``,         vision noise, 0.1 deg and 0.1 mm (Section 4; read as standard
``POSITION_NOISE``           deviations, see :mod:`fricenv.plants.payload`)
``SAMPLE_TIME``              simulation and estimator step [s] (Section 4)
``RANDOM_S_BOUND``           entries of the random calibration matrices in [-3, 3] (Section 4, Fig. 3)
===========================  ===============================================================
"""

from __future__ import annotations

import math

MASS = 2.5  # [kg]
INERTIA = 0.75  # [kg m^2]
RHO_X = 0.2  # [m]
RHO_Y = 0.25  # [m]
CALIBRATION = (
    (0.6110, -0.0372, -0.1445),
    (-0.3361, 1.0020, -0.1443),
    (-0.1147, 0.1674, 0.9598),
)
TABLE1_TIMES = (0.0, 100.0, 200.0)  # [s]
TABLE1_DIAGONALS = ((0.6110, 1.0020, 0.9598), (0.3847, 0.8144, 0.9169), (-0.2839, 0.5472, 1.1172))
WRENCH_TERMS = (
    ((1.0, 2.0, 0.0, False), (0.1, 10.0, 0.0, True), (0.4, math.pi, math.pi / 6, False)),  # M [N m]
    ((1.0, 1.0, 0.0, False), (0.1, 4.5, 0.0, True), (0.4, math.pi, math.pi / 3, False)),  # f_x [N]
    ((2.0, 3.0, 0.0, False), (0.2, 5.0, 0.0, True), (0.4, 7.0, 0.0, False)),  # f_y [N]
)
WRENCH_NOISE_REL = 0.05  # [-]
THETA_NOISE_DEG = 0.1  # [deg]
POSITION_NOISE = 1e-4  # [m] (0.1 mm)
SAMPLE_TIME = 1e-3  # [s]
RANDOM_S_BOUND = 3.0  # [-]
