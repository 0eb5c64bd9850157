"""Real logger artifacts applied to a clean contract log: a real-like log source for any test.

A clean log (uniform step, SI contract channels, as :mod:`tests.independent_sim` or the payload simulator writes it)
goes in as a dict of arrays; out comes what a vehicle's CAN logger or a rig's acquisition would have written:

quarter car (:func:`real_like_quarter_car`)
    a causal 2nd-order Butterworth low-pass on ``a_x`` and ``v`` (an IMU driver, default 5 Hz), sampling at
    25-200 Hz at jittered instants with the odd dropped row and epoch time stamps, isolated wheel-speed outliers,
    the wheel speed as a quantised rim speed in km/h, ``v`` in km/h, ``a_x`` in g, the brake torque as a line
    pressure in kPa (through a nominal pressure-to-torque factor), extra wheel-speed and steering columns, and a
    column map (``docs/contracts.md``, "Column map") that maps it back;
payload (:func:`real_like_payload`)
    a low-pass on the force-moment sensor, a 30 Hz camera whose pose is held between frames, tracking glitches
    (a 5 mm jump in one frame), jittered stamps with dropped rows, the pose in degrees and millimetres.

Like :mod:`tests.independent_sim`, this module shares no code with :mod:`fricenv` (numpy and scipy only): the
artifacts and the map are written from the contract, so a reader bug cannot cancel a writer bug. The sampling rule:
a continuous channel is the clean signal linearly interpolated at the (jittered, exactly stamped) sample instant;
the commanded torque is the command in force at that instant (zero-order hold).

Usage::

    export = real_like_quarter_car(clean, np.random.default_rng(3), QuarterCarArtifacts(rate_hz=25.0))
    csv_path, map_path = write_export(tmp_dir / "run", export)
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import signal

__all__ = [
    "KMH_PER_MS",
    "STANDARD_GRAVITY",
    "PayloadArtifacts",
    "QuarterCarArtifacts",
    "RealExport",
    "add_outliers",
    "held_camera",
    "imu_lowpass",
    "quantise",
    "real_like_payload",
    "real_like_quarter_car",
    "sample_at",
    "sample_instants",
    "write_export",
]

KMH_PER_MS = 3.6  # [km/h per m/s]
STANDARD_GRAVITY = 9.80665  # [m/s^2 per g]
PA_PER_KPA = 1000.0
MM_PER_M = 1000.0
EPOCH0 = 1_700_000_000.0  # a plausible epoch second [s]; each export adds a random offset of up to a day
ZOH_EPS = 1e-9  # rounding guard when locating an instant in the clean grid [samples]


@dataclass(frozen=True)
class QuarterCarArtifacts:
    """What a vehicle logger does to a quarter-car braking log (defaults: a typical CAN export)."""

    rate_hz: float = 50.0  # logger rate [Hz], 25-200 in the real-like tests
    jitter: float = 0.1  # each sample instant moves uniformly by up to this share of the step [-] (steps: 2x)
    drop_prob: float = 0.01  # probability that a row is lost [-] (never the first or the last)
    imu_cutoff_hz: float | None = 5.0  # Butterworth cut-off on a_x and v [Hz]; None: no filter
    imu_order: int = 2
    wheel_quantum_kmh: float | None = 0.1  # quantum of the wheel-speed column [km/h]; None: none
    # white noise of the wheel-speed sensor, drawn at each logged sample [rad/s]; None: the clean channel is taken as
    # measured (its own noise then reaches the log interpolated between the clean samples)
    wheel_noise_std: float | None = None
    outliers: int = 3  # isolated wheel-speed outliers [-]
    outlier_kmh: tuple[float, float] = (5.0, 15.0)  # their size range, either sign [km/h]
    radius: float = 0.345  # wheel radius the map gives for the km/h rim speed [m]
    pressure_factor: float = 1.5e-4  # nominal brake torque per line pressure [N m per Pa]
    v_rate_hz: float | None = None  # a slower reference speed, held between its updates [Hz]; None: logger rate
    state_filter: bool = False  # the map states the IMU filter on v and a_x (its "filter" entry, from a data sheet)


@dataclass(frozen=True)
class PayloadArtifacts:
    """What a rig's acquisition does to a payload log: F/T at the logger rate, a slower camera."""

    rate_hz: float = 100.0  # logger (F/T) rate [Hz]
    jitter: float = 0.1  # share of the step [-]
    drop_prob: float = 0.01  # [-]
    ft_cutoff_hz: float | None = 20.0  # Butterworth cut-off on M, f_x, f_y [Hz]; None: no filter
    ft_order: int = 2
    camera_hz: float = 30.0  # camera frame rate [Hz]; the pose is held between frames
    glitches: int = 2  # tracking glitches: one camera frame jumps in X or Y [-]
    glitch_m: float = 0.005  # size of a glitch [m]


@dataclass
class RealExport:
    """A real-like export: its columns (export name -> values, in file order), its column map and the truth."""

    columns: dict[str, np.ndarray]
    column_map: dict
    truth: dict = field(default_factory=dict)  # what was applied: spec, dropped rows, outlier rows, epoch0, ...
    comments: tuple[str, ...] = ()


# ----------------------------------------------------------------------------------------------------- artifacts
def sample_instants(t_end: float, rate_hz: float, jitter: float, drop_prob: float,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Sample instants of a jittery logger over ``[0, t_end]``: ``k / rate + U(-jitter, jitter) / rate``.

    :param t_end: last clean time [s].
    :param rate_hz: logger rate [Hz].
    :param jitter: largest move of an instant, as a share of the step [-].
    :param drop_prob: probability that a row is lost (never the first or last, never two in a row).
    :param rng: random generator.
    :return: the kept instants [s] (increasing, in ``[0, t_end]``) and the indices of the dropped rows.
    """
    h = 1.0 / rate_hz
    n = math.floor(t_end / h + ZOH_EPS) + 1
    s = np.arange(n) * h + rng.uniform(-jitter, jitter, n) * h
    s[0], s[-1] = 0.0, min(s[-1], t_end)
    s = np.clip(s, 0.0, t_end)
    drop = rng.random(n) < drop_prob
    drop[0] = drop[-1] = False
    drop[1:] &= ~drop[:-1]  # isolated drops only
    return s[~drop], np.flatnonzero(drop)


def sample_at(t: np.ndarray, x: np.ndarray, s: np.ndarray, hold: bool = False) -> np.ndarray:
    """The clean channel ``x(t)`` (uniform ``t``) at instants ``s``: linear interpolation, or with ``hold`` the value
    in force at ``s`` (zero-order hold, for a commanded torque)."""
    if not hold:
        return np.interp(s, t, x)
    j = np.floor((s - t[0]) / (t[1] - t[0]) + ZOH_EPS).astype(int)
    return x[np.clip(j, 0, len(x) - 1)]


def imu_lowpass(x: np.ndarray, fs: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """A causal Butterworth low-pass as an IMU or sensor driver runs it, started at rest on the first value."""
    sos = signal.butter(order, cutoff_hz, btype="low", fs=fs, output="sos")
    zi = signal.sosfilt_zi(sos) * x[0]
    return signal.sosfilt(sos, x, zi=zi)[0]


def quantise(x: np.ndarray, quantum: float) -> np.ndarray:
    """``x`` rounded to a multiple of ``quantum`` (a CAN signal's resolution)."""
    return np.round(x / quantum) * quantum


def add_outliers(x: np.ndarray, count: int, size: tuple[float, float],
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` isolated outliers (at least 3 rows apart, either sign, size uniform in ``size``).

    :return: the corrupted copy and the outlier rows.
    """
    y = x.copy()
    rows: list[int] = []
    candidates = rng.permutation(np.arange(1, len(x) - 1))
    for i in candidates:
        if len(rows) == count:
            break
        if all(abs(int(i) - r) >= 3 for r in rows):
            rows.append(int(i))
    rows_arr = np.array(sorted(rows), dtype=int)
    y[rows_arr] += rng.choice([-1.0, 1.0], len(rows_arr)) * rng.uniform(*size, len(rows_arr))
    return y, rows_arr


def held_camera(t: np.ndarray, x: np.ndarray, s: np.ndarray, camera_hz: float, offset: float) -> np.ndarray:
    """A camera's pose at logger instants ``s``: the frame taken last at or before each instant, held.

    :param t: clean times (uniform) [s]; ``x`` the clean pose channel there.
    :param camera_hz: frame rate [Hz]; frames at ``offset + j / camera_hz``.
    :param offset: time of frame 0, ``0 <= offset < 1 / camera_hz`` [s]; instants before it hold frame -1, taken
        before the log starts (the clean value at ``t[0]``).
    """
    j = np.floor((s - offset) * camera_hz + ZOH_EPS)
    return np.interp(offset + j / camera_hz, t, x)


# ----------------------------------------------------------------------------------------------------- quarter car
def _epoch(s: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    epoch0 = EPOCH0 + float(rng.uniform(0.0, 86400.0))
    return epoch0 + s, epoch0


def _filtered(clean: dict, names: tuple[str, ...], cutoff: float | None, order: int) -> dict:
    """``clean`` with the named channels (those present) low-passed at the clean rate."""
    out = dict(clean)
    if cutoff is None:
        return out
    fs = 1.0 / float(clean["t"][1] - clean["t"][0])
    for name in names:
        if clean.get(name) is not None:
            out[name] = imu_lowpass(np.asarray(clean[name], dtype=float), fs, cutoff, order)
    return out


def real_like_quarter_car(clean: dict, rng: np.random.Generator,
                          spec: QuarterCarArtifacts = QuarterCarArtifacts(),
                          noise_rng: np.random.Generator | None = None) -> RealExport:
    """A real-like CAN export of a clean quarter-car log.

    :param clean: arrays ``t`` (uniform, from 0) [s], ``T_b`` [N m], ``omega`` [rad/s], optional ``v`` [m/s] and
        ``a_x`` [m/s^2] (None or absent: not logged).
    :param rng: random generator (jitter, drops, outliers, epoch, decoy noise).
    :param spec: the artifacts.
    :param noise_rng: random generator of the wheel-speed noise (``spec.wheel_noise_std``; default ``rng``). A sensor
        sampled at an instant carries its own noise there: interpolating a noisy clean series instead would make the
        noise's variance swing between half and all of the sensor's, with a beat at the difference of the two rates,
        and correlate neighbouring samples (up to 0.5 near the clean rate).
    :return: a :class:`RealExport`; its map picks the rear-left wheel (non-driven, non-steered) among four.
    """
    t = np.asarray(clean["t"], dtype=float)
    filt = _filtered(clean, ("v", "a_x"), spec.imu_cutoff_hz, spec.imu_order)
    s, dropped = sample_instants(float(t[-1]), spec.rate_hz, spec.jitter, spec.drop_prob, rng)
    stamps, epoch0 = _epoch(s, rng)
    omega = sample_at(t, np.asarray(clean["omega"], dtype=float), s)
    if spec.wheel_noise_std is not None:
        omega = omega + (rng if noise_rng is None else noise_rng).normal(0.0, spec.wheel_noise_std, omega.size)
    rim_kmh = omega * spec.radius * KMH_PER_MS
    rim_kmh, outlier_rows = add_outliers(rim_kmh, spec.outliers, spec.outlier_kmh, rng)
    if spec.wheel_quantum_kmh is not None:
        rim_kmh = quantise(rim_kmh, spec.wheel_quantum_kmh)
    torque = sample_at(t, np.asarray(clean["T_b"], dtype=float), s, hold=True)
    cols: dict[str, np.ndarray] = {
        "timestamp": stamps,
        "wheel_fl(kmph)": rim_kmh * 1.03 + rng.normal(0.0, 0.3, len(s)),  # decoys: a driven, a steered wheel
        "p_brake_rl[kPa]": torque / spec.pressure_factor / PA_PER_KPA,
        "wheel_rl(kmph)": rim_kmh,
        "wheel_rr(kmph)": rim_kmh * 0.99 + rng.normal(0.0, 0.3, len(s)),
        "steer_angle[deg]": rng.normal(0.0, 0.5, len(s)),
    }
    channels = {
        "t": {"column": "timestamp", "unit": "epoch_s"},
        "T_b": {"column": "p_brake_rl", "unit": "kPa", "factor": spec.pressure_factor},
        "omega": {"column": "wheel_rl", "unit": "km/h", "radius": spec.radius},
    }
    if filt.get("v") is not None:
        v_s = s if spec.v_rate_hz is None else _slow_instants(s, spec.v_rate_hz)
        cols["speed (km/h)"] = sample_at(t, filt["v"], v_s) * KMH_PER_MS
        channels["v"] = {"column": "speed", "unit": "km/h"}
        channels["v"].update(_stated(spec))
    if filt.get("a_x") is not None:
        cols["ax[g]"] = sample_at(t, filt["a_x"], s) / STANDARD_GRAVITY
        channels["a_x"] = {"column": "ax", "unit": "g"}
        channels["a_x"].update(_stated(spec))
    truth = {"spec": asdict(spec), "dropped_rows": dropped.tolist(), "outlier_rows": outlier_rows.tolist(),
             "epoch0": epoch0, "instants": s}
    return RealExport(cols, {"plant": "quarter-car", "channels": channels}, truth,
                      comments=("CAN export, logger v2.1", f"vehicle start {epoch0:.3f}"))


def _stated(spec: QuarterCarArtifacts) -> dict:
    """The map entry's ``filter`` when the export states its IMU filter (the order and cut-off it applied)."""
    if not spec.state_filter or spec.imu_cutoff_hz is None:
        return {}
    return {"filter": {"order": spec.imu_order, "cutoff_hz": spec.imu_cutoff_hz}}


def _slow_instants(s: np.ndarray, rate_hz: float) -> np.ndarray:
    """For each logger instant, the last update instant of a channel refreshed at ``rate_hz`` (held between)."""
    return np.floor(s * rate_hz + ZOH_EPS) / rate_hz


# ----------------------------------------------------------------------------------------------------- payload
def _glitched(pose: np.ndarray, s: np.ndarray, spec: PayloadArtifacts, offset: float,
              rng: np.random.Generator) -> tuple[np.ndarray, list[int]]:
    """``pose`` (held camera samples) with ``spec.glitches`` camera frames moved by ``glitch_m``; the frames'
    indices are returned."""
    frame = np.floor((s - offset) * spec.camera_hz + ZOH_EPS).astype(int)
    frames = np.unique(frame)
    inner = frames[2:-2]
    chosen = rng.choice(inner, size=min(spec.glitches, len(inner)), replace=False) if len(inner) else []
    out = pose.copy()
    for f in chosen:
        out[frame == f] += rng.choice([-1.0, 1.0]) * spec.glitch_m
    return out, sorted(int(f) for f in chosen)


def real_like_payload(clean: dict, rng: np.random.Generator,
                      spec: PayloadArtifacts = PayloadArtifacts()) -> RealExport:
    """A real-like rig export of a clean payload log.

    :param clean: arrays ``t`` (uniform, from 0) [s], ``M`` [N m], ``f_x``, ``f_y`` [N], ``theta`` [rad],
        ``X``, ``Y`` [m].
    :param rng: random generator.
    :param spec: the artifacts.
    :return: a :class:`RealExport` with the pose in deg and mm, the time in epoch milliseconds.
    """
    t = np.asarray(clean["t"], dtype=float)
    filt = _filtered(clean, ("M", "f_x", "f_y"), spec.ft_cutoff_hz, spec.ft_order)
    s, dropped = sample_instants(float(t[-1]), spec.rate_hz, spec.jitter, spec.drop_prob, rng)
    stamps, epoch0 = _epoch(s, rng)
    offset = float(rng.uniform(0.0, 1.0 / spec.camera_hz))
    pose = {name: held_camera(t, np.asarray(clean[name], dtype=float), s, spec.camera_hz, offset)
            for name in ("theta", "X", "Y")}
    glitch_axis = ("X", "Y")[int(rng.integers(2))]
    pose[glitch_axis], glitch_frames = _glitched(pose[glitch_axis], s, spec, offset, rng)
    cols = {
        "time_ms": stamps * 1000.0,
        "Fx [N]": sample_at(t, filt["f_x"], s),
        "Fy [N]": sample_at(t, filt["f_y"], s),
        "Mz [N m]": sample_at(t, filt["M"], s),
        "cam_yaw(deg)": np.degrees(pose["theta"]),
        "cam_x(mm)": pose["X"] * MM_PER_M,
        "cam_y(mm)": pose["Y"] * MM_PER_M,
    }
    channels = {
        "t": {"column": "time_ms", "unit": "epoch_ms"},
        "M": {"column": "Mz", "unit": "N m"},
        "f_x": {"column": "Fx", "unit": "N"},
        "f_y": {"column": "Fy", "unit": "N"},
        "theta": {"column": "cam_yaw", "unit": "deg"},
        "X": {"column": "cam_x", "unit": "mm"},
        "Y": {"column": "cam_y", "unit": "mm"},
    }
    truth = {"spec": asdict(spec), "dropped_rows": dropped.tolist(), "glitch_axis": glitch_axis,
             "glitch_frames": glitch_frames, "camera_offset": offset, "epoch0": epoch0, "instants": s}
    return RealExport(cols, {"plant": "payload", "channels": channels}, truth, comments=("rig acquisition",))


# ----------------------------------------------------------------------------------------------------- files
def write_export(stem: str | os.PathLike, export: RealExport) -> tuple[str, str]:
    """Write ``STEM.csv`` (the export: ``#`` comments, header, rows) and ``STEM.map.json`` (its column map).

    :return: the two paths.
    """
    csv_path, map_path = f"{os.fspath(stem)}.csv", f"{os.fspath(stem)}.map.json"
    names = list(export.columns)
    with open(csv_path, "w") as fh:
        fh.writelines(f"# {c}\n" for c in export.comments)
        fh.write(",".join(names) + "\n")
        # 16 significant digits: an epoch stamp in seconds keeps microseconds
        fh.writelines(",".join(f"{x:.16g}" for x in row) + "\n" for row in zip(*export.columns.values()))
    with open(map_path, "w") as fh:
        json.dump(export.column_map, fh, indent=2)
    return csv_path, map_path
