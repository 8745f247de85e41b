"""RtkOptions: defaults, validation, and the TOML key → field table (units converted, unknown keys refused)."""

from __future__ import annotations

import tomllib

import pytest

from onboard.rtk.options import RtkOptions, options_from_mapping


def test_defaults_are_rtklib_like_for_l1_drones():
    o = RtkOptions()
    assert o.elmask_deg == 15.0 and o.ratio_threshold == 3.0 and o.ar_mode == "fix-and-hold"


def test_toml_table_converts_units_at_the_boundary():
    table = tomllib.loads('elevation_mask_deg = 10\nphase_sigma_mm = 4\nar_mode = "continuous"\n')
    o = options_from_mapping(table)
    assert o.elmask_deg == 10.0 and o.phase_sigma_a_m == pytest.approx(0.004) and o.ar_mode == "continuous"


def test_unknown_key_is_an_error_naming_it():
    with pytest.raises(ValueError, match="elmask"):
        options_from_mapping({"elmask": 10})


@pytest.mark.parametrize("bad", [{"ar_mode": "sometimes"}, {"elevation_mask_deg": 95}, {"ratio_threshold": 0.5},
                                 {"code_cn0_ref_dbhz": -1.0}, {"code_cn0_ref_dbhz": float("nan")},
                                 {"code_cn0_ref_dbhz": 90.0}])
def test_bad_values_are_refused(bad):
    with pytest.raises(ValueError):
        options_from_mapping(bad)
