"""Odd logs (tests/odd_logs.py): each gets a verdict or a one-line error naming its file, never a crash."""

import numpy as np
import pytest

from tests.odd_logs import ODD_KINDS, diagnose_odd, write_odd_log


@pytest.mark.parametrize("kind", sorted(ODD_KINDS))
def test_an_odd_log_gets_a_verdict_or_an_error_naming_its_file(tmp_path, kind):
    path = str(tmp_path / f"{kind}.csv")
    write_odd_log(path, kind, np.random.default_rng(7), rate_hz=25.0, optional=True)
    result = diagnose_odd(path)
    assert not result.startswith("crash"), result
    if kind == "huge_torque":  # 80 kN m: not a torque in N m
        assert result.startswith("rejected") and "column 'T_b'" in result


def test_diagnose_odd_calls_anything_but_a_clear_rejection_a_crash(tmp_path, monkeypatch):
    import fricenv.gap.quarter_car.diagnose as dg

    path = str(tmp_path / "x.csv")

    def raising(exc):
        def f(*args, **kwargs):
            raise exc
        return f

    monkeypatch.setattr(dg, "diagnose_file", raising(ValueError(f"{path}: log too short")))
    assert diagnose_odd(path).startswith("rejected")
    monkeypatch.setattr(dg, "diagnose_file", raising(ValueError("attempt to get argmin of an empty sequence")))
    assert diagnose_odd(path).startswith("crash")
    monkeypatch.setattr(dg, "diagnose_file", raising(IndexError("index 3 is out of bounds")))
    assert diagnose_odd(path).startswith("crash")
