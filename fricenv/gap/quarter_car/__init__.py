"""The quarter car's gap diagnosis: prepared data, windowed simulation, fits, candidates, verdict, report, the real
stand-in (:mod:`~fricenv.gap.quarter_car.simulate`) and validation on withheld effects."""
