"""What a person or a logger gets wrong in a log, found before any long work (docs/contracts.md, "What the reader
checks"): each finding is an error (:class:`fricenv.logs.csvfile.LogFormatError`, one line) or a warning, a line
``<channel>: <what> ...; <what was done>`` that the log keeps (``log.warnings``) for the report.

Errors: a sample rate outside 10 Hz - 1 kHz (a time in ms read as s, or the reverse), a speed or the mapped wheel
speed mostly negative, a constant wheel speed, a brake torque mostly negative or of a size no wheel can have.
Warnings: an ``a_x`` whose sign, lag or scale disagrees with the slope of ``v`` (it is then left out), another wheel
that is negative, constant or far from ``v`` (left out), a wheel whose speed times its radius is off ``v`` by more
than 5 % while rolling freely (kept: a radius or unit to check).
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fricenv.logs.csvfile import LogFormatError
from fricenv.logs.logmap import WHEELS

__all__ = ["RATE_HZ", "AxAgreement", "LogCheckWarning", "ax_agreement", "check_rate", "check_session",
           "check_speeds",
           "one_line_warnings"]

RATE_HZ = (10.0, 1000.0)  # the sample rates a log may have (median step)
_RATE_TOLERANCE = 0.01  # a logger's clock a percent off its nominal rate is still that rate
_MOVING_V = 0.5  # [m/s]: a sample this fast counts for the sign of a speed
_AX_SMOOTH_S = 0.3  # moving mean applied to v and a_x alike before they are compared [s]
_AX_MAX_LAG_S = 2.5  # lags searched between a_x and the slope of v [s]
_AX_STEP_S = 0.02  # the comparison runs at 50 Hz at most
_AX_MIN_SLOPE_STD = 0.3  # [m/s^2]: below this v hardly changes and the comparison says nothing
_AX_MIN_SPREAD = 0.05  # [m/s^2]: an a_x this flat has no shape to compare
_AX_MIN_CORR = 0.5  # a_x that correlates less with the slope of v follows something else
_AX_LAG_OK = 0.3  # [s]: a longer lag is a delayed or heavily filtered channel (shorter ones the diagnosis undoes)
_AX_GAIN_OK = (0.67, 1.5)
_MIN_BRAKING_S = 0.2  # [s] of braking samples before the brake's size is judged
_BRAKED_MASS_KG = (15.0, 1.0e4)  # T_b / (r x deceleration): a wheel's share of a vehicle, bicycle to truck
_FREE_ROLL_V = 5.0  # [m/s]
_FREE_ROLL_RATIO = 0.05  # |wheel x radius / v - 1| above this while rolling freely: check the radius or unit
_WIDE_RATIO = (0.5, 2.5)  # the 95th percentile of wheel x radius / v while rolling (rpm, km/h, a swapped column)


class LogCheckWarning(UserWarning):
    """A finding of the log checks that does not stop the reading (its message: ``<file>: <channel>: ...``)."""


@contextmanager
def one_line_warnings(stream=None) -> Iterator[None]:
    """Show each :class:`LogCheckWarning` raised inside as one line ``warning: ...`` on ``stream`` (stderr); other
    warnings as Python shows them. For a command line front end."""
    out = stream if stream is not None else sys.stderr
    with warnings.catch_warnings():
        previous = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, LogCheckWarning):
                print(f"warning: {message}", file=out)
            else:
                previous(message, category, filename, lineno, file, line)

        warnings.simplefilter("always", LogCheckWarning)
        warnings.showwarning = show
        yield


def check_rate(path: Path, step: float, line: int) -> None:
    """The median time step ``step`` [s] must give a rate within :data:`RATE_HZ`.

    :raises LogFormatError: naming the file, the line of the first row and the column ``t``.
    """
    lo, hi = RATE_HZ
    rate = 1.0 / step
    if rate < lo * (1 - _RATE_TOLERANCE):
        hint = "is the time in ms (or us) read as s?"
    elif rate > hi * (1 + _RATE_TOLERANCE):
        hint = "is the time in s read as ms (or us)?"
    else:
        return
    raise LogFormatError(f"{path}:{line}: column 't': median step {step:.6g} s ({rate:.4g} Hz) is outside "
                         f"{lo:g} Hz - {hi / 1000:g} kHz; {hint}")


def _filled(x: np.ndarray) -> np.ndarray:
    """NaN samples linearly interpolated from the present ones (ends held)."""
    ok = np.isfinite(x)
    if ok.all():
        return x
    idx = np.arange(len(x))
    return np.interp(idx, idx[ok], x[ok])


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    """Moving mean over ``width`` samples (edges: the mean over what is there)."""
    kernel = np.ones(max(1, min(width, len(x))))
    return np.convolve(x, kernel, "same") / np.convolve(np.ones(len(x)), kernel, "same")


@dataclass(frozen=True)
class AxAgreement:
    """How ``a_x`` follows the slope of ``v``: ``a_x(t + lag) ~ gain dv/dt(t)``, with the correlation there."""

    lag_s: float
    gain: float
    corr: float


def ax_agreement(step: float, v: np.ndarray, a_x: np.ndarray) -> AxAgreement | None:
    """Lag and gain of ``a_x`` against the slope of ``v`` by cross-correlation and regression, both smoothed alike
    over 0.3 s; None when ``v`` hardly changes (a slope spread below 0.3 m/s^2), ``a_x`` is flat (a spread below
    0.05 m/s^2) or the log is too short.

    :param step: the uniform sample step [s].
    """
    if np.count_nonzero(np.isfinite(v)) < 10 or np.count_nonzero(np.isfinite(a_x)) < 10:
        return None
    width = max(3, round(_AX_SMOOTH_S / step))
    every = max(1, round(_AX_STEP_S / step))
    vs, a = _smooth(_filled(v), width)[::every], _smooth(_filled(a_x), width)[::every]
    edge = max(1, width // every)
    if len(vs) < 2 * edge + 20:
        return None
    h = step * every
    dv = np.gradient(vs, h)[edge:-edge]
    a = a[edge:-edge]
    n = len(dv)
    kmax = min(round(_AX_MAX_LAG_S / h), n // 4)
    if float(np.std(dv)) < _AX_MIN_SLOPE_STD or float(np.std(a)) < _AX_MIN_SPREAD:
        return None
    best = (0.0, 0)
    for k in range(-kmax, kmax + 1):
        x, y = (dv[: n - k], a[k:]) if k >= 0 else (dv[-k:], a[: n + k])
        if np.std(y) > 0:
            c = float(np.corrcoef(x, y)[0, 1])
            if abs(c) > abs(best[0]):
                best = (c, k)
    c, k = best
    x, y = (dv[: n - k], a[k:]) if k >= 0 else (dv[-k:], a[: n + k])
    gain = float(np.cov(x, y)[0, 1] / np.var(x, ddof=1))
    return AxAgreement(k * h, gain, c)


def _check_ax(cols: dict[str, np.ndarray], step: float) -> list[str]:
    """The a_x against the slope of v; a disagreeing a_x is left out (removed from ``cols``)."""
    if "a_x" not in cols or "v" not in cols:
        return []
    found = ax_agreement(step, cols["v"], cols["a_x"])
    if found is None:
        return []
    lag, gain, corr = found.lag_s, found.gain, found.corr
    if abs(corr) < _AX_MIN_CORR:
        problem = f"does not follow the slope of v (best correlation {corr:.2f} within {_AX_MAX_LAG_S:g} s)"
    elif corr < 0:
        problem = (f"its sign disagrees with the slope of v (gain {gain:.2f} at lag {lag:.2f} s, correlation "
                   f"{corr:.2f}), as if negated")
    elif abs(lag) > _AX_LAG_OK or not _AX_GAIN_OK[0] <= gain <= _AX_GAIN_OK[1]:
        when = f"trails the slope of v by {lag:.2f} s" if lag >= 0 else f"leads the slope of v by {-lag:.2f} s"
        problem = (f"{when} at {gain:.2f} times its size (correlation {corr:.2f}): a delayed, filtered or "
                   f"mis-scaled channel")
    else:
        return []
    del cols["a_x"]
    return [f"a_x: {problem}; left out"]


def _moving_sign_share(x: np.ndarray, floor: float) -> tuple[float, int]:
    """Share of negative values among the samples with |x| > floor, and their number."""
    moving = np.abs(x) > floor  # NaN compares False
    n = int(np.count_nonzero(moving))
    return (float(np.mean(x[moving] < 0)) if n else 0.0), n


def _slope(step: float, x: np.ndarray) -> np.ndarray:
    return np.gradient(_smooth(_filled(x), max(3, round(_AX_SMOOTH_S / step))), step)


def _check_brake(path: Path, cols: dict[str, np.ndarray], step: float, radius: float) -> None:
    """T_b mostly positive, and sized like a brake torque: T_b / (r x deceleration) within a wheel's share of a
    vehicle's mass, over the braking samples (the deceleration from v, else from omega r)."""
    tb = cols["T_b"]
    peak = float(np.nanmax(np.abs(tb)))
    if peak == 0.0:
        return
    share, n = _moving_sign_share(tb, 0.01 * peak)
    if n >= 3 and share > 0.5:
        raise LogFormatError(f"{path}: column 'T_b' is negative in {share:.0%} of the braking samples; a brake "
                             f"torque is positive when braking (is its sign flipped?)")
    speed = cols["v"] if "v" in cols else cols["omega"] * radius
    dec = -_slope(step, speed)
    braking = (tb > 0.1 * peak) & (dec > 0.5) & (_filled(speed) > 2.0)
    if np.count_nonzero(braking) < max(5, round(_MIN_BRAKING_S / step)):
        return
    mass = float(np.median(tb[braking] / (radius * dec[braking])))
    lo, hi = _BRAKED_MASS_KG
    if not lo <= mass <= hi:
        raise LogFormatError(
            f"{path}: column 'T_b': its size cannot be a brake torque: T_b / (r x deceleration) = {mass:.3g} kg "
            f"(median of {np.count_nonzero(braking)} braking samples, r = {radius:g} m; a wheel's share of a "
            f"vehicle is {lo:g}-{hi:g} kg); check its unit (a pressure's unit and factor in the map)")


def check_speeds(path: Path, cols: dict[str, np.ndarray], radius: float) -> None:
    """v and omega mostly positive; omega not constant while v changes (first: a sign or a stuck wheel would
    otherwise read as a wrong unit).

    :param radius: the wheel radius [m] of ``omega`` (the map's, else a nominal one).
    :raises LogFormatError: one line naming the file and column.
    """
    for name, floor in (("v", _MOVING_V), ("omega", _MOVING_V / radius)):
        if name in cols:
            share, n = _moving_sign_share(cols[name], floor)
            if n >= 3 and share > 0.5:
                raise LogFormatError(f"{path}: column {name!r} is negative in {share:.0%} of its moving samples; "
                                     f"a speed is positive forward (is its sign flipped?)")
    omega = cols["omega"]
    if np.ptp(omega) == 0.0 and "v" in cols and np.nanmax(cols["v"]) - np.nanmin(cols["v"]) > 1.0:
        raise LogFormatError(f"{path}: column 'omega' is constant ({omega[0]:.6g} rad/s in every row) while 'v' "
                             f"changes by {np.nanmax(cols['v']) - np.nanmin(cols['v']):.3g} m/s: a stuck sensor or "
                             f"a constant column mapped as the wheel speed")


def _rolling_ratio(x: np.ndarray, radius: float, v: np.ndarray, free: np.ndarray) -> tuple[float, float, int]:
    """The 95th percentile of wheel x radius / v while moving, and its median while rolling freely (and count)."""
    moving = v > 1.0
    wide = float(np.percentile(x[moving] * radius / v[moving], 95)) if np.count_nonzero(moving) >= 3 else 1.0
    ok = free & np.isfinite(x) & np.isfinite(v)
    n = int(np.count_nonzero(ok))
    return wide, (float(np.median(x[ok] * radius / v[ok])) if n else 1.0), n


def _free_rolling(cols: dict[str, np.ndarray], step: float) -> np.ndarray:
    """Samples with no brake, no drive, hardly any yaw and the car above 5 m/s."""
    v = cols["v"]
    peak = float(np.nanmax(np.abs(cols["T_b"])))
    free = (v > _FREE_ROLL_V) & (np.abs(cols["T_b"]) <= 0.02 * peak)
    if "throttle" in cols:
        free &= np.abs(cols["throttle"]) <= 0.01 * max(float(np.nanmax(np.abs(cols["throttle"]))), 1e-9)
    if "yaw_rate" in cols:
        free &= np.abs(cols["yaw_rate"]) < 0.02
    return free


def _check_wheels(path: Path, cols: dict[str, np.ndarray], step: float, radii: dict[str, float],
                  nominal: float) -> list[str]:
    """The other wheels: sign, constancy and ratio to v (a bad one is left out); every wheel with a radius from
    the map: its free-rolling ratio to v."""
    notes = []
    free = _free_rolling(cols, step) if "v" in cols else None
    min_free = max(3, round(1.0 / step))
    for name in ("omega", *WHEELS):
        if name not in cols:
            continue
        x, r = cols[name], radii.get(name, nominal)
        problem = None
        if name != "omega":
            share, n = _moving_sign_share(x, _MOVING_V / r)
            if n >= 3 and share > 0.5:
                problem = f"negative in {share:.0%} of its moving samples (its sign flipped?)"
            elif np.nanmax(x) == np.nanmin(x):
                problem = "constant (a stuck sensor?)"
        if problem is None and free is not None:
            wide, ratio, n = _rolling_ratio(x, r, cols["v"], free)
            if name != "omega" and not _WIDE_RATIO[0] <= wide <= _WIDE_RATIO[1]:
                problem = f"{name} x r / v = {wide:.3g} while moving (95th percentile, r = {r:g} m; its unit?)"
            elif name in radii and n >= min_free and abs(ratio - 1.0) > _FREE_ROLL_RATIO:
                notes.append(f"{name}: wheel speed x radius / v = {ratio:.4f} while rolling freely (median of {n} "
                             f"samples, radius {r:g} m); check the radius or the unit; kept")
        if problem is not None:
            del cols[name]
            notes.append(f"{name}: {problem}; left out")
    return notes


def check_session(path: Path, cols: dict[str, np.ndarray], step: float, radii: dict[str, float],
                  nominal_radius: float) -> list[str]:
    """The quarter-car channels on the uniform grid, after :func:`check_speeds`: errors raised, warnings returned (channels they leave out are
    removed from ``cols``).

    :param step: the uniform sample step [s].
    :param radii: the radius [m] the column map gave each wheel channel mapped from a rim speed.
    :param nominal_radius: the radius [m] of a wheel speed given in rad/s without one.
    :raises LogFormatError: one line naming the file and column.
    """
    radius = radii.get("omega", nominal_radius)
    _check_brake(path, cols, step, radius)
    return _check_ax(cols, step) + _check_wheels(path, cols, step, radii, nominal_radius)
