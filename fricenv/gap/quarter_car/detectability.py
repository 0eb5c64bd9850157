"""How large an effect must be to show above the noise of a quarter-car log: a power analysis of
the diagnosis' own significance test, from the log itself, decided before any candidate is fitted.

For an effect at a probe size ``q`` (a parameter vector off the value that switches it off), the calibrated nominal
model's held-out residuals would move by ``a = r_0 - r_q`` (the difference of the two models' normalised
predictions on this log, with the per-window nuisance states refitted, :func:`fricenv.gap.quarter_car.windows.window_residuals`).
The road is refitted by every candidate, so the part of ``a`` that a change of the road ``(B, C, E, theta)``
reproduces is no evidence for the effect: ``a`` is projected off the road's Jacobian (finite differences at the
nominal fit). With the per-window squared norm ``S_w`` of the projected ``a`` (soft-capped like the test's), the
windows of largest and smallest gain left out and ``dn`` extra nuisance states per window, the test of
:func:`fricenv.gap.quarter_car.stats.paired_z` expects ``z(s) = (s^2 S - N dn) / (2 s sqrt(S))`` at ``s`` times the probe
(``S = sum S_w``, ``N`` windows kept), so without the soft cap the smallest detectable multiple would be

    s_min = (z_sig + sqrt(z_sig^2 + N dn)) / sqrt(S);                                         (D1)

it is solved with the cap (per window ``m soft_cap(s^2 S_w / m)``, ``m`` fresh samples) by bisection, and the
smallest detectable deviation of each parameter is ``s_min |q - q_off|``. A road parameter at a bound of its range
is left out of the projection (the fit cannot move it outwards). The probes are the extremes of the effect's
validation draw (its registry ``draw``: the sizes the library claims as plausible), on either side. The statistic's
own noise is unit normal, so an effect is not testable, "below noise", only where even a draw ``LUCK_Z`` standard
deviations lucky would not reach the threshold at its plausible size (``s_min`` at ``z_sig - LUCK_Z`` above 1 for
every probe: a chance below 2.5 %); the sizes reported are those detected half the time. The linearisation at the
nominal road can under-rate an effect that the road absorbed nonlinearly (on the tuning logs it rated two effects
below ``z_sig`` that the true model passed), hence the margin. The cost is one batch of window simulations per
effect at the nominal fit (the windows the diagnosis already cut), no fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.effects import registry
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.params import ROAD_BOUNDS, ROAD_NAMES, fd_steps, param_names
from fricenv.gap.quarter_car.stats import CandidateFit, soft_cap, trimmed, window_counts
from fricenv.gap.quarter_car.verdict import RANGE_EDGE
from fricenv.gap.quarter_car.windows import FREE_ROLL_TORQUE, window_nuisances, window_residuals
from fricenv.plants.tire import MagicFormula

__all__ = ["DRAWS", "Detectability", "detectability", "plausible_probes", "road_jacobian"]

# A test statistic's noise is unit normal: an effect is not testable only when even a draw this many standard
# deviations lucky would not pass the threshold at its largest plausible size (a chance below 2.5 %) [-]
LUCK_Z = 2.0
DRAWS = 64  # validation draws whose extremes make the probes (a fixed generator: the same for every log) [-]
DRAW_SEED = 15  # seed of those draws
SCALE_RANGE = (1e-4, 1e3)  # multiples of a probe searched for the smallest detectable one [-]
BISECTIONS = 40  # bisection steps in log scale (relative precision about 1e-10) [-]


@dataclass(frozen=True)
class Detectability:
    """One effect's power analysis on one log.

    :param scale: ``s_min`` of (D1) for the best probe: the multiple of the probe the test calls significant with
        probability 1/2.
    :param scale_lucky: the same at the threshold lowered by ``LUCK_Z``: the multiple below which the test passes with
        probability below 2.5 % (> 1: not testable).
    :param min_detectable: per parameter, the smallest detectable ``|param - off|`` (a searched parameter, the
        change time, is left out: it places the effect rather than sizing it).
    :param plausible: per parameter, the probe's ``|param - off|`` (the largest plausible deviation).
    :param off: per parameter, the value that switches the effect off.
    """

    scale: float
    scale_lucky: float
    min_detectable: dict
    plausible: dict
    off: dict

    @property
    def detectable(self) -> bool:
        return bool(self.scale_lucky <= 1.0)

    def reason(self) -> str | None:
        """None when detectable, else "below noise: needs |param - off| >= X" for each sized parameter."""
        if self.detectable:
            return None

        def dev(k: str) -> str:
            return f"|{k}{'' if self.off[k] == 0 else f' - {self.off[k]:.4g}'}|"

        need = " and ".join(f"{dev(k)} >= {v:.3g}" for k, v in self.min_detectable.items())
        most = ", ".join(f"{dev(k)} = {v:.3g}" for k, v in self.plausible.items())
        return (f"below noise: needs {need}{' together' if len(self.min_detectable) > 1 else ''}; at the largest "
                f"plausible size ({most}) the chance of a significant test is below 2.5 %")


def plausible_probes(effect: str, road: MagicFormula, p, t_mid: float) -> list[dict]:
    """The effect's probes: every parameter at the low, then at the high extreme of :data:`DRAWS` validation draws
    (a fixed generator), the searched parameters (a change time) at ``t_mid``. Empty when the effect has no draw."""
    entry = registry.get(effect)
    if entry.draw is None:
        return []
    rng = np.random.default_rng(DRAW_SEED)
    draws = [entry.draw(road, rng, p) for _ in range(DRAWS)]
    values = {k: np.array([getattr(s, k) for s in draws], dtype=float) for k in entry.param_names}
    probes = []
    for pick in (np.min, np.max):
        probes.append({k: (t_mid if k in entry.searched else float(pick(v))) for k, v in values.items()})
    return probes


def road_jacobian(nominal: CandidateFit, d: Data) -> tuple[np.ndarray, np.ndarray]:
    """The nominal model's normalised residuals on all windows (W, M) and their forward-difference Jacobian in the
    road parameters that are free to move (W * M, <= 4; :func:`_at_bound`)."""
    h = fd_steps(ROAD_NAMES)
    X = np.vstack([nominal.x[None]] + [nominal.x + h[i] * np.eye(len(ROAD_NAMES))[i] for i in range(len(h))])
    r = window_residuals([], nominal.names, X, d)
    J = ((r[1:] - r[0][None]).reshape(len(h), -1) / h[:, None]).T
    return r[0], J[:, ~_at_bound(nominal.x[: len(ROAD_NAMES)])]


def _at_bound(road: np.ndarray) -> np.ndarray:
    """Road parameters within ``RANGE_EDGE`` of their range's ends: a fit cannot move them outwards, so the
    projection leaves them out (it would credit the road with absorbing more than it can)."""
    lo, hi = (np.array([ROAD_BOUNDS[k][i] for k in ROAD_NAMES]) for i in (0, 1))
    tol = RANGE_EDGE * (hi - lo)
    return (road <= lo + tol) | (road >= hi - tol)


def _z(S_w: np.ndarray, m: np.ndarray, s: float, extra_states: int) -> float:
    """The expected :func:`fricenv.gap.quarter_car.stats.paired_z` at ``s`` times a probe whose per-window squared residual
    change is ``S_w`` (uncapped): soft-capped per window, the windows of largest and smallest gain left out
    (:func:`fricenv.gap.quarter_car.stats.trimmed`), less the extra nuisance states' discount."""
    gain = m * soft_cap(s**2 * S_w / m)
    keep = trimmed(gain)
    S = float(np.sum(gain[keep]))
    return (S - extra_states * int(np.sum(keep))) / (2.0 * np.sqrt(S)) if S > 0 else -np.inf


def _scale(a: np.ndarray, J: np.ndarray, counts, extra_states: int, sig_z: float) -> float:
    """``s_min`` of (D1) for the residual change ``a`` (W, M) of a probe, projected off the road's Jacobian: the
    smallest multiple of the probe whose expected z reaches ``sig_z`` (bisection in log scale; the soft cap makes
    (D1) an upper bound, the bisection solves it with the cap)."""
    flat = np.nan_to_num(a.reshape(-1))
    coef, *_ = np.linalg.lstsq(J, flat, rcond=None)
    perp = (flat - J @ coef).reshape(a.shape)
    m = np.maximum(np.broadcast_to(np.asarray(counts, dtype=float), (a.shape[0],)), 1.0)
    S_w = np.sum(perp**2, axis=-1)
    if S_w.size < 2 or _z(S_w, m, SCALE_RANGE[1], extra_states) < sig_z:
        return float("inf")
    lo, hi = np.log(SCALE_RANGE[0]), np.log(SCALE_RANGE[1])
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _z(S_w, m, float(np.exp(mid)), extra_states) >= sig_z else (mid, hi)
    return float(np.exp(hi))


def _braking_middle(d: Data) -> float:
    """Log time of the middle braking window (where a change of the road is placed by the probes) [s]."""
    tmax = max(float(np.max(np.abs(d.Tb))), 1e-9)
    rows = d.starts[:, None] + np.arange(d.horizon)[None, :]
    braking = np.flatnonzero(np.any(np.abs(d.Tb[rows]) > FREE_ROLL_TORQUE * tmax, axis=1))
    w = int(braking[braking.size // 2]) if braking.size else len(d.starts) // 2
    return float(d.t0 + d.dt * d.starts[w])


def detectability(nominal: CandidateFit, d: Data, effects, sig_z: float) -> dict[str, Detectability]:
    """The power analysis (D1) of each of ``effects`` that has a validation draw, at the calibrated nominal fit.

    :param nominal: the calibrated nominal model (its road is the probes' road).
    :param d: the prepared log (its noise levels are the tool's estimate).
    :param effects: effect names.
    :param sig_z: the significance threshold of the verdict (``DiagnoseConfig.sig_z``).
    """
    road_x = nominal.x[: len(ROAD_NAMES)]
    road = MagicFormula(**nominal.road())
    r0, J = road_jacobian(nominal, d)
    counts = window_counts(d)
    t_mid = _braking_middle(d)
    out = {}
    for e in effects:
        probes = plausible_probes(e, road, d.p, t_mid)
        if not probes:
            continue
        entry = registry.get(e)
        off = {q.name: float(np.asarray(q.off_value(road_x, d.p)).reshape(-1)[0]) for q in entry.params}
        X = np.array([np.concatenate([road_x, [pr[k] for k in entry.param_names]]) for pr in probes])
        r = window_residuals([e], param_names([e]), X, d)
        extra = window_nuisances([e], d) - window_nuisances([], d)
        scales = [_scale(r0 - r[i], J, counts, extra, sig_z) for i in range(len(probes))]
        lucky = [_scale(r0 - r[i], J, counts, extra, sig_z - LUCK_Z) for i in range(len(probes))]
        best = int(np.argmin(scales))
        sized = [k for k in entry.param_names if k not in entry.searched]
        dev = {k: abs(probes[best][k] - off[k]) for k in sized}
        out[e] = Detectability(scale=scales[best], scale_lucky=min(lucky), min_detectable={k: scales[best] * v for k, v in dev.items()},
                               plausible=dev, off={k: off[k] for k in sized})
    return out
