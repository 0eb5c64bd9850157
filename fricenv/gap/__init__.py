"""Sim-to-real gap tool (issue 6): real stand-in and log writer (:mod:`~fricenv.gap.simulate`), diagnosis
(:mod:`~fricenv.gap.diagnose`), reports and plots (:mod:`~fricenv.gap.report`) and validation on withheld effects
(:mod:`~fricenv.gap.validate`). The policy-level API is :func:`fricenv.effects.quarter_car.simulate_with_effects`."""
