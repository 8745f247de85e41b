"""Property: whatever value a numeric settings key is given (non-finite, huge, negative, of the wrong type,
unicode text), from the TOML file, the environment or the command line, `load_settings` either accepts it as a
finite number of the key's type or raises ConfigFileError naming the key; never another exception.

Examples drawn: 50 per key (max_examples=50), over every numeric key of the recorder, of [receiver] and of
[rtk.engine] (47 keys today: 2350 examples, ~30 s here)."""

from __future__ import annotations

import dataclasses
import math
import tempfile
import typing
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.errors import ConfigFileError
from onboard.receiver.profiles import ReceiverOptions
from onboard.recorder.settings import KEYS, RTK_ENGINE, Settings, load_settings
from onboard.rtk.options import TOML_KEYS

_SETTINGS_TYPES = typing.get_type_hints(Settings)


def _numeric_keys() -> dict[str, type]:
    """Every numeric key → int or float (what an accepted value must be)."""
    keys: dict[str, type] = {k: _SETTINGS_TYPES[f] for k, f in KEYS.items() if _SETTINGS_TYPES[f] in (int, float)}
    for f in dataclasses.fields(ReceiverOptions):
        if type(f.default) in (int, float):
            keys[f"receiver.{f.name}"] = type(f.default)
    for key, (_, conv) in TOML_KEYS.items():
        if conv not in (bool, str):
            keys[RTK_ENGINE + key] = int if conv is int else float
    return keys


NUMERIC = _numeric_keys()

text = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12)  # TOML cannot hold surrogates
scalars = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),  # TOML's integers are 64-bit
    st.sampled_from([1e308, -1e308, 5e-324, 0.0, -0.0, 2**53 + 1, -1]),
    st.booleans(),
    text,
    st.floats(allow_nan=True, allow_infinity=True).map(repr),  # numbers as text: "nan", "1e+300"
)
values = st.one_of(scalars, st.lists(scalars, max_size=3),
                   st.dictionaries(st.from_regex(r"[a-z]{1,5}", fullmatch=True), scalars, max_size=2))


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):  # a TOML basic string: quote, backslash and control characters escaped
        return '"' + "".join(f"\\u{ord(c):04x}" if c in '"\\' or ord(c) < 0x20 or ord(c) == 0x7F else c
                             for c in value) + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"


def _load(key: str, value: Any, source: str) -> Settings:
    section, _, name = key.rpartition(".")
    if source == "file":
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "recorder.toml"
            path.write_text(f"[{section}]\n{name} = {_toml(value)}\n", encoding="utf-8")
            return load_settings(path, environ={})
    if source == "environment":
        if not isinstance(value, str):
            value = _toml(value) if not isinstance(value, float) else repr(value)
        if "\x00" in value:  # no environment can hold a NUL
            value = value.replace("\x00", "")
        return load_settings(None, environ={"ONBOARD_" + key.upper().replace(".", "_"): value})
    return load_settings(None, environ={}, overrides={key: value})


def _accepted(s: Settings, key: str) -> Any:
    if key in KEYS:
        return getattr(s, KEYS[key])
    if key.startswith(RTK_ENGINE):
        return s.rtk_engine[key[len(RTK_ENGINE):]]
    return s.receiver_options[key.split(".", 1)[1]]


@pytest.mark.parametrize("key", sorted(NUMERIC))
@settings(max_examples=50, deadline=None)
@given(value=values, source=st.sampled_from(["file", "environment", "command line"]))
def test_numeric_key_accepts_a_number_or_names_itself(key: str, value: Any, source: str) -> None:
    try:
        s = _load(key, value, source)
    except ConfigFileError as exc:
        assert key in str(exc) or key.replace(".", "_").upper() in str(exc), str(exc)
        return
    got = _accepted(s, key)
    assert type(got) is NUMERIC[key], (key, value, got)
    assert math.isfinite(got), (key, value, got)
    assert not isinstance(value, (bool, list, dict)), (key, value)


def test_every_numeric_key_is_drawn() -> None:
    """The key list follows the code: the recorder's, the receiver's and the RTK engine's numeric options."""
    assert {"journal.segment_max_mb", "port.baud", "gpio.pps_pin", "receiver.meas_rate_ms",
            "receiver.camera_period_s", RTK_ENGINE + "ratio_threshold"} <= set(NUMERIC)
    assert len(NUMERIC) >= 40
