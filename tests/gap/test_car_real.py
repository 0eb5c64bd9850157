"""The racecar session end to end (validation/realcar.py): ``gap diagnose`` on the export with the committed column
map finds every braking event, names an effect set that halves the held-out gap, finds the mapped wheel's radius
within 0.3 % of its free-rolling figure, in 60 s or less. Skips when the export (GPL-3.0 data, kept out of the
repository) is absent."""

import pytest

from validation import realcar


@pytest.mark.slow
def test_racecar_session_meets_its_targets(tmp_path):
    export = realcar.default_export()
    if export is None:
        pytest.skip("the racecar export is not beside the repository (../shared/realdata/av21)")
    res = realcar.run(export, tmp_path)
    assert "error" not in res, res.get("error")
    assert res["checks"] == {"events": True, "ratio": True, "radius": True, "seconds": True}, res


@pytest.mark.slow
def test_a_braking_zone_ending_in_a_turn_in_is_diagnosed_on_its_straight_part(tmp_path):
    """The export with its longest braking event turning in over its last 1.5 s (yaw rate set to 9 m/s^2 of lateral
    acceleration from 427 s), as a road course's braking zone ends: the straight part is diagnosed."""
    import numpy as np

    export = realcar.default_export()
    if export is None:
        pytest.skip("the racecar export is not beside the repository (../shared/realdata/av21)")
    header = export.read_text(encoding="utf-8").splitlines()[0]
    table = np.loadtxt(export, delimiter=",", comments="#")
    names = [h.split("(")[0].strip() for h in header.lstrip("#").strip().split(",")]
    t = table[:, 0] - table[0, 0]
    turn = (t >= 427.0) & (t <= 429.0)
    table[turn, names.index("omega")] = 9.0 / np.maximum(table[turn, names.index("vx")], 1.0)
    variant = tmp_path / "turn_in.csv"
    np.savetxt(variant, table, delimiter=",", header=header.lstrip("#").strip(), comments="# ", fmt="%.17g")
    res = realcar.run(variant, tmp_path / "out")
    assert "error" not in res, res.get("error")
    assert res["checks"] == {"events": True, "ratio": True, "radius": True, "seconds": True}, res
    assert res["events_found"][0][1] < 427.0 <= res["events_reference"][0][1]
