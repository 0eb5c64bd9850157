"""Constants of Li, Du & Li (EKF/RLS estimation of the tire-road friction), in one place.

Every module that needs a number of that paper imports it from here; none writes it again.

==========================  ===============================================================
name                        meaning (paper reference)
==========================  ===============================================================
``MASS``, ``L_F``, ``L_R``  vehicle mass [kg], CG to front / rear axle [m] (Table I)
``TIRE_STIFFNESS``          longitudinal tire stiffness C_s [N/unit slip], eqs. (2), (7), Table I
``YAW_INERTIA``             yaw inertia I_z [kg m^2] (Table I; unused in straight line)
``WHEEL_RADIUS``,           wheel radius R_w [m], wheel inertia I_w [kg m^2] (Table I)
``WHEEL_INERTIA``
``ROAD_MU``                 road friction coefficient of the simulations (Section IV.B)
``DUGOFF_EPS_R``            Dugoff velocity reduction factor [s/m] (eq. (2), Table I)
``CORNERING_STIFFNESS``     C_alpha [N/rad] (Table I; unused in straight line)
``AX_NOISE``                half-width of the uniform a_x noise [m/s^2] (Section IV.B, Fig. 12)
``CORRECTION_GAIN``         gain K of the a_x correction loop [1/s] (Fig. 2, Table I)
``MAP_SLOPE``,              the paper's friction map mu = MAP_SLOPE k_s + MAP_OFFSET, eq. (15)
``MAP_OFFSET``
==========================  ===============================================================
"""

from __future__ import annotations

MASS = 1298.9  # [kg], Table I
L_F = 1.0  # [m], Table I
L_R = 1.454  # [m], Table I
TIRE_STIFFNESS = 50000.0  # C_s [N/unit slip], Table I
YAW_INERTIA = 1627.0  # I_z [kg m^2], Table I
WHEEL_RADIUS = 0.35  # R_w [m], Table I
WHEEL_INERTIA = 2.1  # I_w [kg m^2], Table I
ROAD_MU = 0.9  # [-], Section IV.B
DUGOFF_EPS_R = 0.015  # [s/m], Table I
CORNERING_STIFFNESS = 30000.0  # C_alpha [N/rad], Table I
AX_NOISE = 0.05  # [m/s^2], Section IV.B
CORRECTION_GAIN = 100.0  # K [1/s], Fig. 2 / Table I
MAP_SLOPE = 0.1  # eq. (15) [-]
MAP_OFFSET = 0.02  # eq. (15) [-]
