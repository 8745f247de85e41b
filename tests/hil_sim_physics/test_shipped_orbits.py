"""The simulator's broadcast orbits ship with the package, each with its provenance, licence and checksum."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import hil_sim
from hil_sim.scenario import DATA_DIR, DEFAULT_NAV_PATH, Scenario
from hil_sim.world import World

PACKAGE = Path(hil_sim.__file__).resolve().parent


def test_default_world_reads_the_orbits_shipped_inside_the_package() -> None:
    assert DEFAULT_NAV_PATH.is_relative_to(PACKAGE) and DEFAULT_NAV_PATH.is_file()
    assert Scenario.default().nav_path == DEFAULT_NAV_PATH
    assert len(World(Scenario.default(duration_s=60.0)).prns) >= 8  # GPS satellites with a valid ephemeris


def test_every_shipped_file_is_in_the_notice_with_its_checksum_and_licence() -> None:
    notice = (DATA_DIR / "NOTICE.md").read_text(encoding="utf-8")
    listed = {name: digest for digest, name in re.findall(r"^\s+([0-9a-f]{64})  (\S+)$", notice, re.MULTILINE)}
    shipped = sorted(p for p in DATA_DIR.rglob("*") if p.is_file() and p.name != "NOTICE.md")
    assert shipped, "no orbit file shipped"
    assert sorted(listed) == sorted(str(p.relative_to(DATA_DIR)) for p in shipped)
    for path in shipped:
        rel = str(path.relative_to(DATA_DIR))
        assert hashlib.sha256(path.read_bytes()).hexdigest() == listed[rel], f"{rel} differs from its provenance"
        row = next(line for line in notice.splitlines() if line.startswith(f"| `{rel}`"))
        assert "BSD 2-Clause" in row or "MIT" in row, row
    assert "Copyright (c) 2007-2013, T. Takasu" in notice
