"""Sim-to-real gap tool: where a model's predictions leave a log, which unmodelled effect explains it, how far the gap
shrinks once that effect is added.

- :mod:`fricenv.gap.core`: what every plant shares: noise levels (:mod:`~fricenv.gap.core.noise`), the verdict rule
  (:mod:`~fricenv.gap.core.verdict`), the report files (:mod:`~fricenv.gap.core.report`) and the one parallel map
  (:mod:`~fricenv.gap.core.pool`).
- :mod:`fricenv.gap.signals`: signal conditioning of a logged channel: missing, held, quantised, filtered and outlier
  samples (:mod:`~fricenv.gap.signals.sensors`), filters the user states (:mod:`~fricenv.gap.signals.stated_filter`),
  and the vehicle speed reconstructed from the wheel (:mod:`~fricenv.gap.signals.speed`).
- :mod:`fricenv.gap.quarter_car` and :mod:`fricenv.gap.payload`: one subpackage per plant: its data, fits, candidates,
  verdict, report, real stand-in and validation.
- :mod:`fricenv.gap.car`: a car's session: its braking events found in a long log, the car's calibrations shared by
  every event, a four-wheel model fitted across the events and held out by event.
- :mod:`fricenv.gap.plants`: the plant registry through which the commands and the fleet reach a plant.
- :mod:`fricenv.gap.fleet`: many logs at once, on local processes or Ray, and the fleet summary.

Dependencies point one way: ``fleet`` -> ``plants`` -> ``car`` -> the plant subpackages -> ``signals`` -> ``core``
(an import-linter contract).
"""
