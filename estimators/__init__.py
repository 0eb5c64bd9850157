"""Paper estimators (MHE, EKF, EKF/RLS, FMS calibration); they import fricenv.plants, never envs or agents."""

from estimators.base import Estimate, Estimator, EstimatorConfigError, Health, run

__all__ = ["Estimate", "Estimator", "EstimatorConfigError", "Health", "run"]
