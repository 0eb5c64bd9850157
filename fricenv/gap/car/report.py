"""The report of a car's session: ``report.json`` (every contract key of the pooled diagnosis, the events and the
car inside ``where``), ``report.md`` (a table per event) and a timeline plot (speed, brake, throttle, the events
marked), written as :func:`fricenv.gap.report.write_report` writes: complete under a temporary name, then renamed."""

from __future__ import annotations

from pathlib import Path

from fricenv.gap.car.diagnose import SessionDiagnosis
from fricenv.gap.core import report as files
from fricenv.utils import to_jsonable

__all__ = ["PLOT_TIMELINE", "report_dict", "report_markdown", "summary_line", "write_session_report"]

PLOT_TIMELINE = "timeline.png"
MAX_SKIPPED_LINES = 20  # skipped stretches listed in report.md (all are in report.json)


def report_dict(dg: SessionDiagnosis, plant: str = "quarter-car") -> dict:
    """The report.json object: the docs/contracts.md keys for the pooled diagnosis (``gap_before``/``gap_after`` held out
    by event or block), the session's detail in ``where``."""
    return to_jsonable({"plant": plant, "verdict": dg.verdict, "gap_before": dg.gap_before,
                        "gap_after": dg.gap_after, "params": dg.params, "where": dg.where,
                        "candidates": dg.candidates, "effects": dg.effects})


def _params(p: dict) -> str:
    return ", ".join(f"{k}={v:.4g}" for k, v in p.items())


def summary_line(dg: SessionDiagnosis) -> str:
    """One line for the command line."""
    also = [e["effect"] for e in dg.effects if e["effect"] != dg.verdict]
    w = dg.where
    return (f"verdict: {dg.verdict}" + (f" ({_params(dg.params)})" if dg.params else "")
            + (f"; with {', '.join(also)}" if also else "")
            + f"; gap_before {dg.gap_before:.3g} -> gap_after {dg.gap_after:.3g} (noise units, held out by "
            f"{w['held_out']['scheme']}); {len(dg.events)} braking event(s), {len(w['skipped'])} braking "
            f"stretch(es) skipped")


def _event_table(w: dict) -> list[str]:
    lines = []
    for i, e in enumerate(w["events"], 1):
        lines += [f"### Event {i}: {e['t_start']:.2f}-{e['t_end']:.2f} s", "",
                  "| quantity | value |", "| --- | --- |",
                  f"| speed | {e['v_start']:.2f} -> {e['v_end']:.2f} m/s |",
                  f"| prediction windows | {e['windows']} |",
                  f"| largest lateral acceleration | {e['max_lateral_accel']:.2f} m/s^2 |",
                  f"| fitted from | {e['t_fit_start']:.2f} s (the drive settled) |",
                  f"| verdict | `{e['verdict']}`" + (f" ({e['note']})" if e.get("note") else "") + " |"]
        if e["gap_before"] is not None:
            lines.append(f"| gap before / after (held out) | {e['gap_before']:.3f} / {e['gap_after']:.3f} |")
        if e.get("slip_stiffness") is not None:
            lines.append(f"| slip stiffness per unit load (this event) | {e['slip_stiffness']:.3g} |")
        lines += [f"| {x['effect']} (this event alone) | {_params(x['params'])} |" for x in e["effects"]]
        lines.append("")
    return lines


def report_markdown(dg: SessionDiagnosis, report: dict, images=(PLOT_TIMELINE,)) -> str:
    """A readable report of the session."""
    w = report["where"]
    car, sess = w["car"], w["session"]
    lines = [f"# Sim-to-real gap report of a car's session: {Path(dg.source).name}", "",
             f"**Verdict: `{report['verdict']}`**" + (f" with {report['params']}" if report["params"] else ""), "",
             "- effects: " + ("; ".join(f"`{e['effect']}` {_params(e['params'])}" for e in report["effects"])
                             or "none"),
             (f"- held-out gap before: {report['gap_before']:.3f}, after: {report['gap_after']:.3f} (noise units; "
              f"held out by {w['held_out']['scheme']}, {w['held_out']['windows']} windows of "
              f"{w['held_out']['horizon_s']:.2f} s)"),
             f"- session: {sess['duration_s']:.1f} s, " + ", ".join(f"{k} {v:.1f} s" for k, v in
                                                                   sess["seconds"].items()),
             f"- time base: {w['time_base']['origin']}, offset {w['time_base']['offset_s']:.6f} s",
             "- the car: " + ", ".join(f"{k} {car[k]:.5g}" for k in car if k.startswith("r_eff_"))
             + f" m ({car['radius_source']}); brake balance {car['brake_balance']:.3f}",
             f"- diagnosis time: {dg.seconds:.1f} s", ""]
    if w["warnings"]:
        lines += ["## Warnings", ""] + [f"- {x}" for x in w["warnings"]] + [""]
    lines += [f"![timeline]({name})" for name in images] + ([""] if images else [])
    lines += ["## Events", ""] + _event_table(w)
    if w["event_spread"]:
        lines += ["## The car's parameters over the events (each event fitted alone)", "",
                  "| parameter | per event | mean | std |", "| --- | --- | --- | --- |"]
        lines += [f"| {k} | {', '.join(f'{x:.4g}' for x in v['per_event'])} | {v['mean']:.4g} | {v['std']:.3g} |"
                  for k, v in w["event_spread"].items()] + [""]
    lines += ["## Each effect alone on the nominal car (held out)", "", "| effect | params | gap after | score |",
              "| --- | --- | --- | --- |"]
    lines += [f"| {c['effect']} | {_params(c['params'])} | {c['gap_after']:.3f} | {c['score']:.3f} |"
              for c in report["candidates"]] + [""]
    lines += ["## Forward selection (held out)", "", "| step | added | gap after | z paired | accepted |",
              "| --- | --- | --- | --- | --- |"]
    lines += [f"| {i} | {st['added']}{' (calibration)' if st.get('calibration') else ''} | {st['gap']:.3f} | "
              f"{st['z_paired']:.2f} | {st['accepted']} |" for i, st in enumerate(w["forward_selection"], 1)]
    lines += ["", f"## Braking skipped ({len(w['skipped'])} stretches)", ""]
    lines += [f"- {x['t_start']:.2f}-{x['t_end']:.2f} s: {x['reason']}" for x in w["skipped"][:MAX_SKIPPED_LINES]]
    if len(w["skipped"]) > MAX_SKIPPED_LINES:
        lines.append(f"- ... {len(w['skipped']) - MAX_SKIPPED_LINES} more in report.json")
    return "\n".join(lines) + "\n"


def plot_timeline(dg: SessionDiagnosis, path) -> None:
    """Speed, brake and throttle over the session, the events shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = dg.session
    t = s.t - s.t[0]
    fig, axes = plt.subplots(3, 1, figsize=(10, 6), sharex=True)
    axes[0].plot(t, s.v, lw=0.8)
    axes[0].set_ylabel("v [m/s]")
    axes[1].plot(t, s.T_b, lw=0.8, color="C3")
    axes[1].set_ylabel("T_b nominal [N m]")
    if s.throttle is not None:
        axes[2].plot(t, s.throttle, lw=0.8, color="C2")
    axes[2].set_ylabel("throttle")
    axes[2].set_xlabel("t from the first sample [s]")
    for ax in axes:
        for e in dg.where["events"]:
            ax.axvspan(e["t_start"], e["t_end"], color="orange", alpha=0.3)
    axes[0].set_title("session timeline (braking events shaded)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_session_report(dg: SessionDiagnosis, out_dir, plant: str = "quarter-car", plots: bool = True) -> dict:
    """Write report.json, report.md and the timeline into ``out_dir`` (atomically, as
    :func:`fricenv.gap.core.report.write_report`); returns the report dict."""
    return files.write_report(dg, out_dir, plant, markdown=lambda d, r, images: report_markdown(d, r, images),
                              plotter=lambda d, r, folder: plot_timeline(d, folder / PLOT_TIMELINE), plots=plots,
                              plot_names=(PLOT_TIMELINE,), report=report_dict(dg, plant))
