"""Settings of a car's session diagnosis."""

from __future__ import annotations

from dataclasses import dataclass, field

from fricenv.gap.car.events import EventRules
from fricenv.gap.car.model import EFFECT_PARAMS

__all__ = ["CarConfig"]


@dataclass(frozen=True)
class CarConfig:
    """How events are found, cut into prediction windows, held out and scored."""

    rules: EventRules = field(default_factory=EventRules)
    horizon_s: float = 0.4  # prediction window [s]
    pre_s: float = 1.0  # actuator history before an event [s]
    min_events: int = 3  # hold out by event from this many events on; below, by blocks within the events [-]
    max_folds: int = 6  # events dealt in turn into at most this many held-out folds [-]
    blocks: int = 3  # blocks per event when holding out within the events [-]
    sig_z: float = 3.0  # paired z (over held-out windows) an added effect must exceed [-]
    ratio_explained: float = 0.5  # a verdict leaves at most this share: gap_after <= ratio * gap_before [-]
    gap_none: float = 1.1  # nominal gap (noise units) below which the model fits within noise [-]
    max_effects: int = 4  # effects in the selected set at most [-]
    candidates: tuple = tuple(EFFECT_PARAMS)
    fit_loss: str = "soft_l1"
    loss_scale: float = 3.0  # residual scale of the robust loss (noise std) [-]
    max_nfev: int = 200  # least-squares evaluations per fit [-]

    def check(self) -> None:
        unknown = [c for c in self.candidates if c not in EFFECT_PARAMS]
        if unknown:
            raise ValueError(f"CarConfig.candidates: unknown effect(s) {', '.join(unknown)}; valid: "
                             f"{', '.join(EFFECT_PARAMS)}")
        if self.blocks < 2 or self.min_events < 2:
            raise ValueError("CarConfig.blocks and min_events must be >= 2")
