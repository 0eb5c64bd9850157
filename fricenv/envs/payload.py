"""``fricenv/PayloadExcitation-v0``: excite a planar payload so that its force-moment sensor calibrates fast.

A thin Gymnasium shell over :mod:`fricenv.plants.payload` (physics) and :class:`estimators.fms_rls.FmsRLS` (the
calibrator that runs inside).
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from estimators.fms_rls import FmsRLS
from fricenv.envs.actions import check_action
from fricenv.envs.config import ObsField, decode_observation
from fricenv.plants import payload as pl

__all__ = ["CALIBRATIONS", "ESTIMATOR_OPTIONS", "RESET_OPTION_KEYS", "PayloadExcitationEnv"]

CONTROL_DT = 0.02  # agent step [s] (50 Hz)
PHYSICS_DT = 1e-3  # simulation and estimator step [s] (the paper's 1 ms)
TIME_LIMIT = 20.0  # episode length [s]
WRENCH_LIMIT = (3.0, 5.0, 5.0)  # actuator limits of (M [N m], f_x [N], f_y [N]) at action +-1
WORKSPACE = 0.5  # |X|, |Y| bound [m]
WORKSPACE_PENALTY = 5.0  # reward on leaving the workspace (the episode terminates) [-]
EFFORT_WEIGHT = 0.05  # effort penalty per second at full action on all three axes [1/s]
E_FLOOR = 1e-6  # E is floored here inside the log of the reward (no reward for sub-noise digits)
START_POSITION = 0.1  # initial X, Y drawn uniformly in [-START_POSITION, START_POSITION] [m]
RENDER_FPS = 50
CALIBRATIONS = ("paper", "random")
ESTIMATOR_OPTIONS = (False, True, "rls")
RESET_OPTION_KEYS = ("calibration",)
OBS_S_BOUND = 10.0  # bounds of the S_hat entries in the observation
OBS_READING_BOUND = 50.0  # bounds of the scaled raw readings (a badly conditioned S^-1 can amplify)


class PayloadExcitationEnv(gym.Env):
    """
    ## Description

    The planar payload of Liu, Leung, Tang & Jia (m = 2.5 kg, I_G = 0.75 kg m^2, force-moment sensor at
    rho = (0.2, 0.25) m from the centre of mass, Newton-Euler dynamics eq. (1)) floats in a horizontal plane. Its
    sensor is uncalibrated: it reads ``w_hat = S^-1 w + noise`` for the applied wrench ``w``. The agent is the
    excitation policy: every 20 ms (50 Hz) it sets the applied wrench; inside each step the plant is integrated at
    1 ms and an RLS calibrator (:class:`estimators.fms_rls.FmsRLS`, zero-order-hold reading) absorbs the 20 new
    sensor and vision samples. The goal: a calibration error ``E = ||I - S_hat S^-1||_2`` (eq. 16) that falls fast,
    with little effort, while keeping the payload inside the workspace ``|X|, |Y| <= 0.5 m``.

    Noise is the paper's stated noise: sensor std (0.075 N m, 0.075 N, 0.13 N) (5 % of the eq. (13) amplitudes),
    vision std 0.1 deg and 0.1 mm; ``noise_scale`` multiplies all three.

    ## Action Space

    ``Box(-1, 1, (3,), float32)``: the applied body-frame wrench normalised by the actuator limits.
    Out-of-range values are clipped; NaN/inf, a non-numeric dtype or a wrong shape raise ``ValueError``.

    | Num | Action           | Min | Max | Effect                          |
    |-----|------------------|-----|-----|---------------------------------|
    | 0   | moment M         | -1  | 1   | ``M = a * 3 N m``               |
    | 1   | force f_x (body) | -1  | 1   | ``f_x = a * 5 N``               |
    | 2   | force f_y (body) | -1  | 1   | ``f_y = a * 5 N``               |

    ## Observation Space

    ``Box(float32)`` with finite bounds; entry = physical value / scale, clipped to the bounds. The layout by
    name: ``env.unwrapped.observation_fields``; ``env.unwrapped.decode_observation(obs) -> dict``.

    | Num   | Name          | Observation                                                 | Scale     | Min  | Max |
    |-------|---------------|-------------------------------------------------------------|-----------|------|-----|
    | 0     | theta         | vision orientation, wrapped to (-pi, pi]                    | pi rad    | -1   | 1   |
    | 1     | X             | vision position x                                           | 0.5 m     | -2   | 2   |
    | 2     | Y             | vision position y                                           | 0.5 m     | -2   | 2   |
    | 3     | theta_rate    | vision orientation change over the last step / 20 ms        | 5 rad/s   | -10  | 10  |
    | 4     | X_rate        | vision x change over the last step / 20 ms                  | 1 m/s     | -10  | 10  |
    | 5     | Y_rate        | vision y change over the last step / 20 ms                  | 1 m/s     | -10  | 10  |
    | 6     | M_hat         | raw sensor reading (last sample)                            | 3 N m     | -50  | 50  |
    | 7     | fx_hat        | raw sensor reading                                          | 5 N       | -50  | 50  |
    | 8     | fy_hat        | raw sensor reading                                          | 5 N       | -50  | 50  |
    | 9-11  | last_action   | the previous action (after clipping)                        | 1         | -1   | 1   |
    | 12-20 | S_hat_ij      | (``estimator=True``/``"rls"``) RLS estimate of S, row-major | 1         | -10  | 10  |
    | 21    | excitation    | (estimator only) ``log10(1 + excitation)`` of the RLS       | 1         | 0    | 20  |

    The excitation measure is the smallest-direction power of the filtered reading over the filtered sensor noise
    power (:attr:`estimators.fms_rls.FmsRLS.excitation`).

    ## Rewards

    | Term        | Value                                                                 |
    |-------------|-----------------------------------------------------------------------|
    | calibration | ``log10(max(E_prev, 1e-6)) - log10(max(E, 1e-6))`` (decades gained)  |
    | effort      | ``- effort_weight * 0.02 s * mean(a^2)`` (default weight 0.05 / s)    |
    | workspace   | ``- workspace_penalty`` (default 5) when ``|X|`` or ``|Y|`` > 0.5 m   |

    The calibration terms sum to ``log10 E_0 - log10 E_end`` over an episode (E_0: the identity prior).

    ## Starting State

    At rest, ``theta`` uniform in (-pi, pi], ``X, Y`` uniform in [-0.1, 0.1] m; the RLS starts from the identity
    (an uncalibrated sensor). S is the paper's matrix (``calibration="paper"``) or drawn with entries in [-3, 3]
    and condition number <= 10 (``"random"``) from ``self.np_random``, or a given 3x3 array.

    ## Episode End

    * Termination: the true ``|X|`` or ``|Y|`` exceeds 0.5 m (with the workspace penalty).
    * Truncation: ``time_limit`` (default 20 s, 1000 steps).

    ## Info

    ``E`` (calibration error now), ``S_hat``, ``S`` (true, privileged), ``excitation``, ``estimator_health``
    (:class:`estimators.base.Health` value), ``time`` [s], ``effort`` (mean a^2 of the step), ``out_of_workspace``.

    ## Arguments

    ``gymnasium.make("fricenv/PayloadExcitation-v0", render_mode=None, estimator=False, calibration="paper",
    noise_scale=1.0, time_limit=20.0, effort_weight=0.05, workspace_penalty=5.0, params=PAPER_PARAMS)``.
    Unknown arguments raise ``TypeError``; unknown values raise ``ValueError`` listing the valid ones.
    ``reset(options={"calibration": ...})`` overrides the calibration for one episode.

    ## Version History

    * v0: initial version.
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": RENDER_FPS}

    def __init__(self, render_mode: str | None = None, estimator: bool | str = False, calibration="paper",
                 noise_scale: float = 1.0, time_limit: float = TIME_LIMIT, effort_weight: float = EFFORT_WEIGHT,
                 workspace_penalty: float = WORKSPACE_PENALTY, params: pl.PayloadParams = pl.PAPER_PARAMS):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode {render_mode!r}; valid: "
                             f"{', '.join(self.metadata['render_modes'])} or None")
        if not any(estimator is opt or (isinstance(opt, str) and estimator == opt) for opt in ESTIMATOR_OPTIONS):
            raise ValueError(f"unknown estimator {estimator!r}; valid: False, True, 'rls'")
        self._check_calibration(calibration)
        for name, value, low in (("noise_scale", noise_scale, 0.0), ("time_limit", time_limit, CONTROL_DT),
                                 ("effort_weight", effort_weight, 0.0), ("workspace_penalty", workspace_penalty, 0.0)):
            if not isinstance(value, (int, float, np.floating, np.integer)) or not np.isfinite(value) or value < low:
                raise ValueError(f"{name} must be a finite number >= {low:g}, got {value!r}")
        if not isinstance(params, pl.PayloadParams):
            raise TypeError(f"params must be a PayloadParams, got {type(params).__name__}")
        self.render_mode = render_mode
        self.with_estimate = estimator is True or estimator == "rls"
        self.calibration = calibration
        self.noise = pl.PAPER_NOISE.scaled(wrench=noise_scale, vision=noise_scale)
        self.time_limit = float(time_limit)
        self.effort_weight = float(effort_weight)
        self.workspace_penalty = float(workspace_penalty)
        self.params = params
        self.dt = CONTROL_DT
        self.substeps = round(CONTROL_DT / PHYSICS_DT)
        self.max_steps = round(self.time_limit / CONTROL_DT)
        self.limits = np.array(WRENCH_LIMIT)
        self.rls = FmsRLS(PHYSICS_DT, params, wrench_hold="zoh",
                          vision_std=(max(self.noise.theta_std, 1e-12), max(self.noise.position_std, 1e-12)),
                          wrench_std=tuple(self.noise.wrench_std))
        fields = [
            ObsField("theta", "rad", np.pi, -1.0, 1.0, "vision orientation, wrapped"),
            ObsField("X", "m", WORKSPACE, -2.0, 2.0, "vision position x"),
            ObsField("Y", "m", WORKSPACE, -2.0, 2.0, "vision position y"),
            ObsField("theta_rate", "rad/s", 5.0, -10.0, 10.0, "vision orientation change per step / dt"),
            ObsField("X_rate", "m/s", 1.0, -10.0, 10.0, "vision x change per step / dt"),
            ObsField("Y_rate", "m/s", 1.0, -10.0, 10.0, "vision y change per step / dt"),
            ObsField("M_hat", "N m", WRENCH_LIMIT[0], -OBS_READING_BOUND, OBS_READING_BOUND, "raw moment reading"),
            ObsField("fx_hat", "N", WRENCH_LIMIT[1], -OBS_READING_BOUND, OBS_READING_BOUND, "raw force reading x"),
            ObsField("fy_hat", "N", WRENCH_LIMIT[2], -OBS_READING_BOUND, OBS_READING_BOUND, "raw force reading y"),
            ObsField("last_M", "-", 1.0, -1.0, 1.0, "previous action, moment"),
            ObsField("last_fx", "-", 1.0, -1.0, 1.0, "previous action, force x"),
            ObsField("last_fy", "-", 1.0, -1.0, 1.0, "previous action, force y"),
        ]
        if self.with_estimate:
            fields += [ObsField(f"S_hat_{i + 1}{j + 1}", "-", 1.0, -OBS_S_BOUND, OBS_S_BOUND, "RLS estimate of S")
                       for i in range(3) for j in range(3)]
            fields.append(ObsField("excitation", "-", 1.0, 0.0, 20.0, "log10(1 + RLS excitation measure)"))
        self.observation_fields = tuple(fields)
        self._obs_scale = np.array([f.scale for f in fields])
        self._obs_low = np.array([f.low for f in fields])
        self._obs_high = np.array([f.high for f in fields])
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        self.observation_space = spaces.Box(self._obs_low.astype(np.float32), self._obs_high.astype(np.float32),
                                            dtype=np.float32)
        self._state = None
        self._renderer = None
        self._history = None

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        calibration = self.calibration
        if options is not None:
            if not isinstance(options, dict):
                raise ValueError(f"options must be a dict with keys from {RESET_OPTION_KEYS}, "
                                 f"got {type(options).__name__}")
            unknown = sorted(set(options) - set(RESET_OPTION_KEYS))
            if unknown:
                raise ValueError(f"unknown reset option(s) {unknown}; valid: {', '.join(RESET_OPTION_KEYS)}")
            calibration = options.get("calibration", calibration)
            self._check_calibration(calibration)
        rng = self.np_random
        if isinstance(calibration, str):
            S = pl.PAPER_S.copy() if calibration == "paper" else pl.random_calibration(rng)
        else:
            S = np.asarray(calibration, dtype=float).copy()
        self.S = S
        self.S_inv = np.linalg.inv(S)
        self._state = np.zeros(6)
        self._state[0] = rng.uniform(-np.pi, np.pi)
        self._state[1:3] = rng.uniform(-START_POSITION, START_POSITION, size=2)
        self._k = 0
        self._last_action = np.zeros(3)
        self._pose_now = pl.vision(self._state, self.noise, rng)
        self._pose_prev = self._pose_now.copy()
        self._reading = pl.sensor_reading(np.zeros(3), self.S_inv, self.noise, rng)
        self._estimate = self.rls.reset()
        self.E = float(pl.calibration_error(self._estimate["S"], self.S))
        self.E0 = self.E
        if self.render_mode is not None:
            self._history = {"t": [0.0], "X": [self._state[1]], "Y": [self._state[2]], "E": [self.E]}
        return self._observation(), self._info(0.0, False)

    def step(self, action):
        if self._state is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = check_action(action, (3,), "(M, f_x, f_y normalised)")
        a = np.clip(a.astype(float), -1.0, 1.0)
        w = a * self.limits
        rng = self.np_random
        states = pl.step(self._state, w, self.dt, self.substeps, self.params)  # (21, 6), zero-order hold
        # Samples at the 20 sub-steps of this control step: pose at t_k + i ms (the first one drawn at the last
        # step), sensor reading of the wrench held over [t_k + i ms, t_k + (i+1) ms).
        poses = np.empty((self.substeps, 3))
        poses[0] = self._pose_now
        poses[1:] = pl.vision(states[1:-1], self.noise, rng)
        readings = pl.sensor_reading(np.broadcast_to(w, (self.substeps, 3)), self.S_inv, self.noise, rng)
        self._estimate = self.rls.update_block(poses, readings)
        self._state = states[-1]
        self._pose_prev = self._pose_now
        self._pose_now = pl.vision(self._state, self.noise, rng)
        self._reading = readings[-1]
        self._last_action = a
        self._k += 1
        E_prev = self.E
        self.E = float(pl.calibration_error(self._estimate["S"], self.S))
        effort = float(np.mean(a * a))
        reward = (np.log10(max(E_prev, E_FLOOR)) - np.log10(max(self.E, E_FLOOR))
                  - self.effort_weight * self.dt * effort)
        out = bool(np.any(np.abs(self._state[1:3]) > WORKSPACE))
        if out:
            reward -= self.workspace_penalty
        truncated = (not out) and self._k >= self.max_steps
        if self._history is not None:
            h = self._history
            h["t"].append(self._k * self.dt)
            h["X"].append(self._state[1])
            h["Y"].append(self._state[2])
            h["E"].append(self.E)
        return self._observation(), float(reward), out, truncated, self._info(effort, out)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; use render_mode='rgb_array'")
            return None
        if self._history is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        if self._renderer is None:
            from fricenv.envs.payload_rendering import PayloadRenderer

            self._renderer = PayloadRenderer(WORKSPACE, self.time_limit, self.params)
        h = self._history
        return self._renderer.render(h["t"], h["X"], h["Y"], h["E"], float(self._state[0]),
                                     self._last_action * self.limits)

    def close(self):
        self._renderer = None

    # ------------------------------------------------------------------ helpers
    def decode_observation(self, obs) -> dict[str, float]:
        """Physical values (units of :attr:`observation_fields`) of an observation, by name."""
        return decode_observation(self.observation_fields, obs)

    @staticmethod
    def _check_calibration(calibration) -> None:
        if isinstance(calibration, str):
            if calibration not in CALIBRATIONS:
                raise ValueError(f"unknown calibration {calibration!r}; valid: {', '.join(CALIBRATIONS)} "
                                 f"or a 3x3 array")
            return
        S = np.asarray(calibration, dtype=float)
        if S.shape != (3, 3) or not np.all(np.isfinite(S)) or np.linalg.cond(S) > 1e8:
            raise ValueError(f"calibration must be {', '.join(CALIBRATIONS)} or a finite, invertible 3x3 array")

    def _observation(self) -> np.ndarray:
        pose = self._pose_now
        rate = (pose - self._pose_prev) / self.dt
        theta = (pose[0] + np.pi) % (2 * np.pi) - np.pi
        values = [theta, pose[1], pose[2], *rate, *self._reading, *self._last_action]
        if self.with_estimate:
            values += list(self._estimate["S"].reshape(9))
            values.append(np.log10(1.0 + max(float(self._estimate["excitation"]), 0.0)))
        obs = np.clip(np.array(values) / self._obs_scale, self._obs_low, self._obs_high)
        return obs.astype(np.float32)

    def _info(self, effort: float, out: bool) -> dict[str, Any]:
        est = self._estimate
        return {"E": self.E, "S_hat": np.array(est["S"]), "S": self.S.copy(),
                "excitation": float(est["excitation"]), "estimator_health": int(est.health),
                "time": self._k * self.dt, "effort": effort, "out_of_workspace": out}

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state
