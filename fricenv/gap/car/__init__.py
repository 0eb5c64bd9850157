"""A car's session, not one stop: the braking events found in a long log (:mod:`.events`), the car's rolling radii
from its free rolling (:mod:`.radius`), a car model over every logged wheel (:mod:`.model`), the car's parameters
fitted across the events and held out by event (:mod:`.pooled`, :mod:`.select`), and the session's report
(:mod:`.report`). :func:`fricenv.gap.car.diagnose.diagnose_session` runs the whole path."""
