"""Values from users, checked once, one way: numbers, ranges, coordinates, ports, sizes (shared vocabulary).

Every command line (as argparse `type=` functions through `arg_type`), the recorder's settings and the ground
API's schemas check their values with these functions, so a value is refused with the same words everywhere:
`<name> <value>: must be <rule>` with the unit, e.g. `--elmask 95: must be 0–90°`. Each raises `ValueError`
(argparse turns it into a usage error, exit 2; the settings into a `ConfigFileError`; pydantic into a 422).
Pure: no I/O.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")

EARTH_RADIUS_MIN_M = 6.0e6
"""An ECEF position nearer the Earth's centre than this is no place on its surface (the Dead Sea is at 6.35e6 m)."""
EARTH_RADIUS_MAX_M = 6.5e6
"""Nor one farther than this (a drone or a base is within a few km of the ellipsoid; the ISS flies at 6.8e6 m)."""


def _label(name: str | None, value: Any) -> str:
    shown = value if isinstance(value, str) else repr(value)
    return f"{name} {shown}" if name else f"{shown}"


def _fmt(x: float) -> str:
    return f"{x:g}"


def number(value: Any, *, name: str | None = None, unit: str = "", minimum: float | None = None,
           maximum: float | None = None, exclusive_minimum: bool = False, integer: bool = False) -> float:
    """`value` (a number or its text) as a finite float within [minimum, maximum] (`exclusive_minimum`: > minimum).

    `unit` is appended to the rule as written ("°", " m", " s", " MiB"). Raises ValueError
    `"<name> <value>: must be ..."`."""
    label = _label(name, value)
    if isinstance(value, bool):
        raise ValueError(f"{label}: must be a number")  # noqa: TRY004 (one error type for every bad value)
    try:
        x = float(value.strip()) if isinstance(value, str) else float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{label}: must be a number{(' in' + unit) if unit.startswith(' ') else ''}") from None
    if not math.isfinite(x):
        raise ValueError(f"{label}: must be a finite number")
    if integer and x != int(x):
        raise ValueError(f"{label}: must be a whole number")
    low_ok = minimum is None or (x > minimum if exclusive_minimum else x >= minimum)
    high_ok = maximum is None or x <= maximum
    if not (low_ok and high_ok):
        if minimum is not None and maximum is not None and not exclusive_minimum:
            rule = f"{_fmt(minimum)}–{_fmt(maximum)}{unit}"
        elif minimum is not None and maximum is not None:
            rule = f"> {_fmt(minimum)} and ≤ {_fmt(maximum)}{unit}"
        elif minimum is not None:
            rule = f"{'>' if exclusive_minimum else '≥'} {_fmt(minimum)}{unit}"
        else:
            rule = f"≤ {_fmt(maximum)}{unit}"  # type: ignore[arg-type]
        raise ValueError(f"{label}: must be {rule}")
    return x


def integer(value: Any, *, name: str | None = None, unit: str = "", minimum: int | None = None,
            maximum: int | None = None) -> int:
    """`value` as an int within [minimum, maximum] (see `number`)."""
    return int(number(value, name=name, unit=unit, minimum=minimum, maximum=maximum, integer=True))


def positive(value: Any, *, name: str | None = None, unit: str = "", maximum: float | None = None) -> float:
    """A finite number > 0 (durations, sizes, rates)."""
    return number(value, name=name, unit=unit, minimum=0.0, exclusive_minimum=True, maximum=maximum)


def elevation_mask_deg(value: Any, *, name: str | None = "elevation mask") -> float:
    """An elevation mask, degrees above the horizon: 0–90°."""
    return number(value, name=name, unit="°", minimum=0.0, maximum=90.0)


GNSS_SYSTEM_LETTERS = "GRECJ"
"""RINEX system letters the RTK engine uses: GPS, GLONASS, Galileo, BeiDou, QZSS."""


def gnss_systems(value: Any, *, name: str | None = "systems") -> str:
    """Constellations as RINEX letters of G R E C J (GPS, GLONASS, Galileo, BeiDou, QZSS), upper-cased, in the
    given order, repeats dropped: e.g. 'gr' → 'GR'."""
    letters = "".join(dict.fromkeys(value.strip().upper())) if isinstance(value, str) else ""
    if not letters or set(letters) - set(GNSS_SYSTEM_LETTERS):
        raise ValueError(f"{_label(name, value)}: must be letters of G, R, E, C, J (GPS, GLONASS, Galileo, BeiDou, "
                         "QZSS)")
    return letters


def tcp_port(value: Any, *, name: str | None = "port") -> int:
    """A TCP/UDP port number 1–65535."""
    return integer(value, name=name, minimum=1, maximum=65535)


def http_url(value: Any, *, name: str | None = None) -> str:
    """An http:// or https:// URL with a host (e.g. http://ground:8600), returned as given."""
    from urllib.parse import urlsplit

    text = value if isinstance(value, str) else ""
    try:
        parts = urlsplit(text)
        parts.port  # noqa: B018 (raises ValueError on a bad port)
    except ValueError:
        parts = None
    if parts is None or parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"{_label(name, value)}: must be an http:// or https:// URL with a host, "
                         "e.g. http://ground:8600")
    return text


def vector3(value: Any, *, name: str | None = None, unit: str = " m", max_abs: float | None = None,
            what: str = "X,Y,Z") -> tuple[float, float, float]:
    """Three finite numbers from "X,Y,Z" (spaces also separate), or a sequence of three; each |v| ≤ `max_abs`."""
    label = _label(name, value if isinstance(value, str) else ",".join(str(v) for v in value))
    if isinstance(value, str):
        parts = [p for p in value.replace(" ", ",").split(",") if p]
    else:
        parts = list(value)
    if len(parts) != 3:
        raise ValueError(f"{label}: must be {what} (three numbers{', in' + unit if unit.strip() else ''})")
    out = []
    for p in parts:
        try:
            out.append(number(p, name=None, unit=unit, minimum=None if max_abs is None else -max_abs,
                              maximum=max_abs))
        except ValueError as exc:
            raise ValueError(f"{label}: {str(exc).split(': ', 1)[1]} (each of {what})") from None
    return out[0], out[1], out[2]


def ecef_position_m(value: Any, *, name: str | None = None) -> tuple[float, float, float]:
    """An ECEF position X,Y,Z in metres on or near the Earth's surface (|r| 6000–6500 km)."""
    xyz = vector3(value, name=name, unit=" m", what="X,Y,Z in ECEF metres")
    r = math.sqrt(sum(v * v for v in xyz))
    if not EARTH_RADIUS_MIN_M <= r <= EARTH_RADIUS_MAX_M:
        label = _label(name, value if isinstance(value, str) else ",".join(str(v) for v in value))
        raise ValueError(f"{label}: must be X,Y,Z in ECEF metres near the Earth's surface (|r| = {r / 1e3:.0f} km, "
                         f"not {EARTH_RADIUS_MIN_M / 1e3:.0f}–{EARTH_RADIUS_MAX_M / 1e3:.0f} km)")
    return xyz


def lever_arm_m(value: Any, *, name: str | None = None, max_abs_m: float = 5.0) -> tuple[float, float, float]:
    """A camera–antenna lever arm dx,dy,dz in metres, each within ±`max_abs_m` (a drone is not larger)."""
    return vector3(value, name=name, unit=" m", max_abs=max_abs_m, what="dx,dy,dz in metres")


def arg_type(check: Callable[..., T], **kwargs: Any) -> Callable[[str], T]:
    """An argparse `type=` function from a check above: its ValueError becomes a usage error naming the option
    (argparse prefixes "argument --name: "), so `name` is not repeated in the message."""

    def convert(text: str) -> T:
        try:
            return check(text, name=None, **kwargs)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = getattr(check, "__name__", "value")
    return convert
