"""Pure upload rules: any name either is refused or stays a plain file inside the flight directory, sub-folders
included (fuzzed), and the chunk acceptance table."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ground.api.routes.flights import partial_path, safe_path
from ground.api.settings import ApiSettings
from ground.api.upload import (
    Limits,
    UploadRejected,
    check_chunk,
    check_file_name,
    check_file_path,
    check_manifest_files,
)

SETTINGS = ApiSettings(data_dir=Path("/srv/directgeo"), token="x" * 16)
LIMITS = Limits(max_file_bytes=1000, max_flight_bytes=1500, max_chunk_bytes=100, max_files_per_flight=3)


@pytest.mark.slow
@settings(max_examples=500, deadline=None)
@given(st.lists(st.sampled_from([*"ab./\\:\x00 -_+~$*?\n", "..", "é", "\u202e", "%2e"]), max_size=12).map("".join))
def test_any_accepted_name_stays_inside_the_flight_dir(name: str) -> None:
    try:
        p = safe_path(SETTINGS, "f1", name)
    except UploadRejected as exc:
        assert exc.status == 400
        return
    base = (SETTINGS.flights_dir / "f1").resolve()
    assert p.is_relative_to(base) and p.relative_to(base).as_posix() == name
    assert not any(part.startswith(".") for part in p.relative_to(base).parts)
    assert partial_path(p).parent.name == ".partial" and partial_path(p).parent.parent == p.parent


@pytest.mark.parametrize("name", ["000001.ubx", "events.jsonl", "SOL.pos", "IMG_0001.JPG", "a+b-c_d.txt"])
def test_ordinary_names_accepted(name: str) -> None:
    assert check_file_name(name) == name
    assert check_file_path(name) == name


@pytest.mark.parametrize("name", ["radio/000000.ubx", "radio/manifest.json", "a/b/c/d.txt"])
def test_sub_folder_names_accepted_as_paths_only(name: str) -> None:
    """A flight file may live in a sub-folder (the radio/ journal); a flight's own name stays one component."""
    assert check_file_path(name) == name
    p = safe_path(SETTINGS, "f1", name)
    assert p == (SETTINGS.flights_dir / "f1").resolve() / name
    with pytest.raises(UploadRejected):
        check_file_name(name)


@pytest.mark.parametrize("name", ["radio/../x.ubx", "radio/./x.ubx", "radio//x.ubx", "radio/", "/radio/x.ubx",
                                  "radio/.partial/x.ubx", ".partial/x", "radio\\x.ubx", "a/b/c/d/e.txt",
                                  "radio/x:y", "radio/\x00", "x" * 150 + "/" + "y" * 150])
def test_traversing_or_odd_paths_refused(name: str) -> None:
    with pytest.raises(UploadRejected) as info:
        safe_path(SETTINGS, "f1", name)
    assert info.value.status == 400


def test_a_file_cannot_also_be_a_folder() -> None:
    sha = "a" * 64
    check_manifest_files([("radio/000000.ubx", 1, sha), ("radio/manifest.json", 1, sha)], LIMITS)
    with pytest.raises(UploadRejected, match="also the folder") as info:
        check_manifest_files([("radio", 1, sha), ("radio/000000.ubx", 1, sha)], LIMITS)
    assert info.value.status == 400


@pytest.mark.parametrize(
    ("offset", "received", "length", "size", "status"),
    [(0, 0, 101, 1000, 413), (10, 0, 10, 1000, 409), (990, 990, 20, 1000, 413), (0, 5, 5, 1000, 409)],
)
def test_chunk_table(offset: int, received: int, length: int, size: int, status: int) -> None:
    with pytest.raises(UploadRejected) as info:
        check_chunk(offset, received, length, size, LIMITS)
    assert info.value.status == status


def test_chunk_accepted_and_manifest_limits() -> None:
    check_chunk(990, 990, 10, 1000, LIMITS)
    sha = "a" * 64
    check_manifest_files([("a", 1000, sha), ("b", 500, sha)], LIMITS)
    for files, status in (([("a", 1001, sha)], 413), ([("a", 800, sha), ("b", 800, sha)], 413),
                          ([("a", 1, sha)] * 2, 400), ([(str(i), 1, sha) for i in range(4)], 413), ([], 400),
                          ([("a", 1, "A" * 63)], 400)):
        with pytest.raises(UploadRejected) as info:
            check_manifest_files(files, LIMITS)
        assert info.value.status == status
