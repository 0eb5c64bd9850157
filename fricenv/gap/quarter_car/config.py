"""Settings of the quarter-car gap diagnosis (:class:`DiagnoseConfig`)."""

from __future__ import annotations

from dataclasses import dataclass

from fricenv.effects.quarter_car import DEFAULT_SUBSTEPS, EFFECTS

__all__ = ["DEFAULT_CONFIG", "FIT_JACOBIANS", "FIT_LOSSES", "DiagnoseConfig"]

FIT_LOSSES = ("linear", "soft_l1", "cauchy")  # losses of the least-squares fits (scipy's names)
FIT_JACOBIANS = ("projected", "difference")  # Jacobians of the least-squares fits (DiagnoseConfig.fit_jacobian)


@dataclass(frozen=True)
class DiagnoseConfig:
    """Settings of the diagnosis."""

    # Prediction window: ``horizon`` samples when set, else ``horizon_s`` at the log's rate (at least 3 samples).
    # 0.1 s: beyond the friction peak the wheel dynamics are unstable, so a longer open-loop prediction measures the
    # timing of a lock-up rather than the model.
    horizon: int | None = None  # [samples]
    horizon_s: float = 0.1  # [s]
    folds: int = 2  # cross-fitting folds: window i belongs to fold i % folds; each fold is held out once [-]
    max_nfev: int = 30  # least-squares iterations per start [-]
    # Relative step size at which a least-squares run stops (scipy's ``xtol``). Past the optimum the trust region
    # shrinks by 4x per rejected step; scipy's default 1e-8 spent about half of a run's simulations there, moving
    # parameters by less than their last reported digit [-]
    fit_xtol: float = 1e-5
    # Jacobian of the least-squares fits: "projected" differentiates each window at its fitted start states and
    # projects out what those states absorb (variable projection; one simulation per parameter, compiled diagnosis
    # only), "difference" takes forward differences of the nuisance-fitted residuals (a Gauss-Newton fit per
    # perturbed parameter set: the numpy path's, and a reference for the projected one)
    fit_jacobian: str = "projected"
    # Least-squares runs per candidate fit, from the best starts with distinct roads: a run started in the nominal
    # road's basin can stop there (a non-smooth point of the windowed residuals) far from the effect's optimum [-]
    fit_starts: int = 2
    # Loss of the fits on the normalised residuals (scale FIT_LOSS_SCALE noise std). A robust loss keeps the few
    # lock-up windows, whose timing no model predicts, from bending the road away from the bulk of the data.
    fit_loss: str = "soft_l1"
    sig_z: float = 4.0  # robust held-out improvement (noise standard deviations) a candidate must exceed [-]
    ratio_explained: float = 0.35  # a verdict leaves at most this share: gap_after <= ratio * gap_before [-]
    gap_none: float = 1.1  # nominal gap (noise units) below which the model fits within noise [-]
    gap_within_noise: float = 0.3  # a candidate leaving a robust held-out gap below this explains the gap [-]
    substeps: int = DEFAULT_SUBSTEPS  # physics substeps per sample
    jobs: int | None = None  # processes for the candidate fits (None: min(2, available cores))
    joint: bool = True  # also fit the two best significant candidates together
    drift_check: bool = True  # refit the verdict's model on each half of the log; a drift makes it unexplained
    # On a log whose nominal model fits within the noise, a candidate is significant only if its evidence survives
    # the noise covariance read from the candidate's own held-out residual (fricenv.gap.quarter_car.guard)
    false_discovery_guard: bool = True
    drift_z: float = 3.0  # paired z of the early/late refit over the constant model for a drift (one test) [-]
    drift_alpha: float = 0.01  # two-sided level of the early/late parameter-shift test, over the model's parameters [-]
    candidates: tuple[str, ...] = tuple(EFFECTS)  # effects to try
    # Prediction windows simulated by the compiled (numba) kernel; False runs the numpy EffectSimulator path (the
    # reference path, kept to time the speed-up and to check the kernel against it)
    compiled: bool = True

    def check(self) -> None:
        """Reject unknown candidates and losses (at diagnosis time: effects may be registered after import), and a
        drift test's level outside (0, 1).

        :raises ValueError: with the valid names or range.
        """
        unknown = [c for c in self.candidates if c not in EFFECTS]
        if unknown:
            raise ValueError(f"unknown candidate effect(s) {', '.join(unknown)}; valid effects: {', '.join(EFFECTS)}")
        if self.fit_jacobian not in FIT_JACOBIANS:
            raise ValueError(f"DiagnoseConfig.fit_jacobian must be one of {', '.join(FIT_JACOBIANS)}, "
                             f"got {self.fit_jacobian!r}")
        if self.fit_loss not in FIT_LOSSES:
            raise ValueError(f"DiagnoseConfig.fit_loss must be one of {', '.join(FIT_LOSSES)}, got {self.fit_loss!r}")
        if not 0.0 < self.drift_alpha < 1.0:
            raise ValueError(f"DiagnoseConfig.drift_alpha must lie in (0, 1), got {self.drift_alpha!r}")


DEFAULT_CONFIG = DiagnoseConfig()
