"""Sim-to-real gap tool (issue 6): real stand-in and log writer (:mod:`~fricenv.gap.simulate`), diagnosis
(:mod:`~fricenv.gap.diagnose`, orchestrating :mod:`~fricenv.gap.windows` (data and windowed simulation),
:mod:`~fricenv.gap.params` (named parameter vectors), :mod:`~fricenv.gap.fitting`, :mod:`~fricenv.gap.changepoint`,
:mod:`~fricenv.gap.candidates`, :mod:`~fricenv.gap.stats` (tests and cross-fitting), :mod:`~fricenv.gap.drift`,
:mod:`~fricenv.gap.verdict`, :mod:`~fricenv.gap.localise`, :mod:`~fricenv.gap.pool`), reports and plots
(:mod:`~fricenv.gap.report`) and validation on withheld effects (:mod:`~fricenv.gap.validate`); the payload's
diagnosis (:mod:`~fricenv.gap.payload_diagnose`, :mod:`~fricenv.gap.payload_data`) shares the statistics and the
verdict rule. The policy-level API is :func:`fricenv.effects.quarter_car.simulate_with_effects`."""
