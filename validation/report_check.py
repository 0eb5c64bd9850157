"""Does a report say true things about a blind log? Its power analysis and its sensor flags.

For every analysed effect the report gives the smallest deviation from "off" that its test detects half the time
(``where["detectable"]``, :mod:`fricenv.gap.quarter_car.detectability`). On a blind log with one library effect the true size is
known, so the report can be held to it: effects larger than the reported size should mostly be found, smaller ones
mostly not. :func:`size_ratio` is the true size over the reported one, :func:`power_summary` the share found on
either side of 1 and the verdicts that are right or ``none`` on an effect the report sized out of reach.

The report also says which channels looked filtered and how many outliers it set aside (``where["sensors"]``). A
real-like log (:mod:`validation.real_artifacts`) low-passes every ``v`` and ``a_x`` it writes and puts outliers in the wheel
speed; a clean one does neither. :func:`sensor_flags` keeps a row's flags and :func:`sensor_summary` counts, per kind
of log, how often a filtered channel was flagged and how often a clean one was.

On a log with several effects the oracle of one effect (the true model against the calibrated nominal one) does not
say whether the data show each of them: :func:`shown_effects` tests each against the others fitted without it, and
:func:`combo_summary` counts the logs where the tool named what the data show. An out-of-library effect is outside the
tool's model class, so no true model of that class exists: :func:`truth_shown` scores the simulator's noise-free
truth itself against the nominal model (clean logs), and :func:`truth_summary` counts the logs whose data show it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MISS_KINDS", "combo_summary", "format_combos", "format_power", "format_rows", "format_sensors",
           "format_truth", "miss_kind", "miss_kinds", "power_summary", "right_or_below_size", "sensor_flags",
           "sensor_summary", "shown_effects", "size_ratio", "truth_shown", "truth_summary"]

# Why a single library effect's verdict was wrong, in the order tested (the first that applies)
MISS_KINDS = ("below the oracle", "true model leaves the gap", "confounded", "not testable", "other")


def size_ratio(effect: str, truth: dict, dg) -> float | None:
    """The true effect's deviation from "off" over the smallest deviation the report calls detectable, the largest
    ratio over the sized parameters; ``None`` when the report sizes no such effect (not analysed, or out of library).

    :param effect: the log's one library effect.
    :param truth: the log's truth (``params`` and ``road`` before any change: "off" of a friction change).
    :param dg: the diagnosis (its ``where["detectable"]`` and the log's vehicle parameters ``data.p``).
    """
    from fricenv.effects import registry  # the tool, imported only where a diagnosis is checked
    from fricenv.gap.quarter_car.params import ROAD_NAMES

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


def sensor_flags(dg) -> dict:
    """Per logged channel what the report saw: ``{"filtered": bool, "outliers": int, "noise_std": float}`` (the
    noise level the diagnosis normalised the channel by, SI)."""
    return {c: {"filtered": bool(k.get("filtered")), "outliers": int(k.get("outliers", 0)),
                "noise_std": float(dg.data.sigma[c])}
            for c, k in (dg.data.sensors or {}).items()}


def sensor_summary(rows: list[dict]) -> dict:
    """Over the rows with ``sensors``: per kind of log (``real``: written with a logger's artifacts, ``clean``) and
    channel, the logs that carry it and those where it was flagged filtered; and the outliers set aside in the wheel
    speed (a real-like log has :class:`validation.real_artifacts.QuarterCarArtifacts` ``outliers`` of them)."""
    out = {}
    for kind in ("real", "clean"):
        group = [r for r in rows if "sensors" in r and bool(r.get("truth", {}).get("real")) == (kind == "real")]
        if not group:
            continue
        seen = {c: {"logs": sum(c in r["sensors"] for r in group),
                    "flagged_filtered": sum(r["sensors"].get(c, {}).get("filtered", False) for r in group)}
                for c in ("v", "a_x")}
        seen["omega_outliers"] = {"logs": len(group), "set_aside": sum(r["sensors"]["omega"]["outliers"] for r in group)}
        out[kind] = seen
    return out


def format_sensors(s: dict) -> str:
    """One line of :func:`sensor_summary`."""
    parts = []
    for kind, seen in s.items():
        ch = ", ".join(f"{c} {seen[c]['flagged_filtered']}/{seen[c]['logs']}" for c in ("v", "a_x"))
        parts.append(f"{kind} logs flagged filtered: {ch}; wheel-speed outliers set aside "
                     f"{seen['omega_outliers']['set_aside']} in {seen['omega_outliers']['logs']} logs")
    return "sensors: " + "; ".join(parts)


def miss_kind(row: dict) -> str | None:
    """Why a single-effect log's verdict is wrong, ``None`` when it is right or the log has no library effect:
    ``below the oracle`` (even the true model does not pass the test: the data cannot show it), ``true model leaves
    the gap`` (an ``unexplained`` verdict where the true model passes the test but closes less of the gap than the
    verdict rule asks of an effect, ``true_explains``), ``confounded`` (the report names the true effect and the
    verdict as confounded on this log), ``not testable`` (the report lists the true effect as such), else ``other``
    (the tool's own miss)."""
    if row.get("right") or "detectable" not in row or row.get("all_named") is not None:
        return None
    if row["detectable"] is False:
        return "below the oracle"
    if row.get("true_explains") is False and row["verdict"] == "unexplained":
        return "true model leaves the gap"
    pair = {row["expected"], row["verdict"]}
    if any(pair <= set(group) for group in row.get("confounded", [])):
        return "confounded"
    if row["expected"] in row.get("not_testable", ()):
        return "not testable"
    return "other"


def miss_kinds(rows: list[dict]) -> dict:
    """The count of each of :data:`MISS_KINDS` over ``rows`` (:func:`miss_kind`)."""
    kinds = [miss_kind(r) for r in rows]
    return {k: kinds.count(k) for k in MISS_KINDS}


def shown_effects(effects: dict[str, dict], road: dict, dg, cfg, noise: dict[str, float]) -> dict[str, bool]:
    """The oracle of a log with several effects: which of them its data show. For each effect, the true model (every
    effect at its true parameters, the true road) against the best the others can do without it (the road and the
    other effects fitted per fold from their true values, cross-fitted as the tool's candidates are), by the
    diagnosis' own significance test. An effect the others and a refitted road imitate within the noise is not
    shown, and no tool could name it from these data; the true set is not fitted, so "shown" is an upper bound of
    what a fit can find (as for the single-effect oracle). Judged at the true noise levels (:mod:`validation.
    quarter_car_oracle`).

    :param effects: the log's effects, name -> true parameters (contract names, SI units).
    :param road: the true road, keys ``B, C, E, theta``.
    :param dg: the log's diagnosis (its prepared data).
    :param cfg: the diagnosis settings (folds, fit settings, ``sig_z``).
    :param noise: the true noise std per logged channel (:mod:`validation.true_noise`).
    """
    from fricenv.gap.quarter_car.candidates import (
        fit_candidate,  # the tool, imported only where a diagnosis is checked
    )
    from fricenv.gap.quarter_car.params import ROAD_NAMES
    from fricenv.gap.quarter_car.stats import cross_fitted, fold_data, paired_z
    from validation.quarter_car_oracle import true_model_fit, with_noise

    d, names = with_noise(dg.data, noise), list(effects)
    road_x = np.array([road[k] for k in ROAD_NAMES], dtype=float)
    full = true_model_fit(effects, road, d)
    out = {}
    for e in names:
        rest = [o for o in names if o != e]
        fits = [fit_candidate(rest, road_x, fold_data(d, j), cfg, {o: effects[o] for o in rest})
                for j in range(int(cfg.folds))]
        out[e] = bool(paired_z(cross_fitted(fits, d), full, d) > cfg.sig_z)
    return out


def combo_summary(rows: list[dict]) -> dict:
    """Over the rows with several effects and an oracle (``shown``): how many logs show every effect and how many of
    those have every effect named; how many show at least one and how many of those have every shown effect named."""
    rows = [r for r in rows if "shown" in r]
    every = [r for r in rows if set(r["shown"]) == set(r["truth_effects"])]
    some = [r for r in rows if r["shown"]]
    return {"logs": len(rows), "every_shown": len(every), "every_shown_all_named": sum(r["all_named"] for r in every),
            "some_shown": len(some), "shown_named": sum(set(r["shown"]) <= set(r["named"]) for r in some)}


def format_combos(s: dict) -> str:
    """The lines of a ``--combos`` measurement's summary ``s``: its shares of logs with every effect named and the
    oracle's counts (:func:`combo_summary`, under ``s["combos"]``)."""
    c = s["combos"]
    return (f"every effect named: {s['all_effects_named']:.0%} of {s['n']} logs; named or reported not testable: "
            f"{s['named_or_untestable']:.0%}; named true effects' main parameter within 15 %: "
            f"{s['named_effect_params_within_15pct']:.0%}\noracle of several effects: every effect shown by the data "
            f"on {c['every_shown']}/{c['logs']} logs, all named on {c['every_shown_all_named']} of those; at least "
            f"one shown on {c['some_shown']}/{c['logs']}, every shown effect named on {c['shown_named']} of those")


def truth_shown(sim: dict, dg, cfg, noise: dict[str, float]) -> bool:
    """The oracle of an out-of-library log, which the tool's model class cannot hold: does the noise-free truth (the
    simulator's own states and deceleration, ``omega_true``, ``v_true``, ``a_x_true``, on the log's samples) beat the
    calibrated nominal model by the diagnosis' paired test? Its residual is the measurement noise alone, and it fits
    no state per window, so the nominal model's per-window fits are counted against that model
    (:func:`fricenv.gap.quarter_car.stats.paired_z`). If the truth itself does not pass, the data cannot show the effect, and
    `none` is all that a tool can say. ``sim`` holds the truth on the log's rows (a real-like log's:
    :func:`validation.independent_sim.real_truth_rows`). Judged at the true
    noise levels: the nominal model is re-scored there at its own roads (:mod:`validation.quarter_car_oracle`).

    :param sim: ``omega_true``, ``v_true``, ``a_x_true`` on the log's rows (``simulate_case`` of a clean log's case).
    :param dg: the log's diagnosis (its prepared data and nominal model).
    :param cfg: the diagnosis settings (``sig_z``).
    :param noise: the true noise std per logged channel.
    """
    from fricenv.gap.quarter_car.stats import CandidateFit, paired_z, window_counts, window_mse
    from fricenv.gap.quarter_car.windows import trajectory_residuals
    from validation.quarter_car_oracle import nominal_with_noise

    d, nominal = nominal_with_noise(dg, noise)
    if d.n != len(sim["t"]):
        raise ValueError(f"the log has {d.n} samples, its truth {len(sim['t'])}: not the same rows")
    r = trajectory_residuals({"omega": sim["omega_true"], "v": sim["v_true"], "a_x": sim["a_x_true"]}, d)
    wm = window_mse(r, window_counts(d))
    truth = CandidateFit(effect="truth", names=(), x=np.zeros(0), train_mse=float(np.mean(wm[~d.test])),
                         test_mse=float(np.mean(wm)), window_mse=wm, resid=r, nuisances=0)
    return bool(paired_z(nominal, truth, d) > cfg.sig_z)


def truth_summary(rows: list[dict]) -> dict:
    """Over the out-of-library rows with the oracle (``truth_shown``): how many logs show their effect, and how many
    of those and of the others got the right verdict (``unexplained``)."""
    rows = [r for r in rows if "truth_shown" in r]
    shown = [r for r in rows if r["truth_shown"]]
    hidden = [r for r in rows if not r["truth_shown"]]
    return {"logs": len(rows), "shown": len(shown), "right_shown": sum(r["right"] for r in shown),
            "hidden_none": sum(r["verdict"] == "none" for r in hidden)}


def format_truth(s: dict) -> str:
    """The line of :func:`truth_summary` that a measurement run prints."""
    return (f"out-of-library logs: the noise-free truth beats the nominal model on {s['shown']}/{s['logs']}, named "
            f"unexplained on {s['right_shown']} of those; of the {s['logs'] - s['shown']} whose data do not show the "
            f"effect, {s['hidden_none']} read none")


def format_rows(rows: list[dict]) -> str:
    """One line per log: truth, driver, road, columns, verdict, gaps."""
    lines = ["per log: category | driver | road | columns | verdict | gap_before -> gap_after | param error"]
    for r in rows:
        road = r.get("truth", {}).get("road", {}).get("preset", "?")
        cols = ",".join(r.get("truth", {}).get("columns", [])) or "required"
        pe = f"{r['param_error']:.3f}" if "param_error" in r else "-"
        lines.append(f"  {r['category']:>18} | {r.get('truth', {}).get('driver', '?'):>9} | {road:>4} | {cols:>6} | "
                     f"{r['verdict']:>18} {'OK ' if r['right'] else 'BAD'} | {r['gap_before']:.2f} -> "
                     f"{r['gap_after']:.2f} | {pe}")
    return "\n".join(lines)
