"""The parts of ``fricenv demo`` past the classical ABS table: estimators in the loop, a diagnosed log, the corrected
simulator, and the page that links them.

- **Estimators in the loop.** The same slip controller fed by the true state (``slip-pi``), by the EKF/RLS and by
  the MHE (``pipeline:ekf-rls``, ``pipeline:mhe``), braking from :data:`V0` on dry and wet.
- **A hidden effect.** A log of the real stand-in (:mod:`fricenv.gap.quarter_car.simulate`) with a brake lag the
  diagnosis is not told of (its provenance comments are left out), diagnosed into ``OUT/diagnosis/``.
- **The corrected simulator.** ``Braking-v0`` with ``effects=OUT/diagnosis/report.json`` against the nominal env and
  the plant with the true effect: the stopping distance of the ABS controllers on each.
"""

from __future__ import annotations

from pathlib import Path

DIAGNOSIS_DIR = "diagnosis"
HIDDEN_LOG = "hidden_effect.csv"
HIDDEN_EFFECT = ("brake_lag", {"tau": 0.05})  # a slow brake actuator: real ones lag 20-80 ms
HIDDEN_ROAD = "wet"
HIDDEN_SEED = 11
LOOP_POLICIES = ("slip-pi", "pipeline:ekf-rls", "pipeline:mhe")
LOOP_ROADS = ("dry", "wet")
CORRECTED_CONTROLLERS = ("rule-abs", "slip-pi")
V0 = 20.0  # [m/s]
LOOP_PLOT = "estimators_in_the_loop.png"
CORRECTED_PLOT = "corrected_simulator.png"
INDEX = "index.md"


def estimators_in_the_loop(seed: int) -> list[dict]:
    """The slip controller on the true state and on each estimator's outputs: one row per (policy, road)."""
    from agents.evaluation import Scenario, run_episode
    from agents.policy_spec import parse_policy_spec
    from fricenv import progress

    rows = []
    with progress.task("estimators in the loop", total=len(LOOP_POLICIES) * len(LOOP_ROADS)) as advance:
        for name in LOOP_POLICIES:
            spec = parse_policy_spec(name)
            for road in LOOP_ROADS:
                r = run_episode(spec, Scenario(road, V0), seed)
                rows.append({"policy": spec.label, "road": road, **r})
                advance()
    return rows


def format_loop_table(rows: list[dict]) -> str:
    """The estimators-in-the-loop rows as a plain-text table."""
    lines = [f"{'policy':<22} {'road':<6} {'ratio':>7} {'|slip - slip*|':>15} {'locked':>7}"]
    lines += [f"{r['policy']:<22} {r['road']:<6} {r['ratio']:>7.3f} {r['slip_err']:>15.3f} "
              f"{('yes' if r['lock'] else 'no'):>7}" for r in rows]
    return "\n".join(lines)


def diagnose_hidden_effect(out: Path, jobs: int) -> dict:
    """Write a log with :data:`HIDDEN_EFFECT` (not named in the log), diagnose it blind, write its report.

    :return: ``{"log", "report", "truth", "verdict", "effects", "gap_before", "gap_after", "seconds"}``.
    """
    from fricenv.effects.quarter_car import make_effect
    from fricenv.gap.plants import get_plant
    from fricenv.gap.quarter_car.simulate import write_simulated_log
    from fricenv.plants.tire import get_road

    name, params = HIDDEN_EFFECT
    log = out / HIDDEN_LOG
    write_simulated_log(log, [make_effect(name, **params)], get_road(HIDDEN_ROAD), "abs", HIDDEN_SEED,
                        comments=False)
    plant = get_plant("quarter-car")
    dg = plant.diagnose_file(log, None, plant.make_config(None, jobs))
    report = plant.write_report(dg, out / DIAGNOSIS_DIR, True)
    return {"log": str(log), "report": str(out / DIAGNOSIS_DIR / "report.json"), "truth": {name: params},
            "verdict": report["verdict"], "effects": report["effects"], "gap_before": report["gap_before"],
            "gap_after": report["gap_after"], "seconds": dg.seconds}


def corrected_simulator(report: str, seed: int) -> tuple[list[dict], dict]:
    """Stopping distance of each ABS controller on the nominal env, the corrected env (the report's effects) and the
    plant with the true effect; (rows, {plant: {controller: Rollout}}) on :data:`HIDDEN_ROAD` from :data:`V0`."""
    from agents.controllers import make_controller, rollout
    from fricenv.envs.braking import BrakingEnv

    name, params = HIDDEN_EFFECT
    plants = {"nominal": None, "corrected": report, "true effect": [{"effect": name, "params": params}]}
    rows, traces = [], {}
    for plant, effects in plants.items():
        env = BrakingEnv(road=HIDDEN_ROAD, v0=V0, observation="oracle", effects=effects)
        traces[plant] = {}
        for ctl in CORRECTED_CONTROLLERS:
            ro = rollout(env, make_controller(ctl, env), seed=seed)
            traces[plant][ctl] = ro
            rows.append({"plant": plant, "controller": ctl, "distance_m": ro.info["stopping_distance"],
                         "ratio": ro.info["ratio"], "locked": ro.info["lock_seen"]})
        env.close()
    return rows, traces


def format_corrected_table(rows: list[dict]) -> str:
    """Stopping distances per controller: nominal, corrected and true plant side by side."""
    by = {(r["plant"], r["controller"]): r for r in rows}
    lines = [f"{'controller':<12} {'nominal [m]':>12} {'corrected [m]':>14} {'true effect [m]':>16}"]
    for ctl in CORRECTED_CONTROLLERS:
        d = [by[(p, ctl)]["distance_m"] for p in ("nominal", "corrected", "true effect")]
        lines.append(f"{ctl:<12} {d[0]:>12.2f} {d[1]:>14.2f} {d[2]:>16.2f}")
    return "\n".join(lines)


def plot_loop(rows: list[dict], path: Path) -> None:
    """Bar chart of the stopping-distance ratio per policy and road."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from fricenv.utils import save_figure

    fig = Figure(figsize=(7, 3.5), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    policies = list(dict.fromkeys(r["policy"] for r in rows))
    width = 0.8 / len(LOOP_ROADS)
    for j, road in enumerate(LOOP_ROADS):
        vals = [next(r["ratio"] for r in rows if r["policy"] == p and r["road"] == road) for p in policies]
        ax.bar([i + j * width for i in range(len(policies))], vals, width, label=road)
    ax.set_xticks([i + width * (len(LOOP_ROADS) - 1) / 2 for i in range(len(policies))])
    ax.set_xticklabels(policies, fontsize=8)
    ax.set_ylim(0.9, None)
    ax.set_ylabel("stopping distance / physical limit")
    ax.legend(fontsize=8)
    ax.set_title(f"slip controller on the true state and on estimates, from {V0:.0f} m/s")
    fig.tight_layout()
    save_figure(fig, path)


def plot_corrected(traces: dict, path: Path) -> None:
    """Speed against time of each controller on the nominal, corrected and true plant."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from fricenv.utils import save_figure

    fig = Figure(figsize=(8, 3.5 * len(CORRECTED_CONTROLLERS)), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(CORRECTED_CONTROLLERS), 1, sharex=True)
    for ax, ctl in zip(axes, CORRECTED_CONTROLLERS):
        for plant, styles in zip(traces, ("-", "--", ":")):
            ro = traces[plant][ctl]
            ax.plot(ro.t, ro.v, styles, label=f"{plant}: {ro.info['stopping_distance']:.1f} m")
        ax.set_ylabel(f"{ctl}\nspeed [m/s]")
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{HIDDEN_EFFECT[0]} found by the diagnosis, put into the simulator ({HIDDEN_ROAD})")
    fig.tight_layout()
    save_figure(fig, path)


def write_index(out: Path, sections: dict) -> Path:
    """``OUT/index.md``: each part's table and the plots and report it wrote."""
    diag = sections["diagnosis"]
    effects = ", ".join(f"{e['effect']} ({', '.join(f'{k}={v:.4g}' for k, v in e['params'].items())})"
                        for e in diag["effects"]) or diag["verdict"]
    truth = ", ".join(f"{k} ({', '.join(f'{p}={v:g}' for p, v in ps.items())})" for k, ps in diag["truth"].items())
    text = [
        "# fricenv demo", "",
        f"## Classical ABS, from {V0:.0f} m/s", "", "```", sections["abs_table"], "```", "",
        f"![traces]({sections['abs_plot']})", "",
        "## The same slip controller on estimates", "", "```", sections["loop_table"], "```", "",
        f"![estimators in the loop]({LOOP_PLOT})", "",
        "## A log with a hidden effect, diagnosed", "",
        f"- log: `{HIDDEN_LOG}` (true effect, not written in the log: {truth})",
        f"- verdict: **{effects}**; gap {diag['gap_before']:.3g} -> {diag['gap_after']:.3g} noise units (held out)",
        f"- report: [{DIAGNOSIS_DIR}/report.md]({DIAGNOSIS_DIR}/report.md)", "",
        "## The corrected simulator", "", "```", sections["corrected_table"], "```", "",
        f"![corrected simulator]({CORRECTED_PLOT})", "",
    ]
    path = out / INDEX
    from fricenv.utils import atomic_write

    with atomic_write(path) as fh:
        fh.write("\n".join(text))
    return path
