"""The report files every plant's diagnosis writes: ``report.json`` (the contract of docs/contracts.md), ``report.md``
and PNG plots, written atomically.

Nothing is overwritten half-way: every file is first written completely under a temporary name in the output
directory and then renamed onto its final name, ``report.json`` last, so a reader either sees the previous report or
the complete new one, and a failure (e.g. while plotting) leaves any previous ``report.json`` intact. matplotlib is
imported inside the plotting functions, with the Agg backend.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from fricenv.utils import atomic_write, to_jsonable, write_json

__all__ = ["CANDIDATE_KEYS", "PLOT_REGIMES", "PLOT_TIME", "REPORT_KEYS", "effects_of", "image_links", "plot_regimes", "report_dict",
           "write_report"]

REPORT_KEYS = ("plant", "verdict", "gap_before", "gap_after", "params", "where", "candidates", "effects")
CANDIDATE_KEYS = ("effect", "params", "gap_after", "score")
PLOT_TIME = "residual_time.png"
PLOT_REGIMES = "residual_regimes.png"


def _score(c, gap_before: float) -> float:
    """Share of the nominal model's held-out excess squared error that the candidate closes (1 = all, <0 = worse)."""
    if gap_before <= 0:
        return 0.0
    return float(1.0 - c.gap**2 / gap_before**2)


def effects_of(dg) -> list[dict]:
    """The selected set (a diagnosis without forward selection: its verdict's effect, if any)."""
    if getattr(dg, "effects", None) is not None and hasattr(dg, "whole"):
        return list(dg.effects)
    return [] if dg.verdict in ("none", "unexplained") else [{"effect": dg.verdict, "params": dict(dg.params)}]


def report_dict(dg, plant: str = "quarter-car") -> dict:
    """The report.json object, exactly the docs/contracts.md schema (extra detail lives inside ``where``)."""
    cands = [{"effect": c.effect, "params": c.effect_params(), "gap_after": c.gap, "score": _score(c, dg.gap_before)}
             for c in dg.candidates]
    return to_jsonable({"plant": plant, "verdict": dg.verdict, "gap_before": dg.gap_before,
                        "gap_after": dg.gap_after, "params": dg.params, "where": dg.where, "candidates": cands,
                        "effects": effects_of(dg)})


def image_links(images: Sequence[str]) -> list[str]:
    """Markdown lines linking the plots written (``images``: file names), none for plots not written."""
    captions = {PLOT_TIME: "residual over time", PLOT_REGIMES: "residual by regime"}
    return [line for name in images for line in (f"![{captions.get(name, name)}]({name})", "")]


def plot_regimes(report: dict, with_after: bool, path) -> None:
    """Bar chart of the gap per regime of ``report["where"]["regimes"]``, before (and after) the verdict's effect."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    regimes = report["where"]["regimes"]
    names = [k for k, r in regimes.items() if r["samples"]]
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.bar(x - 0.2, [regimes[k]["gap"] for k in names], 0.4, label="before")
    if with_after:
        ax.bar(x + 0.2, [regimes[k].get("gap_after") or 0.0 for k in names], 0.4, label="after")
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("gap (noise units)")
    ax.legend(fontsize=8)
    ax.set_title("gap by operating regime")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_report(dg, out_dir, plant: str, markdown: Callable[..., str], plotter: Callable[..., None],
                 plots: bool = True, plot_names: Sequence[str] = (PLOT_TIME, PLOT_REGIMES),
                 report: dict | None = None) -> dict:
    """Write report.json, report.md and the plots into ``out_dir``; returns the report dict.

    Files are produced in a temporary directory beside the final ones, then renamed into place (report.json last).

    :param plots: write the PNG plots; report.md links only the plots actually written (none without plots).
    :param markdown: ``(dg, report, images=...) -> str`` for report.md; ``images`` are the plot files written.
    :param plotter: ``(dg, report, directory) -> None`` writing the PNG plots named ``plot_names``.
    :param plot_names: the plot files the plotter may write.
    :param report: the report dict (default :func:`report_dict` of ``dg``).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = report_dict(dg, plant) if report is None else report
    tmp = Path(tempfile.mkdtemp(prefix=".report.", dir=out))
    try:
        if plots:
            plotter(dg, report, tmp)
        images = [name for name in plot_names if (tmp / name).exists()]
        with atomic_write(tmp / "report.md") as fh:
            fh.write(markdown(dg, report, images=images))
        write_json(tmp / "report.json", report)
        for name in [*plot_names, "report.md", "report.json"]:
            if (tmp / name).exists():
                os.replace(tmp / name, out / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return report
