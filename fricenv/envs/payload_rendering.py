"""Headless matplotlib (Agg) renderer of a PayloadExcitation episode: the payload in its workspace and E(t).

Imported lazily by :class:`fricenv.envs.payload.PayloadExcitationEnv` only when ``render_mode="rgb_array"``, so
that the env itself never imports matplotlib.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fricenv.plants.payload import PayloadParams

__all__ = ["PayloadRenderer"]

FIG_SIZE = (8.0, 4.0)  # [inch]
DPI = 80  # 640 x 320 pixels
BODY_HALF_SIZE = 0.08  # drawn half side of the payload square [m]
FORCE_ARROW_SCALE = 0.03  # drawn arrow length per newton [m/N]
E_RANGE = (1e-5, 10.0)  # y-axis limits of the E panel


class PayloadRenderer:
    """Draws the path, the payload (square, sensor point, applied force) and E(t) into an RGB array.

    :param workspace: half width of the workspace [m].
    :param time_limit: x-axis limit of the E panel [s].
    :param params: payload parameters (sensor location rho).
    """

    def __init__(self, workspace: float, time_limit: float, params: PayloadParams):
        self.params = params
        self.fig = Figure(figsize=FIG_SIZE, dpi=DPI)
        self.canvas = FigureCanvasAgg(self.fig)
        ax_xy, ax_e = self.fig.subplots(1, 2)
        lim = 1.2 * workspace
        ax_xy.set_xlim(-lim, lim)
        ax_xy.set_ylim(-lim, lim)
        ax_xy.set_aspect("equal")
        ax_xy.plot([-workspace, workspace, workspace, -workspace, -workspace],
                   [-workspace, -workspace, workspace, workspace, -workspace], "k--", lw=0.8)
        ax_xy.set_xlabel("X [m]")
        ax_xy.set_ylabel("Y [m]")
        (self.path,) = ax_xy.plot([], [], lw=0.8, color="tab:blue")
        (self.body,) = ax_xy.plot([], [], color="tab:orange", lw=1.5)
        (self.sensor,) = ax_xy.plot([], [], "o", color="tab:red", ms=4)
        (self.force,) = ax_xy.plot([], [], color="tab:green", lw=1.5)
        ax_e.set_yscale("log")
        ax_e.set_ylim(*E_RANGE)
        ax_e.set_xlim(0.0, time_limit)
        ax_e.axhline(1e-2, color="grey", ls="--", lw=0.8)
        ax_e.set_xlabel("time [s]")
        ax_e.set_ylabel("E = ||I - S_hat S^-1||")
        (self.e_line,) = ax_e.plot([], [], color="tab:purple")
        self.fig.tight_layout()

    def render(self, t, X, Y, E, theta: float, wrench) -> np.ndarray:
        """An (H, W, 3) uint8 frame.

        :param t: times [s] of the history.
        :param X: true x positions [m].
        :param Y: true y positions [m].
        :param E: calibration errors.
        :param theta: current orientation [rad].
        :param wrench: current applied body-frame wrench (M, f_x, f_y).
        """
        self.path.set_data(X, Y)
        c, s = np.cos(theta), np.sin(theta)
        R = np.array([[c, -s], [s, c]])
        square = BODY_HALF_SIZE * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]], dtype=float)
        centre = np.array([X[-1], Y[-1]])
        pts = square @ R.T + centre
        self.body.set_data(pts[:, 0], pts[:, 1])
        sensor = R @ np.array([self.params.rho_x, self.params.rho_y]) * 0.3 + centre  # drawn at 30 % scale
        self.sensor.set_data([sensor[0]], [sensor[1]])
        f = R @ np.asarray(wrench, dtype=float)[1:] * FORCE_ARROW_SCALE
        self.force.set_data([sensor[0], sensor[0] + f[0]], [sensor[1], sensor[1] + f[1]])
        self.e_line.set_data(t, np.maximum(np.asarray(E, dtype=float), E_RANGE[0]))
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()
