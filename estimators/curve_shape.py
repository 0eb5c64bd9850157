"""The friction curve's shape, fitted online: a bank of candidate shapes scored on the EKF/RLS's (slip, mu) pairs.

The EKF/RLS estimator (:mod:`estimators.ekf_rls`) maps its slip slope on one fixed curve shape (dry asphalt), so
its peak slip is the dry curve's 0.19 whatever the road: on wet asphalt (peak at 0.088) a slip controller on that
reference brakes far past the peak. Here the shape is identified from the data the estimator already has: each
sample gives a slip ``S`` (eq. (3) at the filtered speed) and the friction in use ``mu = |F| / F_z`` (force EKF).

Model, per candidate shape j (a Magic Formula with its peak normalized to 1, ``g_j(S) = MF(S; B_j, C_j, E_j, 1) /
max MF``) and candidate speed error ``b_m``: ``mu = theta_jm g_j(S_m) + e``. ``theta_jm`` (the road's peak friction
if shape j and error b_m are right) is a scalar weighted least-squares fit with exponential forgetting ``lam`` (a
scalar RLS, eqs. (S1)-(S3) below), and the pair whose weighted residual is smallest fits best:

    (S0)  v_m = (y - b_m - kappa omega R) / (1 - kappa),   S_m = (v_m - omega R) / v_m   (the slip at speed error b_m)
    (S1)  a = lam a + w g_j(S_m)^2,   b = lam b + w g_j(S_m) mu,   c = lam c + w mu^2     (per j, m)
    (S2)  theta_jm = b / a
    (S3)  J_jm = c - b^2 / a      (the weighted residual sum of squares at theta_jm); J_j = min_m J_jm

The speed error (S0). The slip is computed at the filtered speed y, which starts from one noisy wheel speed (0.15
m/s standard deviation in the braking env) and, while the wheel slips, integrates the torque feedforward of eq.
(5): that is the car's deceleration at steady slip, but not while the wheel itself accelerates, so the filter's
error moves by ``kappa = I_w / (m R_w^2)`` (0.026) times any change of the slip speed ``v - omega R``. At 5 m/s a
0.3 m/s error is a slip error of 0.06, as large as the gap between the wet and dry peaks (measured: wet placed on
5 of 10 noise seeds before (S0)). So the error is modelled, ``y - v = b - kappa (v - omega R)`` with the
coupling ``kappa`` known and the offset ``b`` unknown, and ``b`` is profiled out over a grid (``bias_step`` to
``+-bias_max``). Weights (errors in variables): what remains of the speed error, ``sigma_v``, is a friction error
``theta g'(S) sigma_v / v`` on the steep part of the curve; a sample's weight is the inverse of its total
variance, ``w = 1 / (sigma_mu^2 + (theta_jm g_j'(S_m) sigma_v / v_m)^2)`` with the previous ``theta_jm``. Only
samples with ``|S| > SLIP_MIN`` are scored (below it every shape is the same straight line).

The reported shape (S4). A shape is plausible if ``J_j <= J_min + ambiguity max(J_min / n_eff, 1)`` (within
``ambiguity`` residual variances of the best, the variance estimated from the best fit). Among the plausible
shapes the fit reports the safest one: the shape whose peak slip keeps the most friction on the worst plausible
shape, ``argmax_i min_j kept[i, j]`` with ``kept[i, j] = g_j(peak slip of i)`` (:attr:`ShapeBank.kept`). When the
data tell the shapes apart this is the best fit; when they do not (e.g. slips that never pass a peak), it is the
shape that is least wrong whichever of them is true (dry and snow: dry's 0.19 keeps 98.8 % of snow's friction,
snow's 1.0 only 79 % of dry's). Tuned on noise seeds 1-20 of the test logs (``tests/estimators/
test_curve_shape.py``); on fresh seeds 300-309 dry, wet, snow and ice are placed on every seed, and dry->ice and
ice->dry are followed on every fresh and tuning seed (``python -m tests.shape_validation``).

The reported peak slip (S5). Between shapes whose peaks lie far apart the safest bank peak still loses much: a
policy that brakes at dry's 0.19 on wet gets 92 % of wet's friction, and its slips never pass below wet's peak,
so the data never tell wet from dry (measured: a PPO + EKF/RLS policy of training seed 11 held
slip 0.18-0.22 on wet at 20 m/s for 2 s with the fit on dry, ratio 1.09). So the reported peak slip is, per set of
plausible shapes, the slip that keeps most friction on the worst of them, ``argmax_S min_j g_j(S)``
(:attr:`ShapeBank.minimax_slip`, one entry per set), when that keeps more than ``MINIMAX_GAIN`` (5 % of the peak
friction) more than the safest bank peak; otherwise the safest bank peak as before. Dry or wet: 0.128, 97.4 % of
either peak; braking there puts the data on dry's rising and wet's falling side, and the fit decides. Dry or snow,
dry or ice: the bank peak (dry's 0.19, ice's 0.39). The reported shape (:meth:`ShapeFit.best`) and its peak
friction are those of (S4); :meth:`ShapeFit.plausible` gives the set.

A friction jump restarts the memory from the fast copy (forgetting ``fast_forgetting``), i.e. from the data after
it. The fit sees one when the best pair's theta over the fast memory and over the whole memory differ by more than
``jump_ratio``, or when

    (S6)  mu > theta_reported + OVER_MARGIN sigma_mu   on OVER_SAMPLES scored samples in a row

(the friction in use above the road's peak friction, impossible on one road: after ice -> dry under a gentle
policy the wheel spins up without a gate restart, the slips stay on dry's rising side, the fast and slow theta
differ by less than ``jump_ratio``, and the fit held wet at a peak friction of 0.37 while 0.71 was in use, PPO +
EKF/RLS training seed 0 at 20 m/s). A jump seen by the caller (:meth:`ShapeFit.restart`, the
EKF/RLS's gate restarting) does not zero the memory: on a wheel that locks after dry -> ice, data from slip 1 alone
leave every shape plausible (dry->ice then placed on 0.12 of the samples, fresh seed 300). It withholds the
peak friction (NaN: the caller's own, whose RLS restarted) until the fit's jump test restarts the memory from the
fast copy, which holds the slips the wheel swept on its way to the lock, or for ``PENDING_SAMPLES``.

Outputs: the reported shape's peak slip and its ``theta`` (the peak friction) once ``n_eff`` (the forgotten count
of scored samples) reaches ``MIN_SAMPLES``; before, the prior shape (the bank's first, dry asphalt) and no peak
friction (NaN: the caller keeps its own estimate).

The bank (:data:`DEFAULT_BANK`) holds the shapes of the four road presets (:data:`fricenv.plants.tire.ROADS`: dry,
wet, snow, ice). On these roads the fit identifies the surface, as the Burckhardt-table methods do; on another road
it returns the closest shape of the bank. The snow preset rises all the way to slip 1 and is within 1.5 % of its
peak from slip 0.17 on: between snow and dry the data (and the controller) can hardly tell, and need not.

One update is one compiled loop over N estimators (:func:`_update_rows`, numba, built on first use): the single
estimator runs it with N = 1, the batched estimator (:mod:`estimators.batched`) with N, so the two cannot differ.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from estimators.base import EstimatorConfigError
from fricenv.plants.tire import ROADS, MagicFormula, magic_formula_and_dslip

__all__ = ["DEFAULT_BANK", "ShapeBank", "ShapeFit", "ShapeFitParams"]

SHAPE_FORGETTING = 0.995  # lam of (S1): a memory of about 2 s at 10 ms [-]
SIGMA_MU = 0.02  # friction noise of one sample (a_x noise 0.1 m/s^2 is 0.01 on mu) [-]
SIGMA_V = 0.2  # error of the filtered speed left after (S0) [m/s]
SLIP_MIN = 0.02  # samples below this slip are not scored [-]
MIN_SAMPLES = 20.0  # forgotten count of scored samples before the fit is used (0.2 s of braking) [-]
FAST_FORGETTING = 0.95  # lam of the fast copy of (S1) that detects friction jumps: a memory of 0.2 s [-]
JUMP_MIN_SAMPLES = 10.0  # forgotten count of the fast copy before it may detect a jump (it tends to 20) [-]
JUMP_RATIO = 3.0  # a jump: the fast and slow theta of the winning shape differ by more than this factor [-]
SAMPLE_SPEED_FLOOR = 1.0  # smallest bias-corrected speed of a sample in its slip and slip-error weight (1/v) [m/s]
AMBIGUITY = 3.0  # a shape is plausible if its cost is within this many residual variances of the best [-]
SPEED_BIAS_STEP = 0.1  # spacing of the candidate speed errors profiled out of the fit [m/s]
SPEED_BIAS_MAX = 0.4  # largest candidate speed error (2.6 sigma of a reset from one noisy wheel speed) [m/s]
MINIMAX_STEP = 0.001  # slip grid of the reported peak slip (S5) [-]
MINIMAX_GAIN = 0.05  # (S5) leaves the bank's peaks when that keeps this share of the peak friction more [-]
PENDING_SAMPLES = 40  # after a caller's restart, scored samples the peak friction waits for the jump test [-]
OVER_MARGIN = 3.0  # (S6): the friction in use exceeds the peak friction by this many sigma_mu ... [-]
OVER_SAMPLES = 3  # ... this many scored samples in a row: a friction jump [-]


@dataclass(frozen=True)
class ShapeFitParams:
    """Tuning of the shape fit (module docstring)."""

    forgetting: float = SHAPE_FORGETTING  # lam of (S1) [-]
    sigma_mu: float = SIGMA_MU  # friction noise of one sample [-]
    sigma_v: float = SIGMA_V  # speed error [m/s]
    slip_min: float = SLIP_MIN  # smallest scored slip [-]
    min_samples: float = MIN_SAMPLES  # forgotten sample count before the fit is used [-]
    fast_forgetting: float = FAST_FORGETTING  # lam of the jump detector's fast copy [-]
    jump_ratio: float = JUMP_RATIO  # fast / slow theta factor that is a jump [-]
    bias_step: float = SPEED_BIAS_STEP  # spacing of the candidate speed errors [m/s]
    bias_max: float = SPEED_BIAS_MAX  # largest candidate speed error; 0: none profiled [m/s]
    ambiguity: float = AMBIGUITY  # cost margin, in units of the best fit's residual variance, of a plausible shape

    @property
    def biases(self) -> np.ndarray:
        """The candidate speed errors b (M,): the speed in use minus the true one [m/s]."""
        m = round(self.bias_max / self.bias_step)
        return self.bias_step * np.arange(-m, m + 1)

    def __post_init__(self):
        for name in ("forgetting", "fast_forgetting"):
            if not 0.9 <= getattr(self, name) <= 1.0:
                raise EstimatorConfigError(f"ShapeFitParams.{name} must be in [0.9, 1], got {getattr(self, name)!r}")
        if not (np.isfinite(self.jump_ratio) and self.jump_ratio > 1.0):
            raise EstimatorConfigError(f"ShapeFitParams.jump_ratio must be finite and > 1, got {self.jump_ratio!r}")
        for name in ("sigma_mu", "sigma_v", "slip_min", "min_samples"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise EstimatorConfigError(f"ShapeFitParams.{name} must be finite and > 0, got {value!r}")


class ShapeBank:
    """Candidate curve shapes, each a Magic Formula normalized to a peak of 1.

    :param shapes: the candidates (their theta is ignored); the first is the prior (used before any data).
    """

    def __init__(self, shapes: Sequence[MagicFormula]):
        if len(shapes) < 1:
            raise EstimatorConfigError("a shape bank needs at least one candidate shape")
        self.names = tuple(s.name for s in shapes)
        unit = [MagicFormula(s.B, s.C, s.E, 1.0) for s in shapes]
        self.B = np.array([u.B for u in unit])
        self.C = np.array([u.C for u in unit])
        self.E = np.array([u.E for u in unit])
        self.g_max = np.array([u.mu_max for u in unit])
        self.peak_slip = np.array([u.peak_slip for u in unit])
        # kept[i, j]: shape j's friction at shape i's peak slip, a share of its peak (the safest choice, (S4))
        self.kept = self.g(np.tile(self.peak_slip, (1, 1)))[0][0].T
        self.minimax_slip = self._minimax_slips()

    def _minimax_slips(self) -> np.ndarray:
        """The reported peak slip (S5) per set of plausible shapes (bit j of the index: shape j; index 0, no
        shape: the prior's): the slip whose friction, as a share of the peak, is largest on the worst shape of the
        set, ``argmax_S min_j g_j(S)`` over a grid of step ``MINIMAX_STEP`` holding the peaks, if it keeps more
        than ``MINIMAX_GAIN`` more than the safest shape's peak slip of (S4) does; else that peak slip."""
        grid = np.union1d(np.arange(MINIMAX_STEP, 1.0 + MINIMAX_STEP / 2, MINIMAX_STEP), self.peak_slip)
        g = self.g(grid[None, :])[0][0]  # (K, G)
        table = np.full(2 ** len(self), self.peak_slip[0])
        for mask in range(1, table.size):
            chosen = [j for j in range(len(self)) if mask >> j & 1]
            worst = g[chosen].min(axis=0)
            kept = self.kept[np.ix_(chosen, chosen)].min(axis=1)  # (S4) per shape of the set
            safest = chosen[int(np.argmax(kept))]
            table[mask] = grid[np.argmax(worst)] if worst.max() > kept.max() + MINIMAX_GAIN \
                else self.peak_slip[safest]
        return table

    def __len__(self) -> int:
        return len(self.names)

    def g(self, slip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalized shapes and their slopes at ``slip`` (N, M): two (N, K, M) arrays."""
        s = np.asarray(slip, dtype=float)[:, None, :]
        B, C, E, g_max = (x[None, :, None] for x in (self.B, self.C, self.E, self.g_max))
        mu, dmu = magic_formula_and_dslip(s, B, C, E, 1.0)
        return mu / g_max, dmu / g_max


DEFAULT_BANK = ShapeBank(tuple(ROADS.values()))


class ShapeFit:
    """State of eqs. (S1)-(S3) for N estimators over one bank and M candidate speed errors (module docstring).

    :param n: number of estimators (1 for the single estimator).
    :param bank: the candidate shapes.
    :param params: tuning.
    """

    def __init__(self, n: int, bank: ShapeBank = DEFAULT_BANK, params: ShapeFitParams | None = None,
                 coupling: float = 0.0):
        self.n, self.bank = int(n), bank
        self.params = params or ShapeFitParams()
        if not (np.isfinite(coupling) and 0.0 <= coupling < 0.5):
            raise EstimatorConfigError(f"ShapeFit coupling must be in [0, 0.5), got {coupling!r}")
        self.coupling = float(coupling)
        self.biases = self.params.biases
        p = self.params
        self._tuning = np.array([p.forgetting, p.fast_forgetting, p.sigma_mu, p.sigma_v, p.slip_min, p.min_samples,
                                 p.jump_ratio, p.ambiguity, JUMP_MIN_SAMPLES, SAMPLE_SPEED_FLOOR, self.coupling])
        self._rows = np.arange(self.n)
        shape = (self.n, len(bank), len(self.biases))
        self.a, self.b, self.c = np.zeros(shape), np.zeros(shape), np.zeros(shape)
        self.theta = np.zeros(shape)
        self.n_eff = np.zeros(self.n)
        self.fast = [np.zeros(shape) for _ in range(3)]  # (a, b, c) of (S1) with the fast forgetting
        self.n_fast = np.zeros(self.n)
        self.cost = np.full(shape, np.inf)
        self._best = np.zeros(self.n, dtype=np.int64)  # reported shape (S4), the prior 0 until informed
        self._best_bias = np.zeros(self.n, dtype=np.int64)  # its speed error
        self._informed = np.zeros(self.n, dtype=bool)  # n_eff has reached min_samples
        self._plausible = np.zeros(self.n, dtype=np.int64)  # the plausible shapes of (S4), bit j for shape j
        self._pending = np.zeros(self.n, dtype=np.int64)  # samples a caller's restart (:meth:`restart`) waits
        self._over = np.zeros(self.n, dtype=np.int64)  # scored samples in a row above the peak friction (S6)
        self.reset()
        off = np.zeros(self.n)  # an inactive sample changes no state: it loads the compiled update now, not in the
        self.update(off, off, off, np.zeros(self.n, dtype=bool))  # first timed step

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Forget the data of the estimators in ``mask`` (all by default)."""
        m = np.ones(self.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        for arr in (self.a, self.b, self.c, self.theta, *self.fast):
            arr[m] = 0.0
        self.cost[m] = np.inf
        self.n_eff[m] = 0.0
        self.n_fast[m] = 0.0
        self._best[m] = 0
        self._best_bias[m] = len(self.biases) // 2
        self._informed[m] = False
        self._plausible[m] = 0
        self._pending[m] = 0
        self._over[m] = 0

    def restart(self, mask: np.ndarray) -> None:
        """A friction jump seen by the caller (the EKF/RLS's gate restarted) for the estimators in ``mask``: the
        peak friction is withheld (NaN: the caller's own) until the fit's jump test restarts the memory, or for
        ``PENDING_SAMPLES`` scored samples (module docstring)."""
        m = np.asarray(mask, dtype=bool) & self._informed
        self._pending[m] = PENDING_SAMPLES

    def update(self, slip: np.ndarray, mu: np.ndarray, speed: np.ndarray, active: np.ndarray) -> None:
        """Score one sample per estimator: |slip|, friction in use, filtered speed [m/s], each (N,); estimators
        not ``active`` (skipped samples) or below ``slip_min`` are left as they are. One compiled call
        (:func:`_kernel`) for the N estimators."""
        bank = self.bank
        _kernel()(np.asarray(slip, dtype=float), np.asarray(mu, dtype=float), np.asarray(speed, dtype=float),
                  np.asarray(active, dtype=bool), bank.B, bank.C, bank.E, bank.g_max, bank.kept, self.biases,
                  self._tuning, self.a, self.b, self.c, *self.fast, self.theta, self.cost, self.n_eff, self.n_fast,
                  self._best, self._best_bias, self._informed, self._plausible, self._pending, self._over)

    def best(self) -> np.ndarray:
        """Index of the winning shape per estimator (N,), the prior (0) until the fit is used."""
        return self._best.copy()

    def speed_error(self) -> np.ndarray:
        """The winning candidate speed error per estimator (N,) [m/s], 0 until the fit is used."""
        return self.biases[self._best_bias]

    def plausible(self) -> np.ndarray:
        """The plausible shapes of (S4) per estimator (N,), bit j for shape j of the bank (0 before any data)."""
        return self._plausible.copy()

    def outputs(self) -> tuple[np.ndarray, np.ndarray]:
        """(peak slip, peak friction) per estimator, each (N,): the slip of (S5) over the plausible shapes (the
        prior's peak slip until the fit is used) and the reported shape's peak friction (NaN until then)."""
        k, j = self._best, self._best_bias
        theta = self.theta[self._rows, k, j]
        slip = np.where(self._informed, self.bank.minimax_slip[self._plausible], self.bank.peak_slip[0])
        return slip, np.where(self._informed & (self._pending == 0), theta, np.nan)


def _refresh_row(i, a, b, c, theta, cost, n_eff, kept, tuning, best, best_bias, informed, plausible
                 ) -> tuple[int, int]:
    """theta (S2), the costs (S3), the fit's winner and the reported shape (S4) of estimator ``i`` from its sums;
    returns the winner (shape, speed error). Plain Python compiled by :func:`_kernel`."""
    n_shapes, n_biases = a.shape[1], a.shape[2]
    fit_k, fit_j, best_cost = 0, 0, np.inf
    for k in range(n_shapes):
        for j in range(n_biases):
            pos = a[i, k, j] > 0
            theta[i, k, j] = b[i, k, j] / a[i, k, j] if pos else 0.0  # (S2)
            cost[i, k, j] = c[i, k, j] - b[i, k, j] ** 2 / a[i, k, j] if pos else np.inf  # (S3)
            if cost[i, k, j] < best_cost:
                fit_k, fit_j, best_cost = k, j, cost[i, k, j]
    informed[i] = n_eff[i] >= tuning[5]
    limit = best_cost + tuning[7] * max(best_cost / max(n_eff[i], 1.0), 1.0)
    safest, safest_kept, plausible[i] = 0, -np.inf, 0
    for k in range(n_shapes):  # (S4): the plausible shape whose peak keeps most friction on the worst plausible one
        if cost[i, k].min() <= limit:
            plausible[i] += 1 << k
            worst = np.inf
            for j in range(n_shapes):
                if cost[i, j].min() <= limit:
                    worst = min(worst, kept[k, j])
            if worst > safest_kept:
                safest, safest_kept = k, worst
    best[i] = safest if informed[i] else 0
    best_bias[i] = np.argmin(cost[i, safest]) if informed[i] else n_biases // 2
    return fit_k, fit_j


def _update_rows(slip, mu, speed, active, B, C, E, g_max, kept, biases, tuning, a, b, c, fa, fb, fc, theta, cost,
                 n_eff, n_fast, best, best_bias, informed, plausible, pending, over) -> None:
    """:meth:`ShapeFit.update` for every estimator, in place: (S0)-(S4) and the jump restart. ``tuning`` holds
    (lam, fast lam, sigma_mu, sigma_v, slip_min, min_samples, jump_ratio, ambiguity, jump min samples, speed
    floor, coupling). Plain Python compiled by :func:`_kernel`."""
    lam, lam_fast, sigma_mu, sigma_v, slip_min = tuning[0], tuning[1], tuning[2], tuning[3], tuning[4]
    ratio, floor, kappa = tuning[6], tuning[9], tuning[10]
    for i in range(slip.shape[0]):
        s, m = abs(slip[i]), abs(mu[i])
        if not (active[i] and s > slip_min):
            continue
        wr = speed[i] * (1.0 - s)  # the wheel's surface speed
        for j in range(biases.shape[0]):
            v = max((speed[i] - biases[j] - kappa * wr) / (1.0 - kappa), floor)  # (S0)
            s_b = min(max((v - wr) / v, 0.0), 1.0)
            for k in range(B.shape[0]):
                g, dg = magic_formula_and_dslip(s_b, B[k], C[k], E[k], 1.0)
                g, dg = g / g_max[k], dg / g_max[k]
                w = 1.0 / (sigma_mu**2 + (theta[i, k, j] * dg * sigma_v / v) ** 2)
                ta, tb, tc = w * g * g, w * g * m, w * m * m
                a[i, k, j], b[i, k, j], c[i, k, j] = (lam * a[i, k, j] + ta, lam * b[i, k, j] + tb,  # (S1)
                                                      lam * c[i, k, j] + tc)
                fa[i, k, j], fb[i, k, j], fc[i, k, j] = (lam_fast * fa[i, k, j] + ta, lam_fast * fb[i, k, j] + tb,
                                                         lam_fast * fc[i, k, j] + tc)
        n_eff[i] = lam * n_eff[i] + 1.0
        n_fast[i] = lam_fast * n_fast[i] + 1.0
        k, j = _refresh_row(i, a, b, c, theta, cost, n_eff, kept, tuning, best, best_bias, informed, plausible)
        # a friction jump: the winner's theta over the fast memory and the whole memory differ by more than ratio
        slow, fast = theta[i, k, j], fb[i, k, j] / fa[i, k, j] if fa[i, k, j] > 0 else 0.0
        jump = n_fast[i] >= tuning[8] and slow > 0 and fast > 0 and (fast > ratio * slow or slow > ratio * fast)
        # (S6) the friction in use above the reported peak friction by more than the noise, OVER_SAMPLES in a row
        peak = theta[i, best[i], best_bias[i]]
        over[i] = over[i] + 1 if informed[i] and m > peak + OVER_MARGIN * sigma_mu else 0
        if jump or over[i] >= OVER_SAMPLES:
            a[i], b[i], c[i] = fa[i], fb[i], fc[i]  # the memory restarts from the data after the jump
            n_eff[i] = n_fast[i]
            over[i] = 0
            _refresh_row(i, a, b, c, theta, cost, n_eff, kept, tuning, best, best_bias, informed, plausible)
        pending[i] = 0 if jump else max(pending[i] - 1, 0)


_COMPILED_KERNEL: list = []  # the compiled update, built on first use (numba is not imported with the module)


def _kernel():
    """:func:`_update_rows` compiled with numba (once per process), :func:`_refresh_row` and the library's Magic
    Formula compiled into it (:func:`fricenv.effects.kernels._compile`)."""
    if not _COMPILED_KERNEL:
        import types

        import numba

        from fricenv.effects.kernels import _compile, _guard_cache

        jit = numba.njit(cache=True, error_model="numpy")
        deps = {"magic_formula_and_dslip": _compile(magic_formula_and_dslip)}
        deps["_refresh_row"] = jit(types.FunctionType(_refresh_row.__code__, {**globals(), **deps}, "_refresh_row"))
        rows = jit(types.FunctionType(_update_rows.__code__, {**globals(), **deps}, "_update_rows"))
        _guard_cache({"__name__": __name__, "rows": rows, "refresh": deps["_refresh_row"]})  # tire.py compiled in
        _COMPILED_KERNEL.append(rows)
    return _COMPILED_KERNEL[0]
