"""Peak friction from the RLS slip slope: the maps of the EKF/RLS method's step 5 (:mod:`estimators.ekf_rls`).

The paper's map ``mu = 0.1 k_s + 0.02`` (eq. (15)) was fitted to its tire. On this project's Magic Formula roads the
family relation is used instead: with the tire's shape (B, C, E) fixed and the road scaling theta, the regression
``F / F_z = k_s S`` at the data's load-weighted slip S_bar gives ``theta = k_s S_bar / g(S_bar)``.
"""

from __future__ import annotations

import numpy as np

from fricenv.plants.tire import DRY, MagicFormula, magic_formula

__all__ = ["PAPER_MAP", "SLIP_SMALL", "LinearMap", "MagicFormulaFamilyMap"]

SLIP_SMALL = 1e-4  # below this slip the family maps use their linear limit [-]


class LinearMap:
    """``mu = a k_s + b`` (the paper's eq. (15) form)."""

    def __init__(self, a: float = 0.1, b: float = 0.02):
        self.a, self.b = float(a), float(b)

    def __call__(self, k_s: float, s_bar: float) -> float:
        return self.a * k_s + self.b

    def batch(self, k_s: np.ndarray, s_bar: np.ndarray) -> np.ndarray:
        """The map over arrays of slopes and mean slips (the batched estimator's form)."""
        return self.a * np.asarray(k_s, dtype=float) + self.b


PAPER_MAP = LinearMap(0.1, 0.02)  # eq. (15), for the paper's tire


class MagicFormulaFamilyMap:
    """Peak friction from the slip slope on the family mu = theta g(S) of one tire shape (module docstring).

    :param shape: Magic Formula whose B, C, E give the shape (theta ignored).
    """

    def __init__(self, shape: MagicFormula = DRY):
        self.B, self.C, self.E = shape.B, shape.C, shape.E
        unit = MagicFormula(self.B, self.C, self.E, 1.0)
        self.g_max = unit.mu_max
        self.linear_factor = self.g_max / (self.B * self.C)  # mu per unit k_s as S -> 0

    def __call__(self, k_s: float, s_bar: float) -> float:
        if s_bar < SLIP_SMALL:
            return k_s * self.linear_factor
        g = float(magic_formula(s_bar, self.B, self.C, self.E, 1.0))
        return k_s * s_bar / g * self.g_max

    def batch(self, k_s: np.ndarray, s_bar: np.ndarray) -> np.ndarray:
        """The map over arrays of slopes and mean slips (the batched estimator's form)."""
        k_s, s_bar = np.asarray(k_s, dtype=float), np.asarray(s_bar, dtype=float)
        small = s_bar < SLIP_SMALL
        g = magic_formula(np.where(small, 1.0, s_bar), self.B, self.C, self.E, 1.0)
        return np.where(small, k_s * self.linear_factor, k_s * s_bar / g * self.g_max)
