"""Readable report and PNG plots of a payload gap diagnosis (the report.json contract and the atomic write are
:func:`fricenv.gap.core.report.write_report`'s; matplotlib is imported inside the plotting function, Agg backend)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fricenv.gap.core.report import PLOT_REGIMES, PLOT_TIME, image_links, plot_regimes, write_report
from fricenv.gap.payload.diagnose import CHANNELS, PayloadDiagnosis, _fmt

__all__ = ["payload_markdown", "payload_plots", "write_payload_report"]

PLANT = "payload"
SMOOTH_S = 0.1  # moving RMS window of the residual-over-time plot [s]


def payload_markdown(dg: PayloadDiagnosis, report: dict, images: Sequence[str] = (PLOT_TIME, PLOT_REGIMES)) -> str:
    """A readable report of a payload diagnosis.

    :param images: the plot files written beside it, linked at the end (empty: no image links).
    """
    w = report["where"]
    data = w["data"]
    params = ", ".join(f"{k}={_fmt(v)}" for k, v in report["params"].items())
    lines = [f"# Sim-to-real gap report (payload): {Path(dg.source).name}", "",
             f"**Verdict: `{report['verdict']}`**" + (f" with {params}" if params else ""), "",
             f"- held-out gap before: {report['gap_before']:.3f} (noise units; 0 = the model fits within noise)",
             f"- held-out gap after:  {report['gap_after']:.3f}",
             (f"- data: {data['samples']} samples at {data['dt']:g} s; {data['blocks']} blocks of "
              f"{data['block_s']:g} s, {data['held_out_blocks']} held out; {data['effective_samples']:.0f} effective "
              f"independent residuals; filter: {data['filter']}"),
             "- raw noise std estimated from the log: " + ", ".join(f"{k} {v:.3g}"
                                                                   for k, v in data["raw_noise_std"].items()),
             f"- diagnosis time: {dg.seconds:.1f} s", "",
             "## Where the gap lies", "", "Worst time blocks (nominal model):", ""]
    for s in w["segments"]:
        lines.append(f"- {s['t_start']:.2f}-{s['t_end']:.2f} s: gap {s['gap']:.2f}"
                     + (" (held out)" if s["held_out"] else ""))
    fmt = (lambda x: "-" if x is None else f"{x:.2f}")
    lines += ["", "| regime | samples | gap before | gap after |", "| --- | --- | --- | --- |"]
    for name, r in w["regimes"].items():
        lines.append(f"| {name} | {r['samples']} | {fmt(r['gap'])} | {fmt(r.get('gap_after'))} |")
    lines += ["", "| channel | residual noise std (estimated) | gap before | gap after |", "| --- | --- | --- | --- |"]
    for name, c in w["channels"].items():
        lines.append(f"| {name} | {c['noise_std']:.4g} {c['unit']} | {c['gap']:.2f} | {fmt(c.get('gap_after'))} |")
    lines += ["", "## Candidates (fitted on training blocks, scored on held-out blocks)", "",
              "| effect | params | gap after | score | z | penalised held-out MSE | significant |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for c in report["candidates"]:
        t = w["tests"].get(c["effect"], {})
        p = ", ".join(f"{k}={_fmt(v)}" for k, v in c["params"].items())
        lines.append(f"| {c['effect']} | {p} | {c['gap_after']:.3f} | {c['score']:.3f} | {t.get('z', np.nan):.1f} | "
                     f"{t.get('penalised_test_mse', np.nan):.3f} | {t.get('significant', False)} |")
    if "joint_fit" in w:
        j = w["joint_fit"]
        jp = ", ".join(f"{k}={_fmt(v)}" for k, v in j["params"].items())
        lines += ["", f"Joint fit of {' + '.join(j['effects'])}: gap after {j['gap_after']:.3f}, params {jp}"]
    lines += ["", ("Residual: filtered (I_G theta'', m X'', m Y'') from the vision pose minus the same filter applied "
                   "to G(theta) S w_hat, divided by its noise level propagated from the raw noise. Score: share of the "
                   "nominal model's held-out excess squared error the candidate closes. z: held-out improvement "
                   "without its largest block, in noise standard deviations. Ranking: held-out MSE plus a penalty per "
                   "fitted parameter."), ""]
    return "\n".join(lines + image_links(images))


def _moving_rms(x: np.ndarray, n: int) -> np.ndarray:
    k = np.ones(max(n, 1)) / max(n, 1)
    return np.sqrt(np.convolve(x**2, k, mode="same"))


def payload_plots(dg: PayloadDiagnosis, report: dict, out_dir: Path) -> None:
    """Residual over time per channel (before and after) and the gap by regime, as PNG files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = dg.data
    scored = d.block >= 0
    n = max(round(SMOOTH_S / d.dt), 1)
    fig, axes = plt.subplots(3, 1, figsize=(8, 6), sharex=True)
    for i, (ax, c) in enumerate(zip(axes, CHANNELS)):
        before = np.where(scored, _moving_rms(dg.nominal.residual[:, i], n), np.nan)
        ax.plot(d.t, before, lw=0.8, label="nominal (before)")
        if dg.chosen is not None:
            after = np.where(scored, _moving_rms(dg.chosen.residual[:, i], n), np.nan)
            ax.plot(d.t, after, lw=0.8, label=f"with {dg.verdict} (after)")
        ax.fill_between(d.t, 0, 1, where=d.test, color="gray", alpha=0.15, transform=ax.get_xaxis_transform(),
                        label="held out")
        ax.axhline(1.0, color="k", lw=0.6, ls="--")
        ax.set_yscale("log")
        ax.set_ylabel(f"{c}: RMS / noise")
    axes[0].legend(fontsize=7, loc="upper right")
    axes[0].set_title("normalised acceleration residual (moving RMS)")
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(out_dir / PLOT_TIME, dpi=100)
    plt.close(fig)

    plot_regimes(report, dg.chosen is not None, out_dir / PLOT_REGIMES)


def write_payload_report(dg: PayloadDiagnosis, out_dir, plots: bool = True) -> dict:
    """Write report.json (``"plant": "payload"``), report.md and the plots atomically; returns the report dict."""
    return write_report(dg, out_dir, PLANT, plots=plots, markdown=payload_markdown, plotter=payload_plots)
