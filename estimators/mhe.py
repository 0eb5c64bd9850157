"""Regularized moving horizon estimator (Sui & Johansen), for the quarter car's speed, slip and friction parameters.

The problem, eqs. (9)-(12): at time t, with the last N + 1 wheel speeds Y(t) and N torques U(t), find the window's
first state x(t-N) minimizing

    J = ||W_t (Y(t) - H_t(x(t-N)))||^2 + sum_{i=0..N} beta_i ||x(t-N+i) - xbar(t-N+i)||^2       (12a)

subject to the model x(i+1) = f(x(i), u(i)) (12b, single shooting) and the bounds (12c) on x(t-N). The a priori
trajectory xbar is the previous solution's first state pushed one sample forward and then along the model,
eq. (11). W_t comes from the SVD of the window Jacobian Phi_t = dH_t/dx at the a priori state, eq. (14), with the
singular values below delta thresholded away, eqs. (15)-(16). Directions whose singular value is thresholded get
no weight from the data and are held by the prior: that is how B, C, E stay put when the data do not excite them
(reported as ``Health.NOT_EXCITED``; a brake's torque error ``T_e``, which only a moving command informs, may stay
unexcited in an ``OK`` window).

Two readings of (16) are offered (``weighting=``):

``"literal"``
    Raw SI units, ``W_t = (1/alpha) V S_delta^+ U^T``, ``beta_i = beta``: ``W_t Phi_t = (1/alpha) V_l V_l^T``
    pulls each excited direction to the window's own fit with weight 1e4 against the prior's 1, whatever the units
    -- a sliding-window inversion that cannot filter (the noise of 11 samples goes into theta, about +-0.1).

``"scaled"`` (default)
    The paper notes that its tuning "depends on appropriate scaling of the data, states and model equations". We
    scale the data by the noise (``sigma_y = sqrt(0.2)`` rad/s) and the states by ``D`` = :data:`STATE_SCALES`
    (the prior's spread per window state) and do the SVD (14) and the thresholding in those units: ``Phi_s = Phi
    D / sigma_y = U S V^T``, so ``s_i^2`` is the window's information along ``v_i`` relative to one prior term and
    delta (0.1 for theta alone, 0.8 for four parameters, as in the paper) a threshold on it. ``W_t = (I - U_d
    U_d^T) / sigma_y`` (U_d: left singular vectors with s_i < delta) has the range and null space of the paper's
    ``(1/alpha) V S_delta^+ U^T`` (the thresholded directions are held by the prior) but weighs each excited
    direction by its information s_i^2 instead of 1/alpha^2, so that the prior averages theta over successive
    windows. alpha is not used; (17) holds with ``||(W_t Phi_s)^+|| = 1/s_l <= 1/delta``.

Beyond the paper, and the default (``arrival="ekf"``, ``model_error="auto"``, ``gate=GATE_CHI2``). With B, C, E
fixed at wrong values (cases 1-2) the paper's MHE (exact model (12b), prior terms pinning every window state)
cannot absorb the model error as the EKF's process noise does (case 1 rms_v 0.121 against the EKF's 0.070,
``fricenv paper mhe --seeds 5``). The default solves the usual MHE with process noise:

    J = ||W_t (Y - H)||^2 + ||x(t-N) - xbar(t-N)||^2_{P^-1} + sum_i ||w_i||^2_{Q_vs^-1},
    x(i+1) = f(x(i), u(i)) + (w_i, 0),

with w_i per-sample model errors on (v, slip) penalized by the EKF's ``DEFAULT_EKF_TUNING["Q_std"]``, and the
arrival cost of an EKF run alongside: xbar(t-N), P are that EKF's prior of x(t-N) given y(..t-N-1) (the
"filtering update" of Rao, Rawlings & Lee; with N = 0 the estimator is that EKF). The SVD thresholding is done in
the arrival covariance's units (``Phi_s = Phi L / sigma_y``, P = L L^T). The paper's later prior terms beta_i
(i >= 1) are dropped: they would count the prior N + 1 times (with process noise they make case 1 diverge, so
that combination is refused). A solution further than ``gate`` (squared Mahalanobis distance in the EKF's
posterior covariance) from the alongside EKF's x(t|t) is replaced by the EKF's (info ``gated``): on dry with four
parameters an occasional window fits the slip on the wrong side of the peak (case 3, seed 1: 3.6 m/s once).
Measured (``fricenv paper mhe --seeds 5``; seeds 3-7 to check): v within 0.6 % of the EKF's, slip 1-10 % better
in every case; arrival means from the MHE's own estimates were worse (they count the window's data twice). The
paper's MHE is ``arrival="paper", model_error=None``; ``model_error=(std_v, std_slip)`` sets the process noise.

Outliers (:mod:`estimators.outliers`): the alongside EKF is the quarter-car EKF itself
(:class:`estimators.ekf.QuarterCarEKF`, attribute ``arrival_filter``, with this MHE's noise); it runs for every
arrival option and gates every wheel speed on its innovation. A rejected sample stays in the window with zero
weight (its row removed before the SVD) and the EKF skips it (``Health.OUTLIER``); the ``max_rejections + 1``-th
in a row restarts the EKF from the reference speed (:mod:`estimators.mismatch`) and the window after it
(``Health.REINITIALISED``). A persistent innovation (a model error, :mod:`estimators.mismatch`) is no outlier: the
EKF updates with it under raised process noise, and the window keeps it with its full weight.

Solver: a few projected Levenberg-Marquardt iterations on a compiled CasADi SX function (window outputs, states,
Jacobians; weights applied in numpy), warm-started from the a priori solution, bounds by an active set plus
projection, at most ``MAX_EVALS`` model evaluations per update. A solve that raises or gives a non-finite result
falls back to the a priori trajectory (``Health.SOLVER_FAILED``).
"""

from __future__ import annotations

from collections import deque

import casadi as ca
import numpy as np

from estimators.base import Estimate, Estimator, EstimatorConfigError, Health, check_dt
from estimators.ekf import QuarterCarEKF
from estimators.mhe_config import MHEConfig
from estimators.outliers import Verdict
from estimators.quarter_car_model import AugmentedModel
from estimators.tuning import (
    DEFAULT_ARRIVAL,
    GATE_CHI2,
    HORIZON,
    PAPER_TUNING,
    SLIP_PRIOR,
    STATE_SCALES,
    V_PRIOR,
)

__all__ = ["DEFAULT_ARRIVAL", "GATE_CHI2", "HORIZON", "PAPER_TUNING", "STATE_SCALES", "RegularizedMHE"]

LM_DAMPING0 = 1e-6  # initial Levenberg-Marquardt damping (relative to diag(J^T J))
LM_DAMPING_MAX = 1e6  # give up above this damping
TOL_STEP = 1e-9  # stop when the relative cost decrease is below this
SV_FLOOR = 1e-12  # relative singular value treated as exactly zero
MAX_EVALS = 8  # model evaluations per update (bounds the worst-case time)
PD_JITTER = 1e-12  # added to the arrival covariance before its Cholesky factor
BOUND_TOL = 1e-9  # relative distance at which a bound counts as active


class RegularizedMHE(Estimator):
    """The regularized MHE of Sui & Johansen on the augmented quarter-car model.

    ``update(omega, u)`` takes the wheel speed at time t and the input held from t to t+1 (the torque, or
    ``(T_b, a_x)``: :attr:`input_columns`), and returns x(t|t).
    Until N + 1 samples have arrived it returns the a priori trajectory (``arrival="ekf"``: the alongside EKF's
    estimate; ``Health.NOT_EXCITED``, info ``warming_up``). Values: ``v``, ``slip``, theta, B, C, E and ``mu``.

    :param estimated: parameters augmented to the state (subset of theta, B, C, E).
    :param dt: sample time [s].
    :param config: the options (:class:`estimators.mhe_config.MHEConfig`: horizon, alpha, beta, delta,
        weighting, arrival, state_scales, noise_std, max_iter, model_error, gate, outlier_gate), or give them as
        keyword ``options``. ``arrival="paper"`` is the paper's prior terms beta_i ||(x_i - xbar_i)/D||^2 of (12a),
        ``"ekf"`` the arrival cost of an EKF run alongside (||x(t-N) - xbar||^2 in P^-1, beyond the paper);
        ``model_error`` the process noise in the window (``"auto"``: the EKF's Q_std of v and slip with the EKF
        arrival cost, else none; with an arrival filter that carries the torque error ``T_e``, each sample's model
        errors take the variance of (v, slip) that its jump adds, :func:`estimators.ekf.torque_step_noise`); ``gate``
        returns the alongside EKF's estimate when the solution is further than this squared Mahalanobis distance
        from it (info ``gated``); ``outlier_gate`` gates the wheel speed on the alongside EKF's innovation (module
        docstring, "Outliers").
    :param model: a prebuilt :class:`AugmentedModel` (one whose speed follows ``a_x`` makes the inputs ``(T_b, a_x)``
        per sample, ``mhe-ax``).
    :param filter_options: options of the arrival filter (:class:`QuarterCarEKF`: ``P0_std``, ``Q_std``,
        ``Q_braking_std``); with them, ``model_error="auto"`` is that filter's process noise on (v, slip), its braked
        value once a brake torque has acted.
    """

    measurement_columns = ("omega",)
    input_columns = ("T_b",)
    names = ("v", "slip", "theta", "B", "C", "E", "mu")

    def __init__(self, estimated: tuple[str, ...] = ("theta",), dt: float = 0.01, config: MHEConfig | None = None,
                 model: AugmentedModel | None = None, filter_options: dict | None = None, **options):
        dt = check_dt(dt)
        if config is not None and options:
            raise EstimatorConfigError(f"give either config or options, not both (options: {sorted(options)})")
        config = config if config is not None else MHEConfig(**options)
        try:
            self.model = model or AugmentedModel(estimated=tuple(estimated), dt=dt)
        except ValueError as exc:
            raise EstimatorConfigError(str(exc)) from None
        group = "theta-only" if len(self.model.estimated) <= 1 else "all"
        auto_error = isinstance(config.model_error, str)
        self.config = cfg = config.resolved(group)
        self.alpha, self.beta, self.delta = cfg.alpha, cfg.beta, cfg.delta
        self.arrival, self.N, self.weighting = cfg.arrival, cfg.horizon, cfg.weighting
        self.noise_std, self.max_iter, self.gate = cfg.noise_std, cfg.max_iter, cfg.gate
        self.model_error = None if cfg.model_error is None else np.asarray(cfg.model_error, dtype=float)
        self.outlier_gate = cfg.outlier_gate
        scales = {**STATE_SCALES[group], **(cfg.state_scales or {})}
        names = self.model.names
        self.D = np.array([scales[n] for n in names]) if cfg.weighting == "scaled" else np.ones(len(names))
        self.lower, self.upper = self.model.lower(), self.model.upper()
        # the arrival-cost filter and outlier gate: the quarter-car EKF itself, with this MHE's noise
        self.arrival_filter = QuarterCarEKF(self.model.estimated, dt, R=self.noise_std**2, model=self.model,
                                            outlier_gate=self.outlier_gate, **(filter_options or {}))
        self._Q, self._P0, self._R = self.arrival_filter.filter.Q, self.arrival_filter.P0, self.arrival_filter.filter.R
        self.input_columns = self.model.input_names  # ("T_b",), or ("T_b", "a_x") when the speed follows a_x
        # model_error "auto" with the arrival filter's own options: that filter's process noise on (v, slip), and
        # its braked value once a brake torque has acted (filter_options' Q_braking_std)
        self._model_error_braked = None
        if auto_error and filter_options and self.model_error is not None:
            self.model_error = np.sqrt(np.diag(self._Q)[:2])
            if self.arrival_filter.Q_braking is not None:
                self._model_error_braked = np.sqrt(np.diag(self.arrival_filter.Q_braking)[:2])
        # a window is excited when it informs every direction of the state but the torque error's, which only a
        # moving command informs (a held one leaves it at its fading prior)
        self.excited_rank = self.model.nx - (self.arrival_filter.torque_error is not None)
        self._build()
        self.reset()

    # ------------------------------------------------------------------ compiled problem
    def _build(self) -> None:
        """Compile one SX function: the unweighted window pieces and their Jacobians at a decision vector z.

        z = (x(t-N), w) with w the optional model-error inputs. Weights are applied in numpy, so one call per
        Gauss-Newton trial point gives residual, Jacobian, Phi (eq. (14)), the window trajectory and f(x(t-N)).
        """
        m, N, nx = self.model, self.N, self.model.nx
        nw = 2 * N if self.model_error is not None else 0
        x0 = ca.SX.sym("x0", nx)
        w = ca.SX.sym("w", nw)  # model-error inputs on (v, slip), one pair per sample (option model_error)
        z = ca.vertcat(x0, w)
        U = ca.SX.sym("U", N, len(m.input_names))  # row i: the inputs held over sample i
        xs = [x0]
        f0 = None
        for i in range(N):
            xn = m.step_sx(xs[-1], U[i, :].T)  # (12b)
            if i == 0:
                f0 = xn
            if nw:
                xn = xn + ca.vertcat(w[2 * i:2 * i + 2], ca.SX.zeros(nx - 2))
            xs.append(xn)
        H = ca.vertcat(*[m.measurement_sx(x) for x in xs])  # eq. (9)
        X = ca.horzcat(*xs)
        self._nz = nx + nw
        if self.arrival == "ekf":
            # only the data depend on the later window states: no derivatives of the trajectory needed
            out = ca.vertcat(H, ca.vec(X))
            self._fun = ca.Function("mhe_window", [z, U], [out, ca.jacobian(H, z), f0])
        else:
            out = ca.vertcat(H, ca.vec(X))  # one Jacobian for the data and the prior terms
            self._fun = ca.Function("mhe_window", [z, U], [out, ca.jacobian(out, z), f0])
        self._devJ0 = np.eye(nx, self._nz)[None]  # d (x(t-N) - xbar) / dz
        # the a priori trajectory of eq. (11): once per update, no derivatives
        xb = [x0]
        for i in range(N):
            xb.append(m.step_sx(xb[-1], U[i, :].T))
        self._fun_prior = ca.Function("mhe_prior", [x0, U], [ca.horzcat(*xb)])
        self._zlo = np.r_[self.model.lower(), np.full(nw, -np.inf)]
        self._zhi = np.r_[self.model.upper(), np.full(nw, np.inf)]
        self._w_scale = self._w_scale_free = np.tile(self.model_error, N) if nw else np.zeros(0)
        self._w_scale_braked = np.tile(self._model_error_braked, N) if nw and self._model_error_braked is not None \
            else self._w_scale_free

    def _z(self, x0: np.ndarray) -> np.ndarray:
        return np.r_[x0, np.zeros(self._nz - len(x0))]

    def _evaluate(self, z, Xbar, Y, U) -> dict:
        """Unweighted pieces at z: output error, its Jacobian, prior deviations and theirs, trajectory, f(x0)."""
        out, J, f0 = self._fun(z, U)
        out, J = np.asarray(out).ravel(), np.asarray(J)
        N1, nx = self.N + 1, self.model.nx
        X = out[N1:].reshape(N1, nx)  # row i = x(t-N+i)
        devJ = J[N1:].reshape(N1, nx, self._nz) if J.shape[0] > N1 else self._devJ0
        return {"z": z, "e": Y - out[:N1], "PhiZ": J[:N1], "dev": X - Xbar, "devJ": devJ, "X": X.T,
                "f0": np.asarray(f0).ravel()}

    # ------------------------------------------------------------------ interface
    def reset(self, v: float = V_PRIOR, slip: float = SLIP_PRIOR, params: dict | None = None,
              v_std: float | None = None) -> Estimate:
        """Start from the a priori state of Section IV (v = 19, slip = 0, eq. (18) parameters).

        :param v_std: how well ``v`` is known [m/s], as :meth:`QuarterCarEKF.reset` (the arrival filter's start).
        """
        self.x_prior0 = self.model.nominal_state(v, slip, params)  # xbar of the oldest sample in the buffer
        self._y: list[float] = []
        self._u: list[np.ndarray] = []
        self._x_est0: np.ndarray | None = None  # x(t-N|t) of the last solve
        self._f_est0: np.ndarray | None = None  # f(x(t-N|t), u(t-N)), for the next prior (eq. (11))
        self.arrival_filter.reset(v, slip, params, v_std=v_std)
        self._P = self.arrival_filter.P.copy()  # EKF covariance at the window start (arrival="ekf")
        self._last = self.x_prior0.copy()
        self._n_fail = 0
        self._X_prev: np.ndarray | None = None
        self._w_prev: np.ndarray | None = None
        self._arr_hist: deque = deque(maxlen=self.N + 1)
        self._used: list[bool] = []  # per window sample: False if the gate rejected it
        # per sample, the variance of (v, slip) the torque error's jump adds over the arrival filter's time update
        self._torque_variance: deque = deque(maxlen=self.N + 1)
        return self._estimate(self.x_prior0, Health.OK)

    def _estimate(self, x: np.ndarray, health: Health, info: dict | None = None) -> Estimate:
        return Estimate(self.model.values(x), health, info or {})

    def update(self, measurement, u) -> Estimate:
        sample = self._validated_sample(measurement, u)
        if sample is None:
            return self._estimate(self._last, Health.INVALID_INPUT, {"reason": "NaN or wrong shape; sample skipped"})
        y, uu = sample
        verdict = self._take(y, uu)
        est = self._window_estimate()
        self._ekf_predict(uu)
        if verdict in (Verdict.ACCEPT, Verdict.MISMATCH, Verdict.START):  # no outlier (estimators.mismatch)
            return est
        health = Health.OUTLIER if verdict == Verdict.REJECT else Health.REINITIALISED
        return Estimate(est.values, health, {**est.info, "window_health": est.health})

    def _take(self, y: np.ndarray, u: np.ndarray) -> Verdict:
        """Gate the sample and update the arrival filter (the EKF's correction), append it to the window buffers."""
        f = self.arrival_filter
        verdict, x_post, P_post, _, _ = f.correct(y)
        if verdict in (Verdict.REINIT, Verdict.START):  # the arrival filter restarted from the sample: so does the window
            self._y, self._u, self._used = [], [], []
            self._arr_hist.clear()
            self._torque_variance.clear()
            self.x_prior0, self._X_prev = f.x.copy(), None
        self._y.append(float(y[0]))
        self._u.append(u.copy())  # the window keeps it: not the caller's buffer
        self._used.append(verdict != Verdict.REJECT)  # a rejected sample stays in the window with no weight
        self._arr_hist.append((f.x, f.P))  # prior of x(t) given y(..t-1)
        self._ekf_post = (x_post, P_post)
        return verdict

    def _window_estimate(self) -> Estimate:
        """Warm-up, window solve (eq. (12)), fallback and the EKF-consistency gate."""
        N = self.N
        if len(self._y) < N + 1:  # warming up: propagate the prior, eq. (11), or the alongside EKF's estimate
            if self.arrival == "ekf":
                x = np.clip(self._ekf_post[0], self.lower, self.upper)
            else:
                x = self.x_prior0
                for k in range(len(self._y) - 1):
                    x = self.model.f(x, self._u[k])
            self._last = x
            return self._estimate(x, Health.NOT_EXCITED, {"warming_up": True})
        if len(self._y) > N + 1:  # the window slides: the a priori start is x(t-N-1|t-1) pushed on, eq. (11)
            self._y.pop(0), self._u.pop(0), self._used.pop(0)
            self.x_prior0 = np.clip(self._f_est0, self.lower, self.upper)
        if self.arrival == "ekf":
            self.x_prior0, self._P = self._arr_hist[0]
        Y = np.asarray(self._y)
        U = np.asarray(self._u[:N]).reshape(N, -1)
        self._w_scale = self._w_scale_braked if self.arrival_filter.braked else self._w_scale_free
        if self.arrival_filter.torque_error is not None and len(self._w_scale):  # the window's model errors take it
            self._w_scale = np.sqrt(self._w_scale**2 + np.concatenate(list(self._torque_variance)[-N:]))
        try:
            sol, health, info = self._solve(self.x_prior0, Y, U, np.asarray(self._used))
        except Exception as exc:  # noqa: BLE001 - a failed solve must never raise inside a loop
            sol, health, info = None, Health.SOLVER_FAILED, {"reason": f"{type(exc).__name__}: {exc}"}
        if sol is None:
            # fallback: the a priori trajectory (prior propagated by the model, eq. (11)), computed by functions
            # independent of the failed solve
            self._n_fail += 1
            try:
                Xb = np.asarray(self._fun_prior(self.x_prior0, U))
                f0 = Xb[:, 1]
                usable = bool(np.all(np.isfinite(Xb)))
            except Exception:  # noqa: BLE001
                usable = False
            if not usable:  # even the prior is unusable: hold the last estimate, restart from the prior start
                self._x_est0, self._f_est0 = self.x_prior0, self.x_prior0
                return self._estimate(self._last, Health.SOLVER_FAILED, info)
            self._x_est0, self._f_est0 = self.x_prior0, f0
            self._X_prev = None
            self._last = Xb[:, -1]
            return self._estimate(self._last, Health.SOLVER_FAILED, info)
        self._x_est0 = sol["z"][:self.model.nx]
        self._X_prev, self._w_prev = sol["X"], sol["z"][self.model.nx:]
        self._f_est0 = sol["f0"]
        self._last = sol["X"][:, -1]
        gate = self.gate
        if self.arrival == "ekf" and gate:
            x_ekf, P_ekf = self._ekf_post
            d = self._last - x_ekf
            d2 = float(d @ np.linalg.solve(P_ekf + PD_JITTER * np.eye(len(d)), d))
            info = {**info, "gate_d2": d2}
            if d2 > gate:
                self._last = np.clip(x_ekf, self.lower, self.upper)
                self._X_prev = None
                info["gated"] = True
        return self._estimate(self._last, health, info)

    def _ekf_predict(self, u: np.ndarray) -> None:
        """The arrival filter's time update from x(t|t) to the prior of x(t+1)."""
        self.arrival_filter.propagate(*self._ekf_post, u)
        self._torque_variance.append(self.arrival_filter.torque_variance)

    # ------------------------------------------------------------------ weights and solver
    def _masked_weights(self, Phi: np.ndarray, used: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """:meth:`_weights` over the samples the gate kept, with zero weight on the others."""
        if used.all():
            return self._weights(Phi)
        W_used, s, rank = self._weights(Phi[used])
        W = np.zeros((len(used), len(used)))
        W[np.ix_(np.arange(W_used.shape[0]) if self.weighting == "literal" else used, used)] = W_used
        return W, s, rank

    def _weights(self, Phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """W_t of eq. (16) (literal) or its scaled reading; returns (W (N+1 x N+1), singular values, rank kept)."""
        N1, nx = Phi.shape
        if self.weighting == "literal":
            Uu, s, Vt = np.linalg.svd(Phi, full_matrices=False)  # eq. (14)
            keep = (s >= self.delta) & (s > SV_FLOOR * max(s[0], 1e-300))
            s_inv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
            W = (Vt.T * s_inv) @ Uu.T / self.alpha  # eq. (16), nx x (N+1)
            Wfull = np.zeros((max(N1, nx), N1))  # (more rows than samples only when the gate removed some)
            Wfull[:nx] = W
            return Wfull, s, int(keep.sum())
        if self.arrival == "ekf":
            # the prior is the EKF covariance P = L L^T: scale the states by L, so that s_i^2 is the window's
            # information along v_i relative to the arrival cost's
            L = np.linalg.cholesky(0.5 * (self._P + self._P.T) + PD_JITTER * np.eye(nx))
            Phi_s = Phi @ L / self.noise_std
        else:
            Phi_s = Phi * self.D / self.noise_std
        Uu, s, _ = np.linalg.svd(Phi_s, full_matrices=False)
        keep = s >= self.delta
        Ud = Uu[:, ~keep]
        return (np.eye(N1) - Ud @ Ud.T) / self.noise_std, s, int(keep.sum())

    def _prior_weights(self) -> tuple[np.ndarray, np.ndarray | None]:
        """(weight of x(t-N) - xbar(t-N), weight of the later window states' deviations or None)."""
        if self.arrival == "ekf":
            # ||L^-1 (x - xbar)||^2 = (x - xbar)^T P^-1 (x - xbar), P = L L^T; the EKF covariance carries the whole
            # prior: no terms on the later window states (no double counting)
            L = np.linalg.cholesky(0.5 * (self._P + self._P.T) + PD_JITTER * np.eye(len(self.D)))
            return np.linalg.solve(L, np.eye(len(self.D))), None
        Wp = np.diag(np.sqrt(self.beta) / self.D)
        return Wp, Wp

    def _residual(self, ev: dict, W, Wa, Wp) -> tuple[np.ndarray, np.ndarray]:
        """Weighted residual and Jacobian of (12a) (plus the process-noise terms) from the unweighted pieces."""
        nx = self.model.nx
        r = [W @ ev["e"], Wa @ ev["dev"][0]]
        J = [-W @ ev["PhiZ"], Wa @ ev["devJ"][0]]
        if Wp is not None:
            r.append((ev["dev"][1:] @ Wp.T).ravel())
            J.append(np.einsum("ij,kjl->kil", Wp, ev["devJ"][1:]).reshape(-1, self._nz))
        if self._nz > nx:
            r.append(ev["z"][nx:] / self._w_scale)
            Jw = np.zeros((self._nz - nx, self._nz))
            Jw[:, nx:] = np.diag(1.0 / self._w_scale)
            J.append(Jw)
        return np.concatenate(r), np.vstack(J)

    def _solve(self, xb0: np.ndarray, Y: np.ndarray, U: np.ndarray, used: np.ndarray):
        """Projected Levenberg-Marquardt on (12a) from the a priori start; returns (solution or None, health, info).

        ``used`` marks the window samples the outlier gate kept; the others get no weight."""
        z = self._z(xb0)
        # eq. (11), row i = xbar(t-N+i); with the EKF arrival cost only xbar(t-N) enters
        Xbar = np.asarray(self._fun_prior(xb0, U)).T if self.arrival == "paper" else np.tile(xb0, (self.N + 1, 1))
        nx = self.model.nx
        if self._nz > nx and self._X_prev is not None:
            z[nx:] = np.r_[self._w_prev[2:], 0.0, 0.0]

        ev = self._evaluate(z, Xbar, Y, U)
        nx = self.model.nx
        W, s, rank = self._masked_weights(ev["PhiZ"][:, :nx], used)  # Phi_hat at the a priori state, eq. (14)
        Wa, Wp = self._prior_weights()
        r, J = self._residual(ev, W, Wa, Wp)
        cost = float(r @ r)
        if not np.isfinite(cost):
            return None, Health.SOLVER_FAILED, {"reason": "non-finite cost at the prior"}
        lower, upper = self._zlo, self._zhi
        lam = LM_DAMPING0
        n_eval = 1
        for _ in range(self.max_iter):
            g = J.T @ r
            JtJ = J.T @ J
            diag = np.diag(JtJ).copy() + 1e-12
            # active bounds (12c): variables at a bound whose descent direction points out are held there
            span = np.minimum(upper - lower, 1.0)
            free = ~(((z <= lower + BOUND_TOL * span) & (g > 0)) | ((z >= upper - BOUND_TOL * span) & (g < 0)))
            improved = False
            while lam <= LM_DAMPING_MAX and n_eval < MAX_EVALS:
                step = np.zeros_like(z)
                A = JtJ[np.ix_(free, free)] + lam * np.diag(diag[free])
                step[free] = np.linalg.solve(A, -g[free])
                z_new = np.clip(z + step, lower, upper)  # bounds (12c) by projection
                ev_new = self._evaluate(z_new, Xbar, Y, U)
                n_eval += 1
                r_new, J_new = self._residual(ev_new, W, Wa, Wp)
                cost_new = float(r_new @ r_new)
                if np.isfinite(cost_new) and cost_new <= cost:
                    improved = True
                    lam = max(lam / 10.0, LM_DAMPING0)
                    break
                lam *= 10.0
            if not improved:
                break
            rel = (cost - cost_new) / max(cost, 1e-300)
            z, ev, r, J, cost = z_new, ev_new, r_new, J_new, cost_new
            if rel < TOL_STEP:
                break
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(ev["X"]))):
            return None, Health.SOLVER_FAILED, {"reason": "non-finite solution"}
        health = Health.OK if rank >= self.excited_rank else Health.NOT_EXCITED
        return ev, health, {"singular_values": s, "rank": rank, "cost": cost, "evaluations": n_eval}
