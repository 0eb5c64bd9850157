"""The quarter car's report: the one-line summary, ``report.md`` and its plots (the files are written by
:func:`fricenv.gap.core.report.write_report`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fricenv.gap.core import report as files
from fricenv.gap.core.report import (
    CANDIDATE_KEYS,
    PLOT_REGIMES,
    PLOT_TIME,
    REPORT_KEYS,
    effects_of,
    image_links,
    plot_regimes,
    report_dict,
)
from fricenv.gap.quarter_car.diagnose import Diagnosis
from fricenv.gap.quarter_car.drift import SHIFT_SHARE
from fricenv.gap.quarter_car.stats import TRIM_SHARE

__all__ = ["CANDIDATE_KEYS", "REPORT_KEYS", "report_dict", "report_markdown", "summary_line", "write_report"]


def _shift_text(dt: dict) -> str:
    """The parameter-shift test per parameter (jackknife t, share of the effect's size) and its limits."""
    if not dt.get("shift"):
        return ""
    def num(x, fmt: str) -> str:
        return format(x, fmt) if x is not None and np.isfinite(x) else "n/a"

    ts = ", ".join(f"{k} t {num(v.get('t'), '.1f')}, share {num(v.get('share'), '.2f')}"
                   for k, v in dt["shift"].items())
    return f" (parameter shift: {ts}; a drift past |t| {dt['shift_limit']:.2f} and a share {SHIFT_SHARE})"


def _z(z: float | None) -> str:
    """A z value for a table; "-" for a test not made (the payload, or a model without an effect)."""
    return "-" if z is None else f"{z:.1f}"


def summary_line(dg: Diagnosis) -> str:
    """One-line summary for the command line."""
    params = ", ".join(f"{k}={v:.4g}" for k, v in dg.params.items())
    verdict = dg.verdict + (f" ({params})" if params else "")
    seg = dg.where["segments"][0] if dg.where.get("segments") else None
    worst = f"; worst segment {seg['t_start']:.2f}-{seg['t_end']:.2f} s" if seg else ""
    more = [e["effect"] for e in effects_of(dg)[1:]]
    also = f"; with {', '.join(more)}" if more else ""
    untested = sorted(dg.where.get("not_testable", {}))
    untested = f"; not testable on this log: {', '.join(untested)}" if untested else ""
    apart = dg.where.get("told_apart")
    apart = (f"; not told apart from {apart['from']} (z paired {apart['z_paired']:.1f})"
             if apart and not apart["apart"] else "")
    return (f"verdict: {verdict}{also}; gap_before {dg.gap_before:.3g} -> gap_after {dg.gap_after:.3g} "
            f"(noise units, held-out){apart}{worst}{untested}")


def report_markdown(dg: Diagnosis, report: dict, images: Sequence[str] = (PLOT_TIME, PLOT_REGIMES)) -> str:
    """A readable report.

    :param images: the plot files written beside it, linked at the end (empty: no image links).
    """
    w = report["where"]
    lines = [f"# Sim-to-real gap report: {Path(dg.source).name}", "", f"**Verdict: `{report['verdict']}`**", "",
             *_effects_table(report["effects"]),
             f"- held-out gap before: {report['gap_before']:.3f} (noise units; 0 = the model fits within noise)",
             f"- held-out gap after:  {report['gap_after']:.3f}",
             (f"- data: {w['data']['samples']} samples, channels {', '.join(w['data']['channels'])}; "
              f"{w['data']['windows']} prediction windows of {w['data']['horizon_s']:.2f} s, "
              f"each held out once ({w['data']['folds']}-fold cross-fitting); speed: {w['data']['speed_source']}"),
             f"- certainty: {w['data']['certainty']}",
             (f"- times from the log's first sample (its stamp in the log's own base: "
              f"{w['time_base']['offset_s']!r} s)" if "time_base" in w else "- times as logged"),
             "- calibrated nominal road: " + ", ".join(f"{k}={v:.4g}" for k, v in w["nominal_road"].items()),
             f"- diagnosis time: {dg.seconds:.1f} s", "",
             *(["## Warnings on the log", "", *[f"- {x}" for x in w["warnings"]], ""] if w.get("warnings") else []),
             "## Where the gap lies", "", "Worst time segments (nominal model):", ""]
    for s in w["segments"]:
        lines.append(f"- {s['t_start']:.2f}-{s['t_end']:.2f} s: gap {s['gap']:.2f}"
                     + (" (held out)" if s["held_out"] else ""))
    lines += ["", "| regime | samples | gap before | gap after |", "| --- | --- | --- | --- |"]
    for name, r in w["regimes"].items():
        fmt = (lambda x: "-" if x is None else f"{x:.2f}")
        lines.append(f"| {name} | {r['samples']} | {fmt(r['gap'])} | {fmt(r.get('gap_after'))} |")
    lines += ["", "| channel | noise std (estimated) | gap before | gap after |", "| --- | --- | --- | --- |"]
    for name, c in w["channels"].items():
        after = c.get("gap_after")
        lines.append(f"| {name} | {c['noise_std']:.4g} | {c['gap']:.2f} | {'-' if after is None else f'{after:.2f}'} |")
    lines += ["", "## Candidates (each window predicted by a fit that did not see it)", "",
              "| effect | params | gap after | robust gap after | score | t | z | z paired | z own road | significant |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for c in report["candidates"]:
        t = w["tests"].get(c["effect"], {})
        params = ", ".join(f"{k}={v:.4g}" for k, v in c["params"].items())
        lines.append(f"| {c['effect']} | {params} | {c['gap_after']:.3f} | {t.get('robust_gap', float('nan')):.3f} "
                     f"| {c['score']:.3f} | {t.get('t_stat', float('nan')):.2f} | {t.get('z', float('nan')):.1f} | "
                     f"{t.get('z_paired', float('nan')):.1f} | {_z(t.get('z_without_effect'))} | "
                     f"{t.get('significant', False)} |")
    lines += _testability_lines(w)
    if w.get("told_apart") and w["told_apart"]["from"] is not None:
        a = w["told_apart"]
        params = ", ".join(f"{k}={v:.4g}" for k, v in a["params"].items())
        lines += ["", (f"Told apart: `{a['effect']}` against the best other significant candidate, `{a['from']}` "
                       f"({params}; gap after {a['gap_after']:.3f}): z paired {a['z_paired']:.1f}. "
                       + ("The log tells them apart." if a["apart"] else
                          "Below the significance bound: the log reads as well with either effect, and the "
                          "verdict is the better fit of the two."))]
    if "joint_fit" in w:
        j = w["joint_fit"]
        lines += ["", f"Joint fit of {' + '.join(j['effects'])}: gap after {j['gap_after']:.3f}, params {j['params']}"]
    if "drift_test" in w:
        dt = w["drift_test"]
        moved = ", ".join(f"{k} {dt['params_early'][k]:.4g} -> {dt['params_late'][k]:.4g}"
                          for k in dt["params_early"])
        lines += ["", (f"Drift test of `{dt['model']}` (refitted on the early and the late half of the log, each half "
                       f"held out as above): z paired {dt['z_paired']:.1f}, robust gap {dt['robust_gap']:.3f} -> "
                       f"{dt['robust_gap_split']:.3f}; early -> late: {moved}{_shift_text(dt)}. "
                       + ("Its parameters drift: the gap is caused by something this constant library effect only "
                          "imitates, hence `unexplained`." if dt["drifts"] else "No significant drift."))]
    if w.get("periodic"):
        lines += ["", _periodic_sentence(w["periodic"])]
    lines += ["", ("Score: share of the nominal model's held-out excess squared error the candidate closes. "
                   "z paired: held-out improvement of the squared normalised error (without its largest window) "
                   "over its spread under the measurement noise given the two models' prediction difference; a "
                   "candidate is significant above DiagnoseConfig.sig_z. z: the same improvement over the spread "
                   "of a sum of squares of noise, and t: paired t statistic of the per-window log error ratio "
                   "(both reported only). A verdict needs a significant candidate whose robust held-out gap (the "
                   f"worst {TRIM_SHARE:.0%} of windows left out, for every model alike) is at most "
                   "DiagnoseConfig.ratio_explained of the nominal one, or below gap_within_noise. The robust "
                   f"nominal gap is {w.get('robust_gap_before', float('nan')):.3f}."), ""]
    return "\n".join(lines + image_links(images))


def _effects_table(effects: list[dict]) -> list[str]:
    """The selected effects' parameters as a table with their units (none for ``none``/``unexplained``)."""
    from fricenv.effects import registry

    if not effects:
        return []
    lines = ["| effect | parameter | value | unit |", "| --- | --- | --- | --- |"]
    for e in effects:
        units = {q.name: q.unit for q in registry.get(e["effect"]).params}
        lines += [f"| {e['effect']} | {k} | {v:.4g} | {units.get(k, '') or '-'} |" for k, v in e["params"].items()]
    return lines + [""]


def _periodic_sentence(line: dict) -> str:
    """What a line in the nominal wheel-speed residual means for the verdict."""
    head = (f"The nominal model's wheel-speed residual holds a line at {line['freq_hz']:.1f} Hz, "
            f"{line['ratio']:.0f} times its spectrum's median level")
    if line.get("remains_with_effects") is False:
        return head + ": the selected effects remove it (their own signature, such as ABS cycles through a lag)."
    return head + (": a periodic gap (a wheel hop, a brake judder) that no library effect makes"
                   + (", hence `unexplained`." if line.get("decided") else "."))


def _testability_lines(w: dict) -> list[str]:
    """report.md lines on what the log cannot tell: the candidates not tested (with why) and the smallest size of
    each tested one that would have passed the significance test (``where["detectable"]``)."""
    lines = []
    if w.get("not_testable"):
        lines += ["", "Not testable on this log (not fitted; a verdict of `none` says nothing about them):", ""]
        lines += [f"- `{e}`: {why}" for e, why in w["not_testable"].items()]
    if w.get("caveats"):
        lines += ["", "Tested in part (a verdict of `none` says less about them):", ""]
        lines += [f"- `{e}`: {why}" for e, why in w["caveats"].items()]
    if w.get("alternatives"):
        lines += ["", "Could also be (this log's channels cannot tell them apart):", ""]
        lines += [f"- `{a['effect']}` (" + ", ".join(f"{k} = {x:.4g}" for k, x in a["params"].items())
                  + f") instead of `{a['instead_of']}`: {a['why']}" for a in w["alternatives"]]
    confounded = [(st["effect"], st["confounded_with"]) for st in w.get("forward_selection", [])
                  if st.get("confounded_with")]
    if confounded:
        lines += ["", "Confounded on this log (each explains the gap alone, neither adds to the other):", ""]
        lines += [f"- `{e}` with " + ", ".join(f"`{x}`" for x in with_) for e, with_ in confounded]
    sizes = {e: v for e, v in w.get("detectable", {}).items() if e not in w.get("not_testable", {})}
    if sizes:
        lines += ["", ("Smallest size each tested effect needed to show above this log's noise (detected half "
                       "the time; a smaller one would pass unseen):"), ""]
        lines += [f"- `{e}`: " + ", ".join(f"|{k} - off| = {x:.3g}" for k, x in v.items()) for e, v in sizes.items()]
    return lines


def _plots(dg: Diagnosis, report: dict, tmpdir: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = dg.data
    t_mid = d.t0 + d.dt * (d.starts + d.horizon / 2)
    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.step(t_mid, dg.residuals["before"], where="mid", label="nominal (before)")
    if "after" in dg.residuals:
        ax.step(t_mid, dg.residuals["after"], where="mid", label=f"with {dg.verdict} (after)")
    first = d.fold == 0
    ax.plot(t_mid[first], np.zeros(first.sum()) + 0.05, "k|", label="fold 1 (the others: fold 2)")
    ax.axhline(1.0, color="gray", lw=0.8, ls="--", label="noise level")
    ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("RMS residual / noise")
    ax.legend(fontsize=8)
    ax.set_title("prediction residual per window")
    fig.tight_layout()
    fig.savefig(tmpdir / PLOT_TIME, dpi=100)
    plt.close(fig)

    plot_regimes(report, "after" in dg.residuals, tmpdir / PLOT_REGIMES)


def write_report(dg: Diagnosis, out_dir, plant: str = "quarter-car", plots: bool = True) -> dict:
    """Write the quarter car's report.json, report.md and plots into ``out_dir``; returns the report dict
    (:func:`fricenv.gap.core.report.write_report`)."""
    return files.write_report(dg, out_dir, plant, markdown=report_markdown, plotter=_plots, plots=plots)
