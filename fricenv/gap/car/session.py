"""A car's session as the car diagnosis reads it (:class:`Session`), made from a mapped log, and the car section of
``--params`` (:class:`CarParams`)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from fricenv.errors import InvalidInputError
from fricenv.plants import quarter_car as qc
from fricenv.utils import read_json_object

__all__ = ["CORNERS", "SESSION_CHANNELS", "CarParams", "Session", "is_session", "load_car_params", "session_of"]

CORNERS = ("fl", "fr", "rl", "rr")  # front/rear, left/right
# Channels that make a log a car's session (any one of them present).
SESSION_CHANNELS = ("throttle", "yaw_rate", "steer") + tuple(f"omega_{c}" for c in CORNERS)
GRAVITY = 9.81  # [m/s^2]


@dataclass(frozen=True)
class CarParams:
    """The car section of ``--params``: mass [kg] and the centre of gravity's distance to the front and to the
    rear axle [m]; optional: each wheel's moment of inertia [kg m^2] (0: not modelled), the front axle's share of the
    brake torque (default: its share of the static load), and ``omega_wheel``, the corner of the log's ``omega`` when
    the map does not show it."""

    mass: float
    lf: float
    lr: float
    wheel_inertia: float = 0.0
    brake_balance: float | None = None
    omega_wheel: str | None = None

    def __post_init__(self):
        for name in ("mass", "lf", "lr"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"car.{name} must be finite and > 0, got {value!r}")
        if not np.isfinite(self.wheel_inertia) or self.wheel_inertia < 0:
            raise ValueError(f"car.wheel_inertia must be finite and >= 0, got {self.wheel_inertia!r}")
        if self.brake_balance is not None and not 0.0 < self.brake_balance < 1.0:
            raise ValueError(f"car.brake_balance must lie in (0, 1), got {self.brake_balance!r}")
        if self.omega_wheel is not None and self.omega_wheel not in CORNERS:
            raise ValueError(f"car.omega_wheel must be one of {', '.join(CORNERS)}, got {self.omega_wheel!r}")

    @property
    def wheelbase(self) -> float:
        return self.lf + self.lr

    def static_load(self, corner: str) -> float:
        """A wheel's static vertical load [N] (half its axle's share of the weight)."""
        arm = self.lr if corner.startswith("f") else self.lf
        return self.mass * GRAVITY * arm / (2.0 * self.wheelbase)

    @property
    def front_share(self) -> float:
        """The front axle's share of the brake torque: stated, else its share of the static load [-]."""
        return self.brake_balance if self.brake_balance is not None else self.lr / self.wheelbase

    def effective_mass(self, radii) -> float:
        """The mass the body's deceleration moves: the car and its wheels' rotation, ``m + sum J / r_c^2`` [kg]."""
        return self.mass + sum(self.wheel_inertia / r ** 2 for r in radii)


def load_car_params(path) -> tuple[qc.QuarterCarParams, CarParams | None]:
    """``--params``: the quarter car's keys (:class:`fricenv.plants.quarter_car.QuarterCarParams`) and an optional
    ``"car"`` object (:class:`CarParams`). Unknown keys are rejected, naming the file."""
    raw = dict(read_json_object(path, "vehicle parameters"))
    car_raw = raw.pop("car", None)
    valid = [f.name for f in fields(qc.QuarterCarParams)]
    unknown = sorted(set(raw) - set(valid))
    if unknown:
        raise InvalidInputError(f"{path}: unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(valid)}, car")
    try:
        p = qc.QuarterCarParams(**{k: float(v) for k, v in raw.items()})
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{path}: {exc}") from None
    if car_raw is None:
        return p, None
    if not isinstance(car_raw, dict):
        raise InvalidInputError(f"{path}: 'car' must be an object with mass, lf, lr")
    names = [f.name for f in fields(CarParams)]
    bad = sorted(set(car_raw) - set(names))
    missing = sorted({"mass", "lf", "lr"} - set(car_raw))
    if bad or missing:
        raise InvalidInputError(f"{path}: car: " + (f"unknown key(s) {', '.join(bad)}; " if bad else "")
                                + (f"missing {', '.join(missing)}; " if missing else "") + f"valid: {', '.join(names)}")
    try:
        return p, CarParams(**{k: (v if k == "omega_wheel" else float(v)) for k, v in car_raw.items()})
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{path}: {exc}") from None


@dataclass(frozen=True)
class Session:
    """A car's log: time from the first sample, the mapped wheel's nominal brake torque ``T_b`` [N m], the speed,
    every logged wheel's speed by corner, and what the map adds (throttle, yaw rate, steering)."""

    t: np.ndarray
    T_b: np.ndarray
    v: np.ndarray
    wheels: dict  # corner -> omega [rad/s]
    mapped: str  # the corner of the log's omega
    a_x: np.ndarray | None = None
    throttle: np.ndarray | None = None
    yaw_rate: np.ndarray | None = None
    steer: np.ndarray | None = None
    source: str = "<memory>"
    t_offset: float = 0.0
    torque_from_pressure: bool = False
    warnings: tuple = field(default=())
    radii: dict = field(default_factory=dict)  # corner -> the radius the map converted its rim speed with [m]

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)


def is_session(log) -> bool:
    """Whether a mapped log carries any of a car's session channels (:data:`SESSION_CHANNELS`)."""
    return any(getattr(log, c, None) is not None for c in SESSION_CHANNELS)


def _mapped_corner(omega: np.ndarray, wheels: dict, car: CarParams | None) -> str:
    """The corner of ``omega``: stated in the car section, else the logged corner whose samples it equals, else the
    one corner the map leaves out, else the front left."""
    if car is not None and car.omega_wheel is not None:
        return car.omega_wheel
    for c, w in wheels.items():
        if w.shape == omega.shape and np.allclose(w, omega, equal_nan=True):
            return c
    left = [c for c in CORNERS if c not in wheels]
    return left[0] if len(left) == 1 else "fl"


def session_of(log, car: CarParams | None = None) -> Session:
    """The :class:`Session` of a mapped log (any object with the log's channel attributes; absent ones None).

    :raises InvalidInputError: a log without a speed ``v`` (the car model takes the body's motion from it).
    """
    if getattr(log, "v", None) is None:
        raise InvalidInputError(f"{getattr(log, 'source', 'log')}: a car's session needs the speed channel 'v'")
    omega = np.asarray(log.omega, dtype=float)
    wheels = {c: np.asarray(w, dtype=float) for c in CORNERS
              if (w := getattr(log, f"omega_{c}", None)) is not None}
    mapped = _mapped_corner(omega, wheels, car)
    wheels.setdefault(mapped, omega)
    wheels = {c: wheels[c] for c in CORNERS if c in wheels}
    opt = {k: (None if getattr(log, k, None) is None else np.asarray(getattr(log, k), dtype=float))
           for k in ("a_x", "throttle", "yaw_rate", "steer")}
    mapped_radii = dict(getattr(log, "radii", None) or {})  # channel -> radius, when the log keeps the map's
    radii = {c: float(mapped_radii[f"omega_{c}"]) for c in wheels if f"omega_{c}" in mapped_radii}
    if mapped in wheels and "omega" in mapped_radii:
        radii.setdefault(mapped, float(mapped_radii["omega"]))
    return Session(t=np.asarray(log.t, dtype=float), T_b=np.asarray(log.T_b, dtype=float),
                   v=np.asarray(log.v, dtype=float), wheels=wheels, mapped=mapped, **opt,
                   source=getattr(log, "source", "<memory>"), t_offset=float(getattr(log, "t_offset", 0.0) or 0.0),
                   torque_from_pressure=bool(getattr(log, "torque_from_pressure", False)),
                   warnings=tuple(getattr(log, "warnings", ()) or ()), radii=radii)
