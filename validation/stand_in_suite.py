"""The library stand-in's blind suite (the logs of ``fricenv gap validate``) with the oracle of what each log's data
show (:mod:`validation.quarter_car_oracle`, at the noise levels the stand-in drew: whether they show the effect, and
whether they tell it from the best other library effect; on an out-of-library log, whether its noise-free truth
beats the nominal model) and the numbers of :mod:`validation.scores`.

``fricenv gap validate`` draws the same logs for the same seed and scores its verdicts; this command adds the
oracle, which lives here, outside the library.

Command::

    python -m validation.stand_in_suite --n 60 --seed 9022 --jobs 2 [--json P]
"""

from __future__ import annotations

from collections.abc import Sequence

from validation.measure_cli import measurement_parser

__all__ = ["main", "measure", "out_of_library_oracle"]


def out_of_library_oracle(truth: dict, dg, cfg, noise: dict[str, float]) -> dict:
    """The oracle of an out-of-library stand-in log: ``truth_shown``, whether the stand-in's noise-free truth on the
    log's rows beats the tool's nominal model at the drawn noise (:func:`validation.report_check.truth_shown`, as
    for the independent simulator's logs)."""
    from validation.report_check import truth_shown

    return {"truth_shown": truth_shown(truth, dg, cfg, noise)}


def measure(n: int, seed: int, jobs: int = 1, required_only_share: float = 0.0) -> dict:
    """The stand-in suite (:func:`fricenv.gap.quarter_car.validate.validate`) with the oracle on every effect log
    and the three numbers under ``"scores"``."""
    from fricenv.gap.quarter_car.validate import validate
    from validation.quarter_car_oracle import effect_oracle
    from validation.scores import quarter_car_numbers

    s = validate(n, seed, jobs=jobs, drop_optional_share=required_only_share, show_progress=False,
                 oracle=effect_oracle, truth_oracle=out_of_library_oracle)
    s["scores"] = quarter_car_numbers(s["logs"])
    s["source"] = "validation.stand_in_suite"
    return s


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m validation.stand_in_suite --n 60 --seed 9022 --jobs 2 [--json P]``."""
    ap = measurement_parser("The library stand-in's blind suite, scored against what the data show.", n=60,
                            seed=9022)
    ap.add_argument("--required-only-share", type=float, default=0.0,
                    help="share of logs written with t, T_b and omega only")
    args = ap.parse_args(argv)
    from fricenv.gap.quarter_car.validate import format_summary
    from fricenv.utils import write_json
    from validation.scores import format_numbers

    s = measure(args.n, args.seed, args.jobs, args.required_only_share)
    print(format_summary(s))
    print(format_numbers(s["scores"]))
    if args.json:
        write_json(args.json, s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
