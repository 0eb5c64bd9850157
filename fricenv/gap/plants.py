"""The plant registry of the gap tool: what a command or the fleet needs of a plant's diagnosis, by plant name.

Each entry adapts one plant subpackage (:mod:`fricenv.gap.quarter_car`, :mod:`fricenv.gap.payload`) to one calling
convention; the subpackages are imported only when an entry is used, so ``import fricenv.gap.plants`` is cheap.
A new plant is a new subpackage and one entry here: no caller branches on the plant's name.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["GAP_PLANTS", "GapPlant", "get_plant"]


@dataclass(frozen=True)
class GapPlant:
    """One plant's diagnosis, report and validation behind one calling convention.

    :param name: the plant's name on the command line and in report.json (``plant``).
    :param make_config: ``(candidates or None, jobs or None) -> config``: the diagnosis settings.
    :param diagnose_file: ``(log path, params file or None, config) -> diagnosis``.
    :param write_report: ``(diagnosis, out dir, plots) -> report dict`` (report.json, report.md, plots).
    :param summary_line: ``diagnosis -> str``: the one-line summary the command prints.
    :param validate: ``(n, seed, jobs, ray, required_only_share) -> (summary dict, printable text)``.
    :param parallel_fits: whether the diagnosis uses ``--jobs`` worker processes for its fits.
    """

    name: str
    make_config: Callable[[Sequence[str] | None, int | None], Any]
    diagnose_file: Callable[..., Any]
    write_report: Callable[..., dict]
    summary_line: Callable[[Any], str]
    validate: Callable[..., tuple[dict, str]]
    parallel_fits: bool


def _qc_config(candidates, jobs):
    from fricenv.gap.quarter_car.config import DiagnoseConfig

    kwargs = {} if candidates is None else {"candidates": tuple(candidates)}
    return DiagnoseConfig(**kwargs) if jobs is None else DiagnoseConfig(jobs=jobs, **kwargs)


def _qc_diagnose(path, params_file, cfg):
    """A quarter-car log, read once; a car's session (fricenv.gap.car) is diagnosed across its braking events."""
    from fricenv.gap.car.entry import diagnose_car_log
    from fricenv.gap.quarter_car.diagnose import diagnose, load_params
    from fricenv.logs import read_log
    from fricenv.plants.quarter_car import PAPER_PARAMS

    log = read_log(path, "quarter-car")
    session = diagnose_car_log(log, params_file, candidates=cfg.candidates)
    if session is not None:
        return session
    return diagnose(log, load_params(params_file) if params_file is not None else PAPER_PARAMS, cfg)


def _qc_report(dg, out, plots: bool = True) -> dict:
    from fricenv.gap.car.entry import is_session_diagnosis
    from fricenv.gap.quarter_car.report import write_report

    if is_session_diagnosis(dg):
        from fricenv.gap.car.report import write_session_report

        return write_session_report(dg, out, "quarter-car", plots=plots)
    return write_report(dg, out, "quarter-car", plots=plots)


def _qc_summary(dg) -> str:
    from fricenv.gap.car.entry import is_session_diagnosis
    from fricenv.gap.quarter_car.report import summary_line

    if is_session_diagnosis(dg):
        from fricenv.gap.car.report import summary_line as session_line

        return session_line(dg)
    return summary_line(dg)


def _qc_validate(n, seed, jobs, ray, required_only_share):
    from fricenv.gap.quarter_car.validate import format_summary, validate

    summary = validate(n, seed, jobs=jobs, drop_optional_share=required_only_share, ray=ray)
    return summary, format_summary(summary)


def _payload_config(candidates, jobs):
    from fricenv.gap.payload.diagnose import PayloadDiagnoseConfig

    return PayloadDiagnoseConfig() if candidates is None else PayloadDiagnoseConfig(candidates=tuple(candidates))


def _payload_diagnose(path, params_file, cfg):
    from fricenv.gap.payload.diagnose import diagnose_payload_file

    return diagnose_payload_file(path, params_file, cfg)


def _payload_report(dg, out, plots: bool = True) -> dict:
    from fricenv.gap.payload.report import write_payload_report

    return write_payload_report(dg, out, plots=plots)


def _payload_summary(dg) -> str:
    from fricenv.gap.payload.diagnose import summary_line

    return summary_line(dg)


def _payload_validate(n, seed, jobs, ray, required_only_share):
    from fricenv.errors import InvalidInputError
    from fricenv.gap.payload.validate import format_payload_summary, validate_payload

    if ray is not None:
        raise InvalidInputError("--ray applies to --plant quarter-car (the payload validation runs in one process)")
    summary = validate_payload(n, seed)
    return summary, format_payload_summary(summary)


GAP_PLANTS: dict[str, GapPlant] = {
    "quarter-car": GapPlant("quarter-car", _qc_config, _qc_diagnose, _qc_report, _qc_summary, _qc_validate, True),
    "payload": GapPlant("payload", _payload_config, _payload_diagnose, _payload_report, _payload_summary,
                        _payload_validate, False),
}


def get_plant(name: str) -> GapPlant:
    """The registry entry of plant ``name``; an unknown name is a ``ValueError`` listing the valid ones."""
    try:
        return GAP_PLANTS[name]
    except KeyError:
        raise ValueError(f"unknown plant {name!r}; valid plants: {', '.join(GAP_PLANTS)}") from None
