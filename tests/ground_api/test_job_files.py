"""Which flight files a job reads (pure): a role's journal segments are read as their folder (a drone's flight:
its own journal at the top, the radio/ corrections), a named folder must hold segments, other ambiguities are
refused with a message."""

from __future__ import annotations

import pytest

from ground.api.job_kinds import check_job
from onboard.errors import InputError

DRONE = {"000000.ubx": "rover_obs", "000001.ubx": "rover_obs", "000000.idx": "index", "events.jsonl": "events",
         "radio/000000.ubx": "base_obs", "radio/manifest.json": "manifest", "solution.pos": "realtime_trajectory"}


def test_a_drone_flight_needs_no_file_names() -> None:
    check_job("rtk", {}, DRONE)
    check_job("rtk", {"rover_obs": ".", "base_obs": "radio", "static_start": True}, DRONE)
    check_job("rtk", {"base_obs": "radio/000000.ubx"}, DRONE)  # one segment by its name: that file


@pytest.mark.parametrize(("files", "params", "message"), [
    (DRONE, {"base_obs": "nowhere"}, "'nowhere' is not a completely uploaded file"),
    (DRONE, {"rover_obs": "radio/manifest.json/x"}, "is not a completely uploaded file"),
    ({**DRONE, "office/rover.ubx": "rover_obs"}, {}, "several files have role 'rover_obs'"),  # not one journal
    ({**DRONE, "old/000000.ubx": "rover_obs"}, {}, "several files have role 'rover_obs'"),  # two journals
    ({k: v for k, v in DRONE.items() if not k.startswith("radio/")}, {}, "needs uploaded base_obs"),
    (DRONE, {"static_start": "yes please"}, "static_start"),
])
def test_ambiguous_or_missing_inputs_are_refused(files: dict[str, str | None], params: dict[str, object],
                                                 message: str) -> None:
    with pytest.raises(InputError, match=message):
        check_job("rtk", params, files)


def test_the_real_time_solution_is_no_trajectory_unless_named() -> None:
    """An adjustment without orientations is refused; solution.pos is not taken for the trajectory by role."""
    with pytest.raises(InputError, match="missing uploaded orientations"):
        check_job("adjust", {}, DRONE)
    office = {**DRONE, "images.txt": "orientations"}
    check_job("adjust", {}, office)  # the RTK job's output will be the trajectory (rover + base uploaded)
    check_job("adjust", {"trajectory": "solution.pos"}, office)
