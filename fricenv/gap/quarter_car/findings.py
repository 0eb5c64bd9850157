"""What a quarter-car diagnosis found besides its verdict (:class:`Findings`), serialised as report.json's ``where``."""

from __future__ import annotations

from dataclasses import dataclass, field

from fricenv.gap.quarter_car.excitation import NotTestable

__all__ = ["Findings"]


@dataclass
class Findings:
    """The evidence behind a verdict, one field per part of the report's ``where`` (docs/contracts.md).

    :param localisation: where the gap lies: ``segments``, ``regimes``, ``channels``, ``fitted_peak_slip``,
        ``nominal_road`` and ``data`` (:func:`fricenv.gap.quarter_car.localise.localise`).
    :param tests: each candidate's held-out tests (:func:`fricenv.gap.quarter_car.localise.tests_table`).
    :param robust_gap_before: the nominal model's held-out gap with the worst windows left out [noise units].
    :param not_testable: the candidates this log cannot show, with the smallest detectable sizes and caveats.
    :param sensors: what each channel's sensor did (missing, held, outliers, filtered, quantised).
    :param forward_selection: one record per forward-selection step tried.
    :param periodic: a steady line in the nominal wheel-speed residual, or None.
    :param drift_test: the drift test of the model that closes the gap, when it ran.
    :param joint_fit: the joint fit of the two best eligible candidates, when it ran.
    :param expected_effects: effects the log's provenance predicts (a calibration, not a discovery), with why.
    :param alternatives: untested effects that would give the same data as a named one
        (:func:`fricenv.gap.quarter_car.alternatives.alternatives`).
    :param extra: entries a caller adds to ``where`` (the log's time base, its warnings, ...), written last.
    """

    localisation: dict
    tests: dict
    robust_gap_before: float
    not_testable: NotTestable
    sensors: dict | None
    forward_selection: list
    periodic: dict | None
    drift_test: dict | None = None
    joint_fit: dict | None = None
    expected_effects: dict | None = None
    alternatives: list | None = None
    extra: dict = field(default_factory=dict)

    def as_where(self) -> dict:
        """report.json's ``where``: optional parts only where they ran or found something."""
        optional = {"drift_test": self.drift_test, "joint_fit": self.joint_fit,
                    "caveats": self.not_testable.caveats or None, "expected_effects": self.expected_effects,
                    "alternatives": self.alternatives or None}
        where = {**self.localisation, "tests": self.tests, "robust_gap_before": self.robust_gap_before,
                 "not_testable": self.not_testable, "detectable": self.not_testable.detectable,
                 "sensors": self.sensors, "forward_selection": self.forward_selection, "periodic": self.periodic}
        where.update({k: v for k, v in optional.items() if v is not None})
        where.update(self.extra)
        return where
