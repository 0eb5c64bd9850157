"""An independent quarter-car braking simulator and log writer, for judging the gap tool.

This module re-implements the braking physics ON PURPOSE (the one deliberate exception to "one piece of code per
idea"): it shares no code and no discretisation with :mod:`fricenv.plants`, :mod:`fricenv.effects` or
:mod:`fricenv.gap`, so that logs drawn from it measure the diagnosis on a source it has never seen. It is written from
the papers' equations and the contracts (docs/contracts.md) only:

- plant 1 (Sui & Johansen, eq. (1)): ``m v' = -F_x``, ``J w' = r F_x - T_b sign(w)``, ``F_x = F_z mu(lambda)``,
  Magic Formula eq. (2) ``mu = theta sin(C atan(B l - E (B l - atan(B l))))``, slip eq. (3) ``l = (v - w r) / v``;
- integrated by fixed-step classical RK4 (``H_STEP`` = 0.25 ms, i.e. 40 steps per 10 ms sample; the fastest wheel
  mode ``r^2 F_z mu'(l) / (J v)`` is about 2.9e3 1/s at the 3 m/s stop speed on a stiff wet road, so
  ``h * rate`` < 0.9, inside RK4's real-axis stability limit 2.79), with a wheel-lock treatment: ``omega`` is
  clamped at 0, and a locked wheel stays locked while the brake torque exceeds the tire torque ``r F_x``;
- the library's effects with their contract names and parameters, and two physically real effects outside the
  library (road-induced vertical-load oscillation, temperature brake fade);
- three drivers unlike the stand-in's: a human pedal press, a classic wheel-deceleration-threshold ABS working on the
  noisy measured wheel speed, and a sinusoidally modulated torque;
- a CSV writer following the log contract of docs/contracts.md directly (not through :mod:`fricenv.logs`).

The physics (constants, model, RK4, drivers) lives in :mod:`validation.independent_model`; every name is re-exported here.

Measurement command (imports the diagnosis only there)::

    python -m validation.independent_sim --n 45 --seed 7 --jobs 2 [--json P] [--real] [--combos] [--omega-only]

``--real`` writes each log through :mod:`validation.real_artifacts` (a real-like export with its column map, converted by
``fricenv gap convert``); ``--combos`` puts several effects in each log.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from validation import report_check
from validation.independent_model import (  # the physics; re-exported: tests and worker processes use these names
    AX_NOISE_RANGE,
    CATEGORIES,
    COLUMN_PROBS,
    COLUMN_SETS,
    DRIVERS,
    DT,
    EFFECT_PARAMS,
    FADE_COOLING_TIME,
    FADE_DROP_RANGE,
    FADE_HEAT_CAPACITY,
    FREE_ROLL_RANGE,
    H_STEP,
    LIBRARY_EFFECTS,
    MAX_DURATION,
    NEUTRAL_COMMENT,
    NONE,
    OMEGA_NOISE_VAR,
    OUT,
    OUT_OF_LIBRARY_EFFECTS,
    ROAD_JITTER_B,
    ROAD_JITTER_THETA,
    ROADS,
    V0_RANGE,
    V_NOISE_RANGE,
    V_STOP,
    VEHICLE,
    ZOH_EPS,
    BoschABS,
    Effect,
    G,
    Road,
    Vehicle,
    _pedal_torque,
    _sine_torque,
    initial_state,
    integrate,
    make_model,
    stopping_distance,
)
from validation.measure_cli import measurement_parser, pool_map
from validation.quarter_car_oracle import effect_oracle, true_model_oracle
from validation.real_artifacts import QuarterCarArtifacts, real_like_quarter_car, write_export
from validation.true_noise import real_like_noise, white_noise

__all__ = ["CATEGORIES", "DRIVERS", "EFFECT_PARAMS", "H_STEP", "LIBRARY_EFFECTS", "OUT_OF_LIBRARY_EFFECTS", "ROADS",
           "V_STOP", "Effect", "G", "IndependentCase", "Road", "Vehicle", "case_noise", "draw_independent_case",
           "initial_state", "integrate", "make_model", "measure", "simulate_case", "stopping_distance", "study_case",
           "study_log",
           "write_independent_log", "write_real_log"]


# ----------------------------------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class IndependentCase:
    """One log's recipe: truth and the random settings of the log."""

    category: str  # effect name, "none" or "out_of_library"
    effects: tuple  # Effect specs switched on
    road: Road
    driver: str
    v0: float  # initial speed [m/s]
    free_roll: float  # free-rolling start [s]
    columns: tuple  # optional columns written, subset of ("v", "a_x")
    v_std: float  # reference-speed noise std [m/s]
    a_x_std: float  # accelerometer noise std [m/s^2]
    seed: int  # seed of driver and noise
    real: dict | None = None  # with --real: validation.real_artifacts.QuarterCarArtifacts settings of the export

    def truth(self) -> dict:
        """The truth in plain types: effect name, params, road, driver."""
        return {"category": self.category, "effect": self.effects[0].name if self.effects else "none",
                "params": dict(self.effects[0].params) if self.effects else {},
                "effects": [{"name": e.name, "params": dict(e.params)} for e in self.effects],
                "road": {"B": self.road.B, "C": self.road.C, "E": self.road.E, "theta": self.road.theta,
                         "preset": self.road.name},
                "driver": self.driver, "v0": self.v0, "columns": list(self.columns), "seed": self.seed,
                "real": self.real}


def random_road(rng: np.random.Generator) -> Road:
    """A road preset with B and theta perturbed (+-15 % / +-10 %), C and E as the preset."""
    base = ROADS[list(ROADS)[int(rng.integers(len(ROADS)))]]
    return Road(B=base.B * (1 + ROAD_JITTER_B * rng.uniform(-1, 1)), C=base.C, E=base.E,
                theta=base.theta * (1 + ROAD_JITTER_THETA * rng.uniform(-1, 1)), name=base.name)


def _fade_effect(v0: float, rng: np.random.Generator, veh: Vehicle) -> Effect:
    """Fade sized so that the applied torque falls by 10-30 % over a full stop from v0 (all kinetic energy into
    the brake, little cooled in 5 s)."""
    drop = rng.uniform(*FADE_DROP_RANGE)
    heat = 0.5 * veh.m * (v0**2 - V_STOP**2)  # [J]
    temp_rise = heat / FADE_HEAT_CAPACITY
    return Effect("brake_fade", {"fade_per_kelvin": drop / temp_rise, "heat_capacity": FADE_HEAT_CAPACITY,
                                 "cooling": FADE_HEAT_CAPACITY / FADE_COOLING_TIME})


def random_effect(category: str, road: Road, v0: float, rng: np.random.Generator, veh: Vehicle = VEHICLE) -> Effect:
    """A library or out-of-library effect at a realistic size."""
    u = rng.uniform
    if category == "brake_lag":
        return Effect(category, {"tau": u(0.02, 0.08)})
    if category == "brake_delay":
        return Effect(category, {"delay": u(0.015, 0.06)})
    if category == "brake_gain":
        return Effect(category, {"gain": u(0.75, 0.88) if rng.random() < 0.5 else u(1.12, 1.3)})
    if category == "relaxation_length":
        return Effect(category, {"sigma": u(0.2, 0.6)})
    if category == "radius_error":
        return Effect(category, {"r_eff": veh.r * (1 + rng.choice([-1.0, 1.0]) * u(0.02, 0.05))})
    if category == "mu_change":
        up = road.theta < 0.85 and rng.random() < 0.5
        return Effect(category, {"t_change": u(1.0, 2.2),
                                 "theta_after": road.theta * (u(1.2, 1.4) if up else u(0.55, 0.8))})
    if category == "drag":
        return Effect(category, {"c0": u(100.0, 300.0), "c2": u(0.2, 0.6)})
    if category == OUT:
        if rng.random() < 0.5:
            return Effect("load_oscillation", {"amplitude": u(0.1, 0.25), "freq": u(8.0, 15.0),
                                               "phase": u(0, 2 * np.pi)})
        return _fade_effect(v0, rng, veh)
    raise ValueError(f"unknown category {category!r}; valid: {', '.join(CATEGORIES)}")


def draw_independent_case(category: str, rng: np.random.Generator, driver: str | None = None,
                          road: Road | None = None, effects: Sequence[Effect] | None = None) -> IndependentCase:
    """A random case of the given category.

    :param category: one of :data:`CATEGORIES`.
    :param rng: random generator.
    :param driver: force a driver (default: random of :data:`DRIVERS`).
    :param road: force a road (default: a perturbed preset).
    :param effects: force the effects (default: one random effect of the category).
    :return: the case.
    """
    if category not in CATEGORIES:
        raise ValueError(f"unknown category {category!r}; valid: {', '.join(CATEGORIES)}")
    if driver is not None and driver not in DRIVERS:
        raise ValueError(f"unknown driver {driver!r}; valid: {', '.join(DRIVERS)}")
    road = road or random_road(rng)
    v0 = float(rng.uniform(*V0_RANGE))
    if effects is None:
        effects = () if category == NONE else (random_effect(category, road, v0, rng),)
    driver = driver or DRIVERS[int(rng.integers(len(DRIVERS)))]
    columns = COLUMN_SETS[int(rng.choice(len(COLUMN_SETS), p=COLUMN_PROBS))]
    return IndependentCase(category, tuple(effects), road, driver, v0, float(rng.uniform(*FREE_ROLL_RANGE)),
                           columns, float(rng.uniform(*V_NOISE_RANGE)), float(rng.uniform(*AX_NOISE_RANGE)),
                           int(rng.integers(2**31)))


def simulate_case(case: IndependentCase, veh: Vehicle = VEHICLE) -> dict:
    """Run a case: returns arrays t, T_b, omega, v, a_x (measured), v_true, omega_true, a_x_true, T_applied."""
    rng = np.random.default_rng(case.seed)
    n = round(MAX_DURATION / DT)
    free = round(case.free_roll / DT)
    t_peak = veh.r * veh.Fz * case.road.mu_max
    cmd_hist = np.zeros(n)
    if case.driver == "pedal":
        plan, ctrl = _pedal_torque(t_peak, n, free, rng), None
    elif case.driver == "sine":
        plan, ctrl = _sine_torque(t_peak, n, free, rng), None
    elif case.driver == "bosch-abs":
        plan, ctrl = None, BoschABS(t_peak, free, veh, rng)
    else:
        raise ValueError(f"unknown driver {case.driver!r}; valid: {', '.join(DRIVERS)}")

    current = [0]  # the sample being integrated: the command is causal, no lookup beyond it

    def cmd(t: float) -> float:  # zero-order hold of the logged command
        j = min(math.floor(t / DT + ZOH_EPS), current[0])  # RK4's last stage sits on t_{k+1}: still cmd_k
        return float(cmd_hist[j]) if j >= 0 else 0.0

    model = make_model(case.road, case.effects, cmd, veh)
    x = initial_state(model, case.v0)
    w_std = math.sqrt(OMEGA_NOISE_VAR)
    rec = {k: [] for k in ("t", "T_b", "omega", "v", "a_x", "v_true", "omega_true", "a_x_true", "T_applied")}
    for k in range(n):
        t = k * DT
        if x[0] < V_STOP:
            break
        om = x[1] + w_std * rng.standard_normal()
        v_m = x[0] + case.v_std * rng.standard_normal()
        ax_true = model.accel(t, x)
        ax = ax_true + case.a_x_std * rng.standard_normal()
        cmd_hist[k] = ctrl(k, om) if ctrl is not None else plan[k]
        current[0] = k
        rec["t"].append(t)
        rec["T_b"].append(cmd_hist[k])
        rec["omega"].append(om)
        rec["v"].append(v_m)
        rec["a_x"].append(ax)
        rec["v_true"].append(x[0])
        rec["omega_true"].append(x[1])
        rec["a_x_true"].append(ax_true)
        rec["T_applied"].append(model.applied(t, x))
        x = integrate(model, x, t, t + DT)
    return {k: np.asarray(v, dtype=float) for k, v in rec.items()}


STUDY_STREAM = 39  # the estimator studies' random stream beside the seed: their cases apart from the suites' draws


def study_case(driver: str, road: str, seed: int) -> IndependentCase:
    """The nominal case the estimator studies (:mod:`validation.estimator_mismatch`, :mod:`validation.estimator_spikes`)
    take for a driver, a preset road and a seed: initial speed, free roll and noise drawn from the seed."""
    return draw_independent_case(NONE, np.random.default_rng([seed, STUDY_STREAM]), driver=driver, road=ROADS[road])


def study_log(case: IndependentCase):
    """A case's measured log as the estimators read it (``t``, ``omega``, ``T_b``, ``a_x``) and its true speed."""
    sim = simulate_case(case)
    return SimpleNamespace(t=sim["t"], omega=sim["omega"], T_b=sim["T_b"], a_x=sim["a_x"]), sim["v_true"]


def case_noise(case: IndependentCase) -> dict[str, float]:
    """The noise levels the case's log carries, per logged channel (:mod:`validation.true_noise`): the white noise
    the simulator draws, or with ``case.real`` that noise through the export's chain."""
    stds = {"omega": math.sqrt(OMEGA_NOISE_VAR), "v": case.v_std, "a_x": case.a_x_std}
    channels = ("omega",) + tuple(case.columns)
    if case.real is None:
        return white_noise(stds, channels)
    return real_like_noise(QuarterCarArtifacts(**case.real), stds, case.columns, DT)


def write_csv(path: str | os.PathLike, cols: dict, columns: Sequence[str]) -> None:
    """Write the contract log: a neutral comment, header ``t,T_b,omega[,v][,a_x]``, rows (atomic rename)."""
    names = ["t", "T_b", "omega"] + [c for c in ("v", "a_x") if c in columns]
    tmp = f"{path}.tmp"
    with open(tmp, "w") as fh:
        fh.write(f"# {NEUTRAL_COMMENT}\n")
        fh.write(",".join(names) + "\n")
        fh.writelines(",".join(f"{x:.9g}" for x in row) + "\n" for row in zip(*(cols[c] for c in names)))
    os.replace(tmp, path)


def write_independent_log(path: str | os.PathLike, case: IndependentCase) -> dict:
    """Simulate ``case`` and write its log to ``path``; returns the truth (effect, params, road, driver, ...)."""
    sim = simulate_case(case)
    write_csv(path, sim, case.columns)
    truth = case.truth()
    truth["samples"] = len(sim["t"])
    return truth


def real_export(case: IndependentCase):
    """Simulate ``case`` and pass it through a logger's artifacts (validation/real_artifacts.py, settings ``case.real``):
    a :class:`validation.real_artifacts.RealExport`, whose ``truth`` says where the artifacts went."""
    sim = simulate_case(case)
    spec = QuarterCarArtifacts(**case.real)
    # by default the logger interpolates the simulated 100 Hz measurement, noise and all (an export resampled from
    # the bus); with ``wheel_noise_std`` the wheel speed is sampled noise-free and gets the sensor's own noise at each
    # logged sample. v and a_x keep theirs either way, smoothed by the IMU filter at the clean rate.
    omega = sim["omega"] if spec.wheel_noise_std is None else sim["omega_true"]
    clean = {"t": sim["t"], "T_b": sim["T_b"], "omega": omega,
             "v": sim["v"] if "v" in case.columns else None, "a_x": sim["a_x"] if "a_x" in case.columns else None}
    return real_like_quarter_car(clean, np.random.default_rng(case.seed + 1), spec,
                                 noise_rng=np.random.default_rng(case.seed + 2))


def real_truth_rows(case: IndependentCase, n: int, dt: float) -> dict:
    """The simulator's noise-free truth (``omega_true``, ``v_true``, ``a_x_true``, unfiltered: the physical states
    the diagnosis' model predicts, against which it realigns a filtered channel) on the ``n`` rows of step ``dt`` of
    the case's real-like log after resampling (its first row is the export's first instant, the simulation's 0)."""
    sim = simulate_case(case)
    t = np.arange(n) * dt
    return {"t": t, **{k: np.interp(t, sim["t"], sim[k]) for k in ("omega_true", "v_true", "a_x_true")}}


def write_real_log(stem: str | os.PathLike, case: IndependentCase) -> tuple[str, str, dict]:
    """Simulate ``case`` and write it as a real-like export with its column map (validation/real_artifacts.py, settings
    ``case.real``): ``STEM.csv`` and ``STEM.map.json``. Returns the two paths and the truth."""
    export = real_export(case)
    csv_path, map_path = write_export(stem, export)
    truth = case.truth()
    truth["samples"] = len(export.columns["timestamp"])
    return csv_path, map_path, truth


# ----------------------------------------------------------------------------------------------------- measurement
EXPECTED = {NONE: "none", OUT: "unexplained"}
# Several effects at once (--combos): the first is the expected verdict, all should be named in "effects".
COMBOS = (("drag", "relaxation_length"), ("brake_gain", "radius_error", "drag"), ("brake_gain", "drag"),
          ("radius_error", "relaxation_length"), ("brake_gain", "relaxation_length"))
REAL_RATES = (25.0, 100.0)  # range of the real-like logger rate [Hz]
# Command-line switches of the real-like export: flag -> (QuarterCarArtifacts settings, help)
ARTIFACT_OPTIONS = {
    "white-wheel-noise": ({"wheel_noise_std": math.sqrt(OMEGA_NOISE_VAR)},
                          ("the wheel speed carries the sensor's white noise drawn at each logged sample instead of "
                          "the simulated 100 Hz measurement interpolated at the logger's instants")),
    "stated-filter": ({"state_filter": True},
                      ("the column map states the IMU filter on v and a_x (order and cut-off, as a data sheet gives "
                      "them) instead of leaving the diagnosis to read it from the noise")),
}


def _diagnosable_log(tmp: str, case: IndependentCase) -> tuple[str, dict]:
    """Write the case's log in ``tmp``: the contract CSV, or with ``case.real`` the export converted through its
    map by ``fricenv gap convert`` (as ``fricenv gap diagnose --map`` does)."""
    if case.real is None:
        path = os.path.join(tmp, "log.csv")
        return path, write_independent_log(path, case)
    from fricenv.commands.gap_convert import convert

    csv_path, map_path, truth = write_real_log(os.path.join(tmp, "export"), case)
    path = os.path.join(tmp, "log.contract.csv")
    convert(csv_path, map_path, "quarter-car", path)
    return path, truth


def _named_effects(dg) -> list[str]:
    """The effects a diagnosis names: its selected set if it has one, else its verdict."""
    found = getattr(dg, "effects", None)
    if not found:
        return [dg.verdict]
    return [e["effect"] if isinstance(e, dict) else getattr(e, "effect", str(e)) for e in found]


def diagnose_case(case: IndependentCase) -> dict:
    """Write the case's log to a temporary directory and diagnose it blind; returns a result row."""
    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose_file

    expected = EXPECTED.get(case.category, case.category)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                path, truth = _diagnosable_log(tmp, case)
                dg = diagnose_file(path, cfg=DiagnoseConfig(jobs=1))
        except Exception as exc:  # noqa: BLE001 -- a log the reader or the tool rejects (or crashes on) counts as wrong
            return {"category": case.category, "truth": case.truth(), "verdict": "error",
                    "error": f"{type(exc).__name__}: {exc}", "expected": expected, "right": False, "gap_before": float("nan"), "gap_after": float("nan"),
                    "params": {}, "seconds": time.perf_counter() - t0}
    out = {"category": case.category, "truth": truth, "true_params": truth["params"], "driver": case.driver,
           "road": truth["road"], "columns": list(case.columns), "verdict": dg.verdict, "expected": expected,
           "right": dg.verdict == expected, "gap_before": float(dg.gap_before), "gap_after": float(dg.gap_after),
           "params": dict(dg.params), "seconds": time.perf_counter() - t0, "samples": truth["samples"],
           "candidates": [c.effect for c in dg.candidates[:3]], "named": _named_effects(dg),
           "not_testable": sorted(dg.where.get("not_testable", {})),
           "robust_gap_before": float(dg.where.get("robust_gap_before", float("nan"))),
           "tests": {e: {"z_paired": float(t["z_paired"]), "z_without_effect": t.get("z_without_effect"),
                         "robust_gap": float(t["robust_gap"]), "significant": bool(t["significant"])}
                     for e, t in dg.where.get("tests", {}).items()},
           "sensors": report_check.sensor_flags(dg), "periodic": dg.where.get("periodic"),
           "guard": dg.where.get("false_discovery_guard"), "told_apart": dg.where.get("told_apart"),
           "true_noise": case_noise(case)}
    out["right_or_untestable"] = right_or_untestable(out)
    _selection_figures(out, case, dg)
    if case.category in LIBRARY_EFFECTS:
        _effect_figures(out, case, dg)
    elif case.category == OUT:  # the noise-free truth, on the log's own samples
        truth_rows = simulate_case(case) if case.real is None else real_truth_rows(case, dg.data.n, dg.data.dt)
        try:
            out["truth_shown"] = report_check.truth_shown(truth_rows, dg, DiagnoseConfig(jobs=1), out["true_noise"])
        except ValueError as exc:  # the export's rows and the log's differ: no oracle, the log counts as shown
            out["truth_error"] = str(exc)
    return out


def _selection_figures(out: dict, case: IndependentCase, dg) -> None:
    """What the forward selection made of the log: the effects it added after the verdict that are not in the log
    (``extra_named``; a wrong verdict is counted by the confusion matrix, not here), the effects it reported as
    confounded (``confounded``: each with those it is confounded with), and on a log with several effects whether
    all are named (``all_named``), all named or listed as not testable (``named_or_untestable``), each named true
    effect's parameter error."""
    from fricenv.gap.quarter_car.validate import main_error

    true = {e.name: dict(e.params) for e in case.effects}
    out["extra_named"] = [e for e in out["named"][1:] if e not in true]
    out["confounded"] = [[s["effect"], *s["confounded_with"]] for s in dg.where.get("forward_selection", [])
                         if s.get("confounded_with")]
    if len(case.effects) < 2:
        return
    out["all_named"] = set(true) <= set(out["named"])
    out["named_or_untestable"] = set(true) <= set(out["named"]) | set(out["not_testable"])
    fitted = {e["effect"]: e["params"] for e in dg.effects}
    out["effect_errors"] = {e: main_error(e, true[e], fitted[e])[0] for e in true if e in fitted}


def right_or_untestable(row: dict) -> bool:
    """A right verdict, or ``none`` on a log whose report lists the true effect as not testable (``none``
    then says "none of the testable effects", which is right; ``none`` where the effect was testable is wrong)."""
    return bool(row["right"]) or (row["verdict"] == "none" and row["expected"] in row.get("not_testable", ()))


def _effect_figures(out: dict, case: IndependentCase, dg) -> None:
    """Gap ratio, detectability (on a log with several effects, also which of them the data show: ``shown``) and
    (if right) parameter error of an effect log's result row."""
    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig
    from fricenv.gap.quarter_car.validate import main_error

    truth = out["truth"]
    out["ratio"] = out["gap_after"] / out["gap_before"] if out["gap_before"] > 0 else float("nan")
    # the tool's own model class with the true values and the true noise: "could any tool see it in these data"
    cfg = DiagnoseConfig(jobs=1)
    oracle = effect_oracle if len(case.effects) < 2 else true_model_oracle
    out.update(oracle({case.category: truth["params"]}, truth["road"], dg, cfg, out["true_noise"]))
    if len(case.effects) < 2:
        out["size_ratio"] = report_check.size_ratio(case.category, truth, dg)
    else:
        shown = report_check.shown_effects({e.name: dict(e.params) for e in case.effects}, truth["road"], dg, cfg,
                                           out["true_noise"])
        out["truth_effects"], out["shown"] = [e.name for e in case.effects], [e for e, yes in shown.items() if yes]
    if out["right"]:
        out["param_error"], out["param_errors"] = main_error(case.category, truth["params"], out["params"])


def draw_cases(n: int, seed: int, real: bool = False, combos: bool = False,
               columns: tuple | None = None, artifacts: dict | None = None) -> list[IndependentCase]:
    """``n`` cases, categories in turn, shuffled.

    :param columns: force the optional columns of every log (``()``: ``t, T_b, omega`` only); the cases are
        otherwise those of the plain draw.
    :param real: write each log as a real-like export (settings drawn from a second generator, so the cases
        themselves are those of the plain draw).
    :param combos: every case carries one of :data:`COMBOS` (several effects at once) instead of one category.
    :param artifacts: with ``real``, settings of :class:`validation.real_artifacts.QuarterCarArtifacts` for every export
        (:data:`ARTIFACT_OPTIONS`: the sensor's white wheel-speed noise, the IMU filter stated in the map).
    """
    rng = np.random.default_rng(seed)
    if combos:
        sets = [COMBOS[i % len(COMBOS)] for i in range(n)]
        rng.shuffle(sets)
        cases = []
        for names in sets:
            road, v0 = random_road(rng), float(rng.uniform(*V0_RANGE))
            effects = tuple(random_effect(name, road, v0, rng) for name in names)
            cases.append(draw_independent_case(names[0], rng, road=road, effects=effects))
    else:
        cats = [CATEGORIES[i % len(CATEGORIES)] for i in range(n)]
        rng.shuffle(cats)
        cases = [draw_independent_case(c, rng) for c in cats]
    if columns is not None:
        cases = [dataclasses.replace(c, columns=tuple(columns)) for c in cases]
    if not real:
        return cases
    rng_real = np.random.default_rng([seed, 15])
    return [dataclasses.replace(c, real={**_real_settings(rng_real), **(artifacts or {})}) for c in cases]


def _real_settings(rng: np.random.Generator) -> dict:
    """Random settings of a real-like export: logger rate 25-100 Hz, the other artifacts at their defaults."""
    return {"rate_hz": float(rng.uniform(*REAL_RATES))}


def measure(n: int, seed: int, jobs: int = 1, real: bool = False, combos: bool = False,
            columns: tuple | None = None, artifacts: dict | None = None) -> dict:
    """Draw ``n`` independent logs, diagnose each blind, and summarise (fricenv.gap.quarter_car.validate's summary format;
    with ``combos`` also the share of logs whose every effect is named)."""
    from fricenv.gap.quarter_car.validate import summarize

    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    if artifacts and not real:
        raise ValueError("artifacts apply to real-like exports only: pass real=True (--real)")
    cases = draw_cases(n, seed, real, combos, columns, artifacts)
    t0 = time.perf_counter()
    results = pool_map(diagnose_case, cases, jobs)
    s = summarize(results)
    s.update(n=n, seed=seed, jobs=jobs, wall_seconds=time.perf_counter() - t0, source="validation.independent_sim",
             real=real, combos=combos, columns=None if columns is None else list(columns),
             artifacts=artifacts or {})
    s["right_or_untestable"] = float(np.mean([r.get("right_or_untestable", False) for r in results]))
    s["extra_effect_share"] = float(np.mean([bool(r.get("extra_named")) for r in results]))
    s["power"], s["sensors"] = report_check.power_summary(results), report_check.sensor_summary(results)
    s["misses"], s["out_of_library"] = report_check.miss_kinds(results), report_check.truth_summary(results)
    if combos:
        errs = [v for r in results for v in r.get("effect_errors", {}).values()]
        s.update(all_effects_named=float(np.mean([r.get("all_named", False) for r in results])),
                 named_or_untestable=float(np.mean([r.get("named_or_untestable", False) for r in results])),
                 named_effect_params_within_15pct=float(np.mean(np.array(errs) <= 0.15)) if errs else float("nan"),
                 combos=report_check.combo_summary(results))
    return s


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m validation.independent_sim --n 45 --seed 7 --jobs 2 [--json P]``."""
    ap = measurement_parser("Measure the gap diagnosis on logs of an independent simulator.", n=45, seed=7)
    ap.add_argument("--real", action="store_true",
                    help="write each log as a real-like export (validation/real_artifacts.py: 25-100 Hz, jittered epoch "
                         "stamps, km/h and kPa with a map, filtered a_x and v, quantised wheel speed, outliers) and "
                         "diagnose it through its map")
    ap.add_argument("--omega-only", action="store_true",
                    help="write t, T_b and omega only (no v, no a_x) in every log")
    ap.add_argument("--combos", action="store_true",
                    help="several effects per log (COMBOS); reports the share with every effect named")
    for flag, (_, text) in ARTIFACT_OPTIONS.items():
        ap.add_argument(f"--{flag}", action="store_true", help=f"with --real: {text}")
    args = ap.parse_args(argv)
    artifacts = {k: v for flag, (setting, _) in ARTIFACT_OPTIONS.items() if getattr(args, flag.replace("-", "_"))
                 for k, v in setting.items()}
    if artifacts and not args.real:
        ap.error(f"--{', --'.join(ARTIFACT_OPTIONS)} need --real")
    from fricenv.gap.quarter_car.validate import format_summary
    from fricenv.utils import write_json
    from validation import independent_sim as mod  # noqa: PLW0406 -- by its import name, so that the worker processes can unpickle

    s = mod.measure(args.n, args.seed, args.jobs, args.real, args.combos, () if args.omega_only else None,
                    artifacts)
    print(report_check.format_rows(s["logs"]))
    print(format_summary(s))
    print(f"right or untestable (none where the report lists the true effect as not testable): "
          f"{s['right_or_untestable']:.0%} of {args.n} logs")
    print(report_check.format_power(s["power"]))
    print(report_check.format_sensors(s["sensors"]))
    print("wrong verdicts on library-effect logs, by kind: " + ", ".join(f"{k} {v}" for k, v in s["misses"].items()))
    if s["out_of_library"]["logs"]:
        print(report_check.format_truth(s["out_of_library"]))
    print(f"logs where the forward selection added an effect that is not in them: {s['extra_effect_share']:.0%}")
    if args.combos:
        print(report_check.format_combos(s))
    print(f"wall time: {s['wall_seconds']:.0f} s on {args.jobs} process(es)")
    if args.json:
        write_json(args.json, s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
