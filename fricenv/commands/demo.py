"""What fricenv does, in about a minute: classical ABS, estimators in the loop, a diagnosed log, the corrected simulator.

1. Brake from 20 m/s on dry, wet, snow and ice with every classical controller: per road and controller the
   stopping distance to v_stop = 2 m/s, the physical limit (v0^2 - v_stop^2) / (2 g mu_max), their ratio, and
   whether the wheel locked (omega r < 0.05 v for > 0.1 s); a PNG of speed, slip and torque on one road.
2. to 4. (:mod:`fricenv.commands.demo_story`, unless ``--quick``): the slip controller on the EKF/RLS's and the
   MHE's estimates against the true state; a log with a hidden effect diagnosed; that effect in the simulator.
   ``OUT/index.md`` links every table, plot and report.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fricenv.commands import demo_story as story
from fricenv.errors import InvalidInputError, user_input

DEFAULT_ROADS = ("dry", "wet", "snow", "ice")
DEFAULT_V0 = 20.0  # [m/s]
PLOT_FILE = "demo_{road}.png"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="runs/demo", help="output directory for the PNG (default: runs/demo)")
    parser.add_argument("--json", metavar="PATH", default=None, help="also write the results as JSON")
    parser.add_argument("--seed", type=int, default=0, help="reset seed of every episode (default: 0)")
    parser.add_argument("--v0", type=float, default=DEFAULT_V0, help="initial speed [m/s] (default: 20)")
    parser.add_argument("--roads", nargs="+", default=list(DEFAULT_ROADS),
                        help="roads to brake on: presets or scenarios like dry->ice (default: dry wet snow ice)")
    parser.add_argument("--plot-road", default="dry", help="road whose traces are plotted (default: dry)")
    parser.add_argument("--quick", action="store_true", help="the classical ABS table only (about 2 s)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes of the diagnosis (default: 2)")


def run_demo(roads, v0: float, seed: int) -> tuple[list[dict], dict]:
    """Every controller on every road: (result rows, {road: {controller: Rollout}})."""
    from agents.controllers import CONTROLLERS, make_controller, rollout
    from fricenv import progress
    from fricenv.envs.braking import BrakingEnv

    results, traces = [], {}
    with progress.task("demo episodes", total=len(roads) * len(CONTROLLERS)) as advance:
        for road in roads:
            env = BrakingEnv(road=road, v0=v0, observation="oracle")
            traces[road] = {}
            for name in CONTROLLERS:
                ro = rollout(env, make_controller(name, env), seed=seed)
                traces[road][name] = ro
                info = ro.info
                results.append({"road": road, "controller": name, "distance_m": info["stopping_distance"],
                                "limit_m": info["limit_distance"], "ratio": info["ratio"],
                                "locked": info["lock_seen"]})
                advance()
            env.close()
    return results, traces


def plot_traces(traces: dict, road: str, path: Path) -> None:
    """Speed, slip and torque against time for every controller on ``road``, saved as a PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from fricenv.utils import save_figure

    fig = Figure(figsize=(9, 8), dpi=100)
    FigureCanvasAgg(fig)
    ax_v, ax_s, ax_t = fig.subplots(3, 1, sharex=True)
    for name, ro in traces.items():
        (line,) = ax_v.plot(ro.t, ro.v, label=f"{name}: {ro.info['ratio']:.3f}x")
        ax_v.plot(ro.t, ro.wheel, color=line.get_color(), alpha=0.35, lw=0.8)
        ax_s.plot(ro.t, ro.slip, color=line.get_color(), lw=1.0)
        ax_t.plot(ro.t, ro.torque, color=line.get_color(), lw=1.0)
    ax_v.set_ylabel("speed [m/s]\n(thin: wheel omega r)")
    ax_v.legend(loc="upper right", fontsize="small")
    ax_s.set_ylabel("slip [-]")
    ax_s.set_ylim(-0.02, 1.02)
    ax_t.set_ylabel("brake torque [N m]")
    ax_t.set_xlabel("time [s]")
    fig.suptitle(f"Braking from {traces[next(iter(traces))].v[0]:.0f} m/s on {road}")
    fig.tight_layout()
    save_figure(fig, path)


def format_table(results: list[dict]) -> str:
    """The results as a plain-text table, one block per road."""
    lines = [f"{'road':<10} {'controller':<12} {'distance [m]':>12} {'limit [m]':>10} {'ratio':>7} {'locked':>7}"]
    last_road = None
    for row in results:
        if last_road is not None and row["road"] != last_road:
            lines.append("")
        last_road = row["road"]
        lines.append(f"{row['road']:<10} {row['controller']:<12} {row['distance_m']:>12.2f} "
                     f"{row['limit_m']:>10.2f} {row['ratio']:>7.3f} {('yes' if row['locked'] else 'no'):>7}")
    return "\n".join(lines)


def check_options(args) -> None:
    """Reject unknown roads and an impossible --v0 before any episode runs."""
    from fricenv.envs.braking import BrakingEnv
    from fricenv.envs.scenario import valid_road_names

    valid = [r for r in valid_road_names() if not r.startswith("random")]
    for road in [*args.roads, args.plot_road]:
        if road not in valid:
            raise InvalidInputError(f"unknown road {road!r}; valid: {', '.join(valid)}")
    with user_input("--v0"):
        BrakingEnv(road=args.roads[0], v0=args.v0, observation="oracle").close()


def run(args) -> int:
    from fricenv.utils import write_json

    check_options(args)
    if args.jobs < 1:
        raise InvalidInputError(f"--jobs must be >= 1, got {args.jobs}")
    out = Path(args.out)
    roads = list(dict.fromkeys([*args.roads, args.plot_road]))
    results, traces = run_demo(roads, args.v0, args.seed)
    shown = [r for r in results if r["road"] in args.roads]
    table = format_table(shown)
    _section("1. Classical ABS controllers", table)
    png = out / PLOT_FILE.format(road=args.plot_road.replace(">", ""))
    plot_traces(traces[args.plot_road], args.plot_road, png)
    summary = {"results": shown}
    if not args.quick:
        summary.update(_story(out, args, table, png.name))
    print(f"\nplots and report: {out / story.INDEX if not args.quick else png}")
    if args.json:
        write_json(args.json, summary)
        print(f"json: {args.json}")
    return 0


def _section(title: str, body: str) -> None:
    print(f"\n{title}\n{body}", flush=True)


def _story(out: Path, args, abs_table: str, abs_plot: str) -> dict:
    """Parts 2 to 4 of the demo, printed as they finish; the index page last."""
    loop = story.estimators_in_the_loop(args.seed)
    loop_table = story.format_loop_table(loop)
    _section("2. The same slip controller on the true state and on estimates", loop_table)
    story.plot_loop(loop, out / story.LOOP_PLOT)
    diag = story.diagnose_hidden_effect(out, args.jobs)
    names = ", ".join(e["effect"] for e in diag["effects"]) or diag["verdict"]
    _section("3. A log with a hidden effect, diagnosed blind",
             f"true: {diag['truth']}; verdict: {names} {[e['params'] for e in diag['effects']]}; "
             f"gap {diag['gap_before']:.3g} -> {diag['gap_after']:.3g} noise units (held out); "
             f"report {diag['report']}")
    rows, traces = story.corrected_simulator(diag["report"], args.seed)
    corrected_table = story.format_corrected_table(rows)
    _section(f"4. The corrected simulator: stopping distance on {story.HIDDEN_ROAD} from {story.V0:.0f} m/s",
             corrected_table)
    story.plot_corrected(traces, out / story.CORRECTED_PLOT)
    story.write_index(out, {"abs_table": abs_table, "abs_plot": abs_plot, "loop_table": loop_table,
                            "diagnosis": diag, "corrected_table": corrected_table})
    return {"estimators_in_the_loop": loop, "diagnosis": diag, "corrected": rows}
