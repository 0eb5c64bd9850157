"""From a log file to a car's session diagnosis: a log is a car's session when it carries a car's channels
(:func:`fricenv.gap.car.session.is_session`); any other log is the quarter car's."""

from __future__ import annotations

from fricenv.errors import InvalidInputError
from fricenv.gap.car.config import CarConfig
from fricenv.gap.car.diagnose import SessionDiagnosis, diagnose_session
from fricenv.gap.car.model import EFFECT_PARAMS
from fricenv.gap.car.session import is_session, load_car_params, session_of
from fricenv.logs import read_log
from fricenv.plants import quarter_car as qc
from fricenv.utils import read_json_object

__all__ = ["car_session", "diagnose_car_file", "diagnose_car_log", "is_session_diagnosis"]


def car_session(log, params_file=None):
    """``(session, car, quarter-car params)`` when ``log`` (a read quarter-car log) is a car's session, else None.

    :raises InvalidInputError: a session without a car section in ``--params``.
    """
    path = getattr(log, "source", "log")
    if not is_session(log):
        return None
    has_car = params_file is not None and "car" in read_json_object(params_file, "vehicle parameters")
    if not has_car:
        raise InvalidInputError(f"{path}: a car's session (throttle, yaw rate or several wheels) needs --params with "
                                'a car section, e.g. {"r": 0.33, "car": {"mass": 790.0, "lf": 1.248, "lr": 1.7328}}')
    p, car = load_car_params(params_file)
    return session_of(log, car), car, p


def diagnose_car_log(log, params_file=None, candidates=None) -> SessionDiagnosis | None:
    """The session diagnosis of a read quarter-car log, or None when it is not a car's session.

    :param candidates: effects to try (None: every effect the car model holds); those it does not hold are left
        out.
    """
    found = car_session(log, params_file)
    if found is None:
        return None
    s, car, p = found
    cfg = CarConfig() if candidates is None else \
        CarConfig(candidates=tuple(c for c in candidates if c in EFFECT_PARAMS))
    return diagnose_session(s, car, p if p is not None else qc.PAPER_PARAMS, cfg)


def diagnose_car_file(path, params_file=None, candidates=None) -> SessionDiagnosis | None:
    """:func:`diagnose_car_log` of the log at ``path`` (:func:`fricenv.logs.read_log`)."""
    return diagnose_car_log(read_log(path, "quarter-car"), params_file, candidates)


def is_session_diagnosis(dg) -> bool:
    """Whether ``dg`` is a car session's diagnosis (:class:`SessionDiagnosis`)."""
    return isinstance(dg, SessionDiagnosis)
