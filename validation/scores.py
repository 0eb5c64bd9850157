"""The three numbers of a quarter-car suite (docs/validation.md), from the JSON that ``python -m
validation.stand_in_suite --json`` (the library stand-in's logs) or ``python -m validation.independent_sim --json``
writes:

- the share of logs whose data show the answer: a nominal log always; a one-effect log when the true model passes
  the diagnosis' significance test (``detectable``, :func:`validation.quarter_car_oracle.true_model_oracle`); a
  log with several effects when every effect is shown (``shown``, :func:`validation.report_check.shown_effects`); an
  out-of-library log when its noise-free truth beats the nominal model (``truth_shown``; a real-like export's on
  its resampled rows), and where that oracle could not run (an export whose rows differ from its truth's,
  ``truth_error``) it counts as shown;
- the right verdicts on those logs (several effects: every effect named);
- the share of all logs with at least one named effect that is not in the log;

and, where the suite ran it, a fourth: the right verdicts on the shown logs whose data also tell the answer from the
best other library effect (``apart``, :func:`validation.quarter_car_oracle.alternative_oracle`; a one-effect log
without that oracle counts as apart). Where the rows carry the tool's own test (``told_apart``, the report's
``where["told_apart"]``), the right share of the effect verdicts it tells apart from its runner-up and of those it
does not.

Every oracle judges with the noise levels the source drew (``true_noise`` of each row, :mod:`validation.true_noise`),
not with the tool's estimate. Where the rows carry the level the tool used (``sensors[c]["noise_std"]``), a second
line gives its ratio to the source's per channel (:func:`noise_levels`). A ``fricenv gap validate --json`` result
carries no oracle: its effect logs are refused here (run the same seed through ``python -m
validation.stand_in_suite``).

Command (``--pool``: a last line with the numbers of every file's logs together, as the validation page's
summary over seeds gives them)::

    python -m validation.scores [--pool] RESULT.json [RESULT.json ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from collections.abc import Sequence

import numpy as np

__all__ = ["format_noise", "format_numbers", "noise_levels", "quarter_car_numbers"]

NONE, OUT = "none", "out_of_library"


def _truth_effects(row: dict) -> list[str]:
    if row.get("truth_effects"):
        return list(row["truth_effects"])
    return [] if row["category"] in (NONE, OUT) else [row["category"]]


def _named(row: dict, library: set[str]) -> list[str]:
    named = row.get("named") or [row["verdict"]]
    return [e for e in named if e in library]


def _shown(row: dict) -> bool:
    if row["category"] == NONE:
        return True
    if row.get("truth_effects"):
        return set(row.get("shown", ())) == set(row["truth_effects"])
    if row["category"] == OUT:
        return bool(row.get("truth_shown", True))
    return bool(row.get("detectable", True))


def _apart(row: dict) -> bool:
    return bool(row.get("apart", True))


def _right(row: dict) -> bool:
    if row.get("truth_effects") and len(row["truth_effects"]) > 1:
        return bool(row.get("all_named", False))
    return bool(row["right"])


def quarter_car_numbers(rows: Sequence[dict]) -> dict:
    """The three numbers over result rows (see the module docstring)."""
    from fricenv.effects.quarter_car import EFFECTS

    library = set(EFFECTS)
    rows = list(rows)
    unjudged = [r for r in rows if r["category"] in library and r.get("verdict") != "error"
                and "detectable" not in r and not r.get("truth_effects")]
    if unjudged:
        raise ValueError(f"{len(unjudged)} effect log(s) without the oracle's 'detectable': a fricenv gap validate "
                         "result? Run the seed through python -m validation.stand_in_suite")
    shown = [r for r in rows if _shown(r)]
    apart = [r for r in shown if _apart(r)]
    wrong = [r for r in rows if any(e not in _truth_effects(r) for e in _named(r, library))]
    out = {"n": len(rows), "shown": len(shown), "right_on_shown": sum(_right(r) for r in shown),
           "wrong_named": len(wrong),
           "shown_share": len(shown) / len(rows) if rows else float("nan"),
           "right_on_shown_share": sum(_right(r) for r in shown) / len(shown) if shown else float("nan"),
           "wrong_named_share": len(wrong) / len(rows) if rows else float("nan")}
    if any("apart" in r for r in rows):
        pairs = Counter(f"{r['category']}->{r['alternative']}" for r in shown if not _apart(r))
        out.update(apart=len(apart), right_on_apart=sum(_right(r) for r in apart), alternatives=dict(pairs))
    flagged = [r for r in rows if r.get("told_apart")]
    if flagged:
        split = {k: [r for r in flagged if bool(r["told_apart"]["apart"]) is v] for k, v in (("apart", True),
                                                                                            ("not_apart", False))}
        out["tool_told_apart"] = {k: {"verdicts": len(v), "right": sum(_right(r) for r in v)} for k, v in split.items()}
    return out


def format_numbers(q: dict, label: str = "") -> str:
    """One line of :func:`quarter_car_numbers`."""
    line = (f"{label}data show the answer on {q['shown']}/{q['n']} ({q['shown_share']:.0%}); right on those "
            f"{q['right_on_shown']}/{q['shown']} ({q['right_on_shown_share']:.0%}); wrong named effects "
            f"{q['wrong_named']}/{q['n']} ({q['wrong_named_share']:.0%})")
    if "apart" in q:
        told = ", ".join(f"{k} {v}" for k, v in sorted(q["alternatives"].items())) or "none"
        line += (f"; told apart from the best other effect on {q['apart']}/{q['shown']}, right on those "
                 f"{q['right_on_apart']}/{q['apart']} (not apart: {told})")
    if "tool_told_apart" in q:
        a, b = q["tool_told_apart"]["apart"], q["tool_told_apart"]["not_apart"]
        line += (f"; effect verdicts the tool tells apart from its runner-up right on {a['right']}/{a['verdicts']}, "
                 f"those it does not on {b['right']}/{b['verdicts']}")
    return line


RATE_BANDS = ((0.0, 50.0), (50.0, 85.0), (85.0, float("inf")))  # logger rates of a real-like export [Hz]


def _band_name(lo: float, hi: float) -> str:
    if lo <= 0.0:
        return f"below {hi:g} Hz"
    return f"{lo:g} Hz and above" if hi == float("inf") else f"{lo:g}-{hi:g} Hz"


def noise_levels(rows: Sequence[dict]) -> dict:
    """Per channel, the noise level the diagnosis used over the one the source drew (``sensors[c]["noise_std"]``
    over ``true_noise[c]``, rows that carry both): the median, the range and the logs, over every such row and, for
    the rows of a real-like export, per band of its logger rate (:data:`RATE_BANDS`). A level read low makes every
    gap larger in noise units, so that a right effect can leave more than the verdict rule allows."""
    def stats(values: list[float]) -> dict:
        return {"logs": len(values), "median": float(np.median(values)), "min": float(np.min(values)),
                "max": float(np.max(values))}

    out: dict = {}
    for c in ("omega", "v", "a_x"):
        pairs = [(r, r["sensors"][c]["noise_std"] / r["true_noise"][c]) for r in rows
                 if "noise_std" in (r.get("sensors") or {}).get(c, {}) and (r.get("true_noise") or {}).get(c)]
        if not pairs:
            continue
        out[c] = {"all": stats([x for _, x in pairs])}
        for lo, hi in RATE_BANDS:
            band = [x for r, x in pairs if lo <= ((r.get("truth") or {}).get("real") or {}).get("rate_hz", -1) < hi]
            if band:
                out[c][_band_name(lo, hi)] = stats(band)
    return out


def format_noise(levels: dict, label: str = "") -> str:
    """One line of :func:`noise_levels`."""
    parts = []
    for c, groups in levels.items():
        parts.append(f"{c} " + ", ".join(f"{k} {g['median']:.2f} ({g['min']:.2f}-{g['max']:.2f}, {g['logs']} logs)"
                                         for k, g in groups.items()))
    return f"{label}noise level used / the source's, median (range): " + "; ".join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    """Print the three numbers of each result file, and with ``--pool`` those of all their logs together."""
    ap = argparse.ArgumentParser(prog="python -m validation.scores", description="The three numbers of quarter-car suite results "
                                 "(docs/validation.md) and the noise levels the diagnosis used.")
    ap.add_argument("results", nargs="+", metavar="RESULT.json", help="a suite's --json result")
    ap.add_argument("--pool", action="store_true", help="a last line with the numbers of every file's logs together")
    args = ap.parse_args(argv)
    paths = args.results
    pooled: list[dict] = []
    for path in paths:
        with open(path) as fh:
            rows = json.load(fh)["logs"]
        try:
            q = quarter_car_numbers(rows)
        except ValueError as exc:
            print(f"{path}: {exc}", file=sys.stderr)
            return 2
        pooled += rows
        print(format_numbers(q, f"{path}: "))
        levels = noise_levels(rows)
        if levels:
            print(format_noise(levels, f"{path}: "))
    if args.pool:
        print(format_numbers(quarter_car_numbers(pooled), f"{len(paths)} files pooled: "))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
