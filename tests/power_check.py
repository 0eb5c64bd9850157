"""Is the diagnosis' power analysis honest? A check of issue 15 item 4 on blind logs.

For every analysed effect the report gives the smallest deviation from "off" that its test detects half the time
(``where["detectable"]``, :mod:`fricenv.gap.detectability`). On a blind log with one library effect the true size is
known, so the report can be held to it: effects larger than the reported size should mostly be found, smaller ones
mostly not. :func:`size_ratio` is the true size over the reported one, :func:`power_summary` the share found on
either side of 1 and the verdicts that are right or ``none`` on an effect the report sized out of reach.
"""

from __future__ import annotations

import numpy as np

__all__ = ["format_power", "power_summary", "right_or_below_size", "size_ratio"]


def size_ratio(effect: str, truth: dict, dg) -> float | None:
    """The true effect's deviation from "off" over the smallest deviation the report calls detectable, the largest
    ratio over the sized parameters; ``None`` when the report sizes no such effect (not analysed, or out of library).

    :param effect: the log's one library effect.
    :param truth: the log's truth (``params`` and ``road`` before any change: "off" of a friction change).
    :param dg: the diagnosis (its ``where["detectable"]`` and the log's vehicle parameters ``data.p``).
    """
    from fricenv.effects import registry  # the tool, imported only where a diagnosis is checked
    from fricenv.gap.params import ROAD_NAMES

    sizes = dg.where.get("detectable", {}).get(effect)
    if not sizes:
        return None
    road = np.array([truth["road"][k] for k in ROAD_NAMES], dtype=float)
    ratios = []
    for q in registry.get(effect).params:
        if q.name in sizes and sizes[q.name] > 0:
            off = float(np.asarray(q.off_value(road, dg.data.p), dtype=float).reshape(-1)[0])
            ratios.append(abs(float(truth["params"][q.name]) - off) / float(sizes[q.name]))
    return max(ratios) if ratios else None


def right_or_below_size(row: dict) -> bool:
    """A right verdict, or ``none`` on an effect the report sized out of reach (true size below the reported
    detectable size, or the effect listed as not testable)."""
    below = row.get("size_ratio") is not None and row["size_ratio"] < 1.0
    return bool(row["right"]) or (row["verdict"] == "none" and (below or row["expected"] in row.get("not_testable", ())))


def power_summary(rows: list[dict]) -> dict:
    """Over the single-effect rows with a ``size_ratio``: how many lie below and above the reported size and how
    many of each the diagnosis named right, and the share of all rows :func:`right_or_below_size`."""
    sized = [r for r in rows if r.get("size_ratio") is not None]
    out = {}
    for side, keep in (("below", lambda x: x < 1.0), ("above", lambda x: x >= 1.0)):
        group = [r for r in sized if keep(r["size_ratio"])]
        out[side] = {"logs": len(group), "right": int(sum(bool(r["right"]) for r in group))}
    out["right_or_below_size"] = float(np.mean([right_or_below_size(r) for r in rows])) if rows else float("nan")
    return out


def format_power(pw: dict) -> str:
    """One line of :func:`power_summary`."""
    return (f"power analysis: effects at or above the reported detectable size named right {pw['above']['right']}/"
            f"{pw['above']['logs']}, below it {pw['below']['right']}/{pw['below']['logs']}; right, or `none` on an "
            f"effect the report sized out of reach: {pw['right_or_below_size']:.0%}")
