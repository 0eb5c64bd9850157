"""The robustness matrix as a table, ``robustness.json`` and a heatmap (estimator or policy x plant cell).

Used by ``fricenv paper robustness`` (estimators: rms speed error per cell) and ``fricenv evaluate --effect-grid``
(policies: stopping-distance ratio per cell, mean over the scenarios). :func:`policy_matrix` reduces evaluation
rows to one entry per (policy, cell); :func:`write_matrix` writes ``robustness.txt`` (the table),
``robustness.json`` (the matrix entries and whatever the caller adds) and ``robustness.png`` into a directory.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fricenv.utils import atomic_write, write_json

__all__ = ["format_matrix", "heatmap", "policy_matrix", "short_cell", "write_matrix"]

_SHORT = {"brake_lag": "lag", "brake_delay": "delay", "brake_gain": "gain", "radius_error": "radius",
          "relaxation_length": "relax", "drag": "drag", "mu_change": "mu"}


def short_cell(cell: str) -> str:
    """A cell label for a narrow column: ``brake_lag:high`` -> ``lag-hi``, ``nominal`` -> ``nominal``."""
    effect, _, size = cell.partition(":")
    return f"{_SHORT.get(effect, effect)}-{size[:2]}" if size else effect


def policy_matrix(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Evaluation rows -> one entry per (policy, cell): mean and worst ratio over the scenarios, lock events,
    episodes that stopped and episodes run."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["policy"], r.get("cell", "nominal")), []).append(r)
    return [{"policy": p, "cell": c,
             "ratio_mean": float(np.mean([m["ratio_mean"] for m in mine])),
             "ratio_worst": float(np.max([m["ratio_mean"] for m in mine])),
             "locks": int(sum(m["locks"] for m in mine)),
             "stopped": int(sum(m["stopped"] for m in mine)),
             "episodes": int(sum(m["episodes"] for m in mine)),
             "scenarios": [m["scenario"] for m in mine]}
            for (p, c), mine in groups.items()]


def _grid(matrix: Sequence[dict[str, Any]], row_key: str, value_key: str) -> tuple[list, list, np.ndarray]:
    names = list(dict.fromkeys(m[row_key] for m in matrix))
    cells = list(dict.fromkeys(m["cell"] for m in matrix))
    values = np.full((len(names), len(cells)), np.nan)
    for m in matrix:
        values[names.index(m[row_key]), cells.index(m["cell"])] = m[value_key]
    return names, cells, values


def format_matrix(matrix: Sequence[dict[str, Any]], row_key: str, value_key: str, fmt: str = "{:.2f}") -> str:
    """A plain-text table: one line per ``row_key`` value, one column per cell, ``value_key`` in each."""
    names, cells, values = _grid(matrix, row_key, value_key)
    width = max([len(row_key)] + [len(n) for n in names])
    cols = [max(len(short_cell(c)), 6) for c in cells]
    head = f"{row_key:<{width}} " + " ".join(f"{short_cell(c):>{w}}" for c, w in zip(cells, cols))
    lines = [head, "-" * len(head)]
    for i, n in enumerate(names):
        cells_text = " ".join(f"{'-' if np.isnan(v) else fmt.format(v):>{w}}" for v, w in zip(values[i], cols))
        lines.append(f"{n:<{width}} {cells_text}")
    return "\n".join(lines)


def heatmap(matrix: Sequence[dict[str, Any]], row_key: str, value_key: str, path: str | Path, title: str,
            label: str, vmax: float | None = None, fmt: str = "{:.2f}") -> Path:
    """A heatmap PNG of ``value_key`` (``row_key`` x cell), each cell annotated with its value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names, cells, values = _grid(matrix, row_key, value_key)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.62 * len(cells) + 2.5), max(2.5, 0.45 * len(names) + 1.6)))
    finite = values[np.isfinite(values)]
    top = vmax if vmax is not None else (float(np.max(finite)) if finite.size else 1.0)
    im = ax.imshow(np.minimum(values, top), cmap="viridis_r" if value_key.startswith("ratio") else "magma_r",
                   aspect="auto", vmin=float(np.min(finite)) if finite.size else 0.0, vmax=top)
    for i in range(len(names)):
        for j in range(len(cells)):
            if np.isfinite(values[i, j]):
                ax.text(j, i, fmt.format(values[i, j]), ha="center", va="center", fontsize=7, color="w"
                        if values[i, j] > 0.6 * top else "k")
    ax.set_xticks(range(len(cells)), [short_cell(c) for c in cells], rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, label=label)
    fig.tight_layout()
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, dpi=110, format="png")
    plt.close(fig)
    return path


def write_matrix(out_dir: str | Path, matrix: Sequence[dict[str, Any]], row_key: str, value_key: str,
                 title: str, label: str, extra: dict[str, Any] | None = None, vmax: float | None = None
                 ) -> dict[str, Path]:
    """Write ``robustness.txt``, ``robustness.json`` (``{"matrix": [...], **extra}``) and ``robustness.png``.

    :return: the written paths by kind (``table``, ``json``, ``heatmap``).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table = format_matrix(matrix, row_key, value_key)
    with atomic_write(out / "robustness.txt") as fh:
        fh.write(f"{title}\n{table}\n")
    write_json(out / "robustness.json", {"matrix": list(matrix), **(extra or {})})
    png = heatmap(matrix, row_key, value_key, out / "robustness.png", title, label, vmax=vmax)
    return {"table": out / "robustness.txt", "json": out / "robustness.json", "heatmap": png}
