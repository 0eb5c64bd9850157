"""The fleet summary page and plots of :mod:`fricenv.gap.fleet.run`: ``fleet.md`` (verdict counts, parameter
distributions per effect, gap before/after, errors) and three PNG plots, written atomically."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from fricenv.utils import atomic_write, save_figure

__all__ = ["PLOT_GAPS", "PLOT_PARAMS", "PLOT_VERDICTS", "fleet_markdown", "param_values", "write_fleet_summary"]

PLOT_VERDICTS = "fleet_verdicts.png"
PLOT_PARAMS = "fleet_params.png"
PLOT_GAPS = "fleet_gaps.png"


def param_values(rows: list[dict]) -> dict[tuple[str, str], list[float]]:
    """``(effect, parameter) -> values`` over the rows whose verdict is an effect (scalar parameters only)."""
    values: dict[tuple[str, str], list[float]] = {}
    for r in rows:
        for effect in r["effects"]:
            for name, v in r["params"].items():
                if isinstance(v, (int, float)):
                    values.setdefault((effect, name), []).append(float(v))
    return dict(sorted(values.items()))


def _gap_pairs(rows: list[dict]) -> np.ndarray:
    """(n, 2) gap_before, gap_after of the rows without error."""
    pairs = [(r["gap_before"], r["gap_after"]) for r in rows
             if r["error"] is None and r["gap_before"] is not None and r["gap_after"] is not None]
    return np.array(pairs, dtype=float).reshape(-1, 2)


def fleet_markdown(rows: list[dict], images: tuple[str, ...] = (PLOT_VERDICTS, PLOT_PARAMS, PLOT_GAPS)) -> str:
    """The readable fleet page.

    :param rows: the fleet.json rows. :param images: plot files beside it to link (empty: none).
    """
    counts = Counter(r["verdict"] for r in rows)
    lines = [f"# Fleet diagnosis: {len(rows)} logs", "", "## Verdicts", "", "| verdict | logs | share |",
             "|---|---:|---:|"]
    lines += [f"| `{v}` | {n} | {n / len(rows):.0%} |" for v, n in counts.most_common()]
    lines += ["", "## Parameters per effect", ""]
    values = param_values(rows)
    if values:
        lines += ["| effect | parameter | n | median | min | max |", "|---|---|---:|---:|---:|---:|"]
        lines += [f"| `{e}` | {k} | {len(v)} | {np.median(v):.4g} | {min(v):.4g} | {max(v):.4g} |"
                  for (e, k), v in values.items()]
    else:
        lines.append("No log has an effect verdict.")
    gaps = _gap_pairs(rows)
    lines += ["", "## Gap before / after (held-out, noise units)", ""]
    if len(gaps):
        lines += [(f"- median gap before: {np.median(gaps[:, 0]):.3f}, after: {np.median(gaps[:, 1]):.3f} "
                   f"({len(gaps)} logs)"),
                  f"- logs whose gap shrank: {int(np.sum(gaps[:, 1] < gaps[:, 0]))}"]
    errors = [r for r in rows if r["error"] is not None]
    lines += ["", f"## Errors ({len(errors)})", ""]
    lines += [f"- `{r['file']}`: {r['error']}" for r in errors] or ["None."]
    lines += ["", "## Logs", "", "| file | verdict | gap before | gap after | seconds |", "|---|---|---:|---:|---:|"]
    lines += [f"| {Path(r['file']).name} | `{r['verdict']}` | {_num(r['gap_before'])} | {_num(r['gap_after'])} | "
              f"{_num(r['seconds'], '.1f')} |" for r in rows]
    lines.append("")
    lines += [f"![{name[:-4].replace('_', ' ')}]({name})\n" for name in images]
    return "\n".join(lines)


def _num(v, fmt: str = ".3f") -> str:
    return "-" if v is None else format(v, fmt)


def _plot_verdicts(rows: list[dict], path: Path, plt) -> None:
    counts = Counter(r["verdict"] for r in rows).most_common()
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.bar([v for v, _ in counts], [n for _, n in counts])
    ax.set_ylabel("logs")
    ax.set_title("verdicts")
    ax.tick_params(axis="x", labelrotation=30)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)


def _plot_params(rows: list[dict], path: Path, plt) -> None:
    values = param_values(rows)
    n = max(len(values), 1)
    cols = min(n, 3)
    fig, axes = plt.subplots((n + cols - 1) // cols, cols, figsize=(3.3 * cols, 2.8 * ((n + cols - 1) // cols)),
                             squeeze=False)
    for ax, ((effect, name), v) in zip(axes.flat, values.items()):
        ax.hist(v, bins=min(max(len(v), 1), 15))
        ax.set_title(f"{effect}: {name}", fontsize=9)
    for ax in list(axes.flat)[len(values):]:
        ax.axis("off")
    if not values:
        axes.flat[0].text(0.5, 0.5, "no effect verdicts", ha="center", va="center")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)


def _plot_gaps(rows: list[dict], path: Path, plt) -> None:
    gaps = _gap_pairs(rows)
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.scatter(gaps[:, 0], gaps[:, 1], s=12)
    top = float(np.max(gaps)) if gaps.size else 1.0
    ax.plot([0, top], [0, top], color="gray", lw=0.8, ls="--", label="no change")
    ax.set_xlabel("gap before")
    ax.set_ylabel("gap after")
    ax.set_title("held-out gap per log")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)


def write_fleet_summary(rows: list[dict], out: str | Path) -> None:
    """Write ``fleet.md`` and the fleet plots into ``out`` (each atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    for name, plot in ((PLOT_VERDICTS, _plot_verdicts), (PLOT_PARAMS, _plot_params), (PLOT_GAPS, _plot_gaps)):
        plot(rows, out / name, plt)
    with atomic_write(out / "fleet.md") as fh:
        fh.write(fleet_markdown(rows))
