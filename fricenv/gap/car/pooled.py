"""The car's parameters fitted across its events: what belongs to the car (the effects' parameters of
:data:`fricenv.gap.car.model.EFFECT_PARAMS`) is shared by all events, each event has its own slip stiffness (its
road state) and each window its own start speed. Held out by event (each event predicted by a fit that did not see
it; the held-out event's slip stiffness is fitted on its own samples, like its start speeds; with more events than
``CarConfig.max_folds``, several events are held out together), or, with fewer than ``CarConfig.min_events``
events, by blocks within the events.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from fricenv.gap.car.config import CarConfig
from fricenv.gap.car.model import (
    EFFECT_PARAMS,
    PARAM_BOUNDS,
    SLIP_STIFFNESS_BOUNDS,
    SLIP_STIFFNESS_START,
    window_mse,
    window_residuals,
)
from fricenv.gap.car.session import CarParams

__all__ = ["Fit", "HeldOut", "Problem", "cross_fit", "event_folds", "fit", "free_names", "scheme"]


@dataclass
class Problem:
    """The events and what every fit shares: the car, the mapped corner, the noise levels, the nominal parameters,
    the free-rolling radii and the coast-down drag (``radius_error``'s radii and ``drag``'s coefficients when
    measured: held, not fitted on the events)."""

    events: list  # EventData
    car: CarParams
    mapped: str
    sigma: dict
    base: dict  # nominal parameters
    rolling: dict | None  # corner -> free-rolling radius
    cfg: CarConfig
    drag: dict | None = None  # c0, c2 measured in the session's coasting

    def start(self, effects) -> dict:
        """The parameters a fit of ``effects`` starts from (the radii measured in free rolling when known)."""
        x = dict(self.base)
        if "radius_error" in effects and self.rolling:
            x.update({f"r_{c}": r for c, r in self.rolling.items()})
        if "drag" in effects and self.drag:
            x.update(self.drag)
        return x

    def corners(self) -> list[str]:
        return list(self.events[0].wheels) if self.events else []


@dataclass
class Fit:
    x: dict  # every car parameter
    stiffness: np.ndarray  # per event (NaN: not fitted)


@dataclass
class HeldOut:
    """Held-out window errors per event and the fold fits."""

    mse: list  # per event (W_e,)
    fits: list  # Fit per fold

    def all(self) -> np.ndarray:
        return np.concatenate(self.mse) if self.mse else np.zeros(0)


def free_names(effects, pb: Problem) -> list[str]:
    """The parameters a fit of ``effects`` frees (a radius only for a logged wheel; none measured outside the
    events)."""
    names = []
    for e in effects:
        if e == "drag" and pb.drag:
            continue
        for n in EFFECT_PARAMS[e]:
            if n.startswith("r_") and (n[2:] not in pb.corners() or pb.rolling):
                continue
            names.append(n)
    return names


def _to_unit(n: str, v: float) -> float:
    lo, hi = PARAM_BOUNDS[n]
    return float(np.clip((v - lo) / (hi - lo), 1e-6, 1 - 1e-6))


def _from_unit(n: str, u: float) -> float:
    lo, hi = PARAM_BOUNDS[n]
    return lo + (hi - lo) * float(u)


def _event_residuals(pb: Problem, x: dict, stiffness: float, i: int, w: np.ndarray) -> np.ndarray:
    r, _ = window_residuals(pb.events[i], x, stiffness, pb.car, pb.mapped, pb.sigma, w)
    return np.nan_to_num(r.ravel(), nan=0.0)


FD_STEP = 1e-5  # forward-difference step of the fits' Jacobian, in the unit-scaled parameters and log-stiffness


def fit(pb: Problem, effects, train: list, start: dict | None = None) -> Fit:
    """Least squares of the shared parameters of ``effects`` and every event's slip stiffness on the windows
    ``train`` (per event, window indices). The Jacobian is formed by forward differences, an event's stiffness
    perturbing that event's residuals only."""
    names = free_names(effects, pb)
    x0 = dict(start or pb.start(effects))
    used = [i for i, w in enumerate(train) if len(w)]
    P = len(names)

    def unpack(z):
        x = dict(x0)
        x.update({n: _from_unit(n, u) for n, u in zip(names, z[:P])})
        return x, np.exp(z[P:])

    def fun(z):
        x, s = unpack(z)
        return np.concatenate([_event_residuals(pb, x, s[k], i, train[i]) for k, i in enumerate(used)])

    def jac(z):
        x, s = unpack(z)
        base = [_event_residuals(pb, x, s[k], i, train[i]) for k, i in enumerate(used)]
        sizes = np.cumsum([0] + [len(b) for b in base])
        J = np.zeros((sizes[-1], len(z)))
        for j in range(P):
            zj = z.copy()
            zj[j] += FD_STEP if zj[j] + FD_STEP <= 1.0 else -FD_STEP
            xj, _ = unpack(zj)
            J[:, j] = np.concatenate([_event_residuals(pb, xj, s[k], i, train[i]) - base[k]
                                      for k, i in enumerate(used)]) / (zj[j] - z[j])
        for k, i in enumerate(used):
            J[sizes[k]:sizes[k + 1], P + k] = (_event_residuals(pb, x, s[k] * np.exp(FD_STEP), i, train[i])
                                               - base[k]) / FD_STEP
        return J

    z0 = np.r_[[_to_unit(n, x0[n]) for n in names], np.full(len(used), np.log(SLIP_STIFFNESS_START))]
    lo = np.r_[np.zeros(P), np.full(len(used), np.log(SLIP_STIFFNESS_BOUNDS[0]))]
    hi = np.r_[np.ones(P), np.full(len(used), np.log(SLIP_STIFFNESS_BOUNDS[1]))]
    sol = least_squares(fun, z0, jac=jac, bounds=(lo, hi), loss=pb.cfg.fit_loss, f_scale=pb.cfg.loss_scale,
                        max_nfev=pb.cfg.max_nfev, x_scale=1.0, method="trf", tr_solver="lsmr")
    x, s = unpack(sol.x)
    stiffness = np.full(len(pb.events), np.nan)
    stiffness[used] = s
    return Fit(x=x, stiffness=stiffness)


def fit_stiffness(pb: Problem, x: dict, i: int, widx: np.ndarray) -> float:
    """An event's slip stiffness on its windows ``widx`` with the car's parameters held."""
    e = pb.events[i]

    def cost(ls):
        r, _ = window_residuals(e, x, np.exp(ls), pb.car, pb.mapped, pb.sigma, widx)
        z = (np.nan_to_num(r) / pb.cfg.loss_scale) ** 2
        return float(np.sum(2.0 * (np.sqrt(1.0 + z) - 1.0)))

    res = minimize_scalar(cost, bounds=np.log(SLIP_STIFFNESS_BOUNDS), method="bounded", options={"xatol": 1e-3})
    return float(np.exp(res.x))


def scheme(pb: Problem) -> str:
    """``"event"`` with at least ``min_events`` events holding a prediction window, else ``"blocks"``."""
    return "event" if sum(len(e.starts) > 0 for e in pb.events) >= pb.cfg.min_events else "blocks"


def event_folds(pb: Problem) -> list[list[int]]:
    """The events with a prediction window dealt in turn into at most ``max_folds`` held-out folds."""
    held = [i for i, e in enumerate(pb.events) if len(e.starts)]
    n = min(len(held), pb.cfg.max_folds)
    return [held[j::n] for j in range(n)]


def _score(pb: Problem, x: dict, s: float, i: int, widx: np.ndarray) -> np.ndarray:
    r, counts = window_residuals(pb.events[i], x, s, pb.car, pb.mapped, pb.sigma, widx)
    return window_mse(r, counts)


def cross_fit(pb: Problem, effects, warm: HeldOut | None = None) -> HeldOut:
    """Every window predicted by a fit that did not see it (:func:`scheme`)."""
    mse = [np.full(len(e.starts), np.nan) for e in pb.events]
    fits = []
    if scheme(pb) == "event":
        for j, out in enumerate(event_folds(pb)):
            train = [np.zeros(0, int) if i in out else np.arange(len(e.starts)) for i, e in enumerate(pb.events)]
            f = fit(pb, effects, train, _warm(pb, effects, warm, j))
            for k in out:
                w = np.arange(len(pb.events[k].starts))
                mse[k] = _score(pb, f.x, fit_stiffness(pb, f.x, k, w), k, w)
            fits.append(f)
    else:
        for j in range(pb.cfg.blocks):
            train = [np.flatnonzero(e.block != j) for e in pb.events]
            f = fit(pb, effects, train, _warm(pb, effects, warm, j))
            for i, e in enumerate(pb.events):
                w = np.flatnonzero(e.block == j)
                if len(w):
                    s = f.stiffness[i] if np.isfinite(f.stiffness[i]) else fit_stiffness(pb, f.x, i, w)
                    mse[i][w] = _score(pb, f.x, s, i, w)
            fits.append(f)
    return HeldOut(mse=mse, fits=fits)


def _warm(pb: Problem, effects, warm: HeldOut | None, k: int) -> dict:
    """A fold's start: the previous set's fit of the same fold (its parameters stay where they were), and the new
    effect's nominal start."""
    x = pb.start(effects)
    if warm is not None and k < len(warm.fits):
        x.update({n: v for n, v in warm.fits[k].x.items() if n in free_names(effects, pb)})
    return x
