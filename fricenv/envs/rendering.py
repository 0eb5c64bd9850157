"""Headless matplotlib (Agg) renderer of a braking episode: speed, slip and brake torque so far.

:class:`EpisodeHistory` records one car of a :class:`~fricenv.envs.braking_sim.BrakingSim` per step and draws it;
matplotlib is imported only at the first frame, so an env that never renders never imports it. Used by
:class:`fricenv.envs.braking.BrakingEnv` and :class:`fricenv.envs.sb3_vec.BrakingSB3VecEnv` (its first sub-env).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["BrakingRenderer", "EpisodeHistory"]

FIG_SIZE = (6.4, 4.8)  # [inch]
DPI = 80  # 512 x 384 pixels


class BrakingRenderer:
    """Draws the history of one braking episode into an RGB array; the figure is reused across frames.

    :param t_max: brake torque at full command [N m] (y-axis limit of the torque panel).
    :param v_max: upper y-axis limit of the speed panel [m/s].
    """

    def __init__(self, t_max: float, v_max: float):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.fig = Figure(figsize=FIG_SIZE, dpi=DPI)
        self.canvas = FigureCanvasAgg(self.fig)
        ax_v, ax_s, ax_t = self.fig.subplots(3, 1, sharex=True)
        (self.line_v,) = ax_v.plot([], [], label="vehicle v")
        (self.line_w,) = ax_v.plot([], [], label="wheel omega r", alpha=0.8)
        ax_v.set_ylabel("speed [m/s]")
        ax_v.set_ylim(0.0, 1.05 * v_max)
        ax_v.legend(loc="upper right", fontsize="small")
        (self.line_s,) = ax_s.plot([], [], color="tab:red")
        ax_s.set_ylabel("slip [-]")
        ax_s.set_ylim(-0.05, 1.05)
        (self.line_t,) = ax_t.plot([], [], color="tab:green")
        ax_t.set_ylabel("torque [N m]")
        ax_t.set_ylim(0.0, 1.05 * t_max)
        ax_t.set_xlabel("time [s]")
        self.axes = (ax_v, ax_s, ax_t)
        self.title = self.fig.suptitle("")
        self.fig.tight_layout()

    def render(self, t, v, wheel, slip, torque, title: str = "") -> np.ndarray:
        """An (H, W, 3) uint8 frame of the given histories (1-D sequences of equal length).

        :param t: time [s].
        :param v: vehicle speed [m/s].
        :param wheel: wheel circumferential speed omega r [m/s].
        :param slip: slip [-].
        :param torque: brake torque [N m].
        :param title: figure title.
        """
        self.line_v.set_data(t, v)
        self.line_w.set_data(t, wheel)
        self.line_s.set_data(t, slip)
        self.line_t.set_data(t, torque)
        t_end = max(float(t[-1]) if len(t) else 0.0, 1.0)
        self.axes[0].set_xlim(0.0, t_end)
        self.title.set_text(title)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()


class EpisodeHistory:
    """The rendered quantities of one car of a sim over its episode so far, and its frames.

    :param t_max: brake torque at full command [N m].
    :param v_max: upper speed of the speed panel [m/s].
    """

    KEYS = ("t", "v", "wheel", "slip", "torque")

    def __init__(self, t_max: float, v_max: float):
        self.t_max, self.v_max = float(t_max), float(v_max)
        self.rows: dict[str, list[float]] = {k: [] for k in self.KEYS}
        self._renderer: BrakingRenderer | None = None
        self.title = ""

    def reset(self) -> None:
        self.rows = {k: [] for k in self.KEYS}

    def record(self, sim: Any, i: int = 0) -> None:
        """Append car ``i``'s state now (time, speed, wheel speed omega r, slip, torque)."""
        values = (float(sim.t[i] * sim.config.dt), float(sim.v[i]), float(sim.omega[i] * sim.config.params.r),
                  float(sim.slip[i]), float(sim.torque[i]))
        for key, value in zip(self.KEYS, values):
            self.rows[key].append(value)
        self.title = f"road: {sim.names[i]}"

    def frame(self) -> np.ndarray:
        """The (H, W, 3) uint8 frame of the episode so far."""
        if self._renderer is None:
            self._renderer = BrakingRenderer(self.t_max, self.v_max)
        h = self.rows
        return self._renderer.render(h["t"], h["v"], h["wheel"], h["slip"], h["torque"], title=self.title)

    def close(self) -> None:
        """Drop the figure (a new one is made at the next frame)."""
        self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None  # a matplotlib figure does not need to travel
        return state
