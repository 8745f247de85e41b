"""Recorder settings: one frozen dataclass, layered package defaults → TOML file → `ONBOARD_*` env → CLI flags.

Keys are `section.key` names in the TOML file (documented, every key commented, in
`onboard/recorder/default_config.toml`); the environment spells them `ONBOARD_SECTION_KEY`
(e.g. `ONBOARD_PORT_DEVICE=/dev/ttyACM0`). The `[receiver]` section takes, besides `model` and `configure`,
every field of `onboard.receiver.profiles.ReceiverOptions` by its name; `[rtk.engine]` the RTK engine's options
by their TOML names (`onboard.rtk.options.TOML_KEYS`; environment `ONBOARD_RTK_ENGINE_<KEY>`). Unknown keys and
bad values raise `ConfigFileError` naming the key.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from onboard import validate as check
from onboard.errors import ConfigFileError
from onboard.recorder.status import DEFAULT_STATUS_PATH, STALE_AFTER_S

ENV_PREFIX = "ONBOARD_"


@dataclass(frozen=True, slots=True)
class Settings:
    """Everything the recorder daemon is configured with (units in names; see default_config.toml)."""

    port_device: str = "/dev/ttyAMA0"
    port_baud: int = 115200
    port_read_timeout_s: float = 0.1
    port_reopen_min_s: float = 0.5
    port_reopen_max_s: float = 10.0
    receiver_model: str = "auto"
    receiver_configure: bool = True
    receiver_options: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    data_dir: Path = Path("/var/lib/directgeo")
    journal_sync_interval_s: float = 0.5
    journal_segment_max_mb: float = 64.0
    journal_segment_max_s: float = 3600.0
    disk_floor_mb: float = 200.0
    disk_check_interval_s: float = 1.0
    status_path: Path = DEFAULT_STATUS_PATH
    status_interval_s: float = 1.0
    watchdog_writer_stall_s: float = 10.0
    gpio_trigger_pin: int = -1
    gpio_pps_pin: int = -1
    gpio_flash_pin: int = -1
    gpio_pin_factory: str = "lgpio"
    rtk_base_stream: str = ""
    rtk_max_base_age_s: float = 30.0
    rtk_preflight_base_timeout_s: float = 10.0
    rtk_takeoff_position: str = ""
    rtk_engine: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    """`[rtk.engine]`: RTK engine options by their TOML names (onboard.rtk.options.TOML_KEYS)."""
    autopilot_link: str = ""
    autopilot_system_id: int = 0
    autopilot_fast_interval_s: float = 0.25
    autopilot_slow_interval_s: float = 1.0
    autopilot_link_timeout_s: float = 3.0
    autopilot_rerequest_s: float = 5.0
    autopilot_settle_s: float = 20.0
    upload_url: str = ""
    upload_token_file: str = ""
    upload_delete_after_upload: bool = False
    upload_chunk_mib: float = 4.0
    upload_backoff_min_s: float = 5.0
    upload_backoff_max_s: float = 300.0
    upload_poll_s: float = 5.0
    base_observations: str = "msm4"
    base_budget_bytes_s: float = 1000.0
    base_obs_interval_s: float = 1.0
    base_position_interval_s: float = 10.0
    base_ephemeris_interval_s: float = 30.0
    base_glonass_bias_interval_s: float = 10.0
    base_receiver_descriptor: str = "auto"


RTK_ENGINE = "rtk.engine."
"""Prefix of the RTK engine's option keys: `rtk.engine.<onboard.rtk.options.TOML_KEYS key>`."""

# TOML key -> Settings field. `receiver.<ReceiverOptions field>` keys are handled separately.
KEYS: Mapping[str, str] = MappingProxyType(
    {
        "port.device": "port_device",
        "port.baud": "port_baud",
        "port.read_timeout_s": "port_read_timeout_s",
        "port.reopen_min_s": "port_reopen_min_s",
        "port.reopen_max_s": "port_reopen_max_s",
        "receiver.model": "receiver_model",
        "receiver.configure": "receiver_configure",
        "journal.data_dir": "data_dir",
        "journal.sync_interval_s": "journal_sync_interval_s",
        "journal.segment_max_mb": "journal_segment_max_mb",
        "journal.segment_max_s": "journal_segment_max_s",
        "journal.disk_floor_mb": "disk_floor_mb",
        "journal.disk_check_interval_s": "disk_check_interval_s",
        "status.path": "status_path",
        "status.interval_s": "status_interval_s",
        "watchdog.writer_stall_s": "watchdog_writer_stall_s",
        "gpio.trigger_pin": "gpio_trigger_pin",
        "gpio.pps_pin": "gpio_pps_pin",
        "gpio.flash_pin": "gpio_flash_pin",
        "gpio.pin_factory": "gpio_pin_factory",
        "rtk.base_stream": "rtk_base_stream",
        "rtk.max_base_age_s": "rtk_max_base_age_s",
        "rtk.preflight_base_timeout_s": "rtk_preflight_base_timeout_s",
        "rtk.takeoff_position": "rtk_takeoff_position",
        "autopilot.link": "autopilot_link",
        "autopilot.system_id": "autopilot_system_id",
        "autopilot.fast_interval_s": "autopilot_fast_interval_s",
        "autopilot.slow_interval_s": "autopilot_slow_interval_s",
        "autopilot.link_timeout_s": "autopilot_link_timeout_s",
        "autopilot.rerequest_s": "autopilot_rerequest_s",
        "autopilot.settle_s": "autopilot_settle_s",
        "upload.url": "upload_url",
        "upload.token_file": "upload_token_file",
        "upload.delete_after_upload": "upload_delete_after_upload",
        "upload.chunk_mib": "upload_chunk_mib",
        "upload.backoff_min_s": "upload_backoff_min_s",
        "upload.backoff_max_s": "upload_backoff_max_s",
        "upload.poll_s": "upload_poll_s",
        "base.observations": "base_observations",
        "base.budget_bytes_s": "base_budget_bytes_s",
        "base.obs_interval_s": "base_obs_interval_s",
        "base.position_interval_s": "base_position_interval_s",
        "base.ephemeris_interval_s": "base_ephemeris_interval_s",
        "base.glonass_bias_interval_s": "base_glonass_bias_interval_s",
        "base.receiver_descriptor": "base_receiver_descriptor",
    }
)
MODELS = ("auto", "lea6t", "m8t")
MAVLINK_BASE_STREAM = "mavlink"
"""`rtk.base_stream` value: the corrections a ground station injects through the autopilot (GPS_RTCM_DATA)."""
PIN_FACTORIES = ("lgpio", "mock")
BASE_OBSERVATIONS = ("msm4", "msm5", "msm7", "1004", "1002")
"""`base.observations` values (onboard.base.station.OBS_MESSAGES, held equal by a test)."""


def _field_types() -> dict[str, Any]:
    return {f.name: f.type for f in dataclasses.fields(Settings)}


def _receiver_option_fields() -> dict[str, Any]:
    from onboard.receiver.profiles import ReceiverOptions

    return {f.name: f.default for f in dataclasses.fields(ReceiverOptions)}


def _rtk_engine_kinds() -> dict[str, str]:
    """Value type of each `rtk.engine.<key>` (the TOML value, before the option's own conversion)."""
    from onboard.rtk.options import TOML_KEYS

    named = {bool: "bool", int: "int", str: "str"}
    return {key: named.get(conv, "float") for key, (_, conv) in TOML_KEYS.items()}


@dataclass(frozen=True, slots=True)
class Bound:
    """The range of one numeric key: [minimum, maximum] (`exclusive_minimum`: > minimum; no maximum when None) in
    `unit`, and why."""

    minimum: float
    maximum: float | None
    unit: str = ""
    exclusive_minimum: bool = False
    why: str = ""


GPIO_PIN = Bound(-1, 27, why="a BCM GPIO number of the 40-pin header, -1 = none")
# Every numeric key's range, with the unit its message shows (`onboard.validate` words the refusal).
BOUNDS: Mapping[str, Bound] = MappingProxyType(
    {
        "port.baud": Bound(1200, 921600, " bit/s", why="921600 is the fastest a u-blox receiver talks"),
        "port.read_timeout_s": Bound(0, 5, " s", True),
        "port.reopen_min_s": Bound(0, 3600, " s", True),
        "port.reopen_max_s": Bound(0, 3600, " s", True),
        "journal.sync_interval_s": Bound(0, 1, " s", True, "received bytes are fsync'd at least once a second"),
        "journal.segment_max_mb": Bound(0, 4000, " MB", why="0 = never by size; a FAT32 file holds less than 4 GiB"),
        "journal.segment_max_s": Bound(0, 86400, " s", why="0 = never by time"),
        # no maximum: a floor above the card's size refuses to record (exit 3), which is what it says
        "journal.disk_floor_mb": Bound(0, None, " MB"),
        "journal.disk_check_interval_s": Bound(0, 60, " s", True),
        "status.interval_s": Bound(0, STALE_AFTER_S / 2, " s", True,
                                   f"the pre-flight page calls a snapshot older than {STALE_AFTER_S:g} s stale"),
        "watchdog.writer_stall_s": Bound(0, 3600, " s", True),
        "gpio.trigger_pin": GPIO_PIN,
        "gpio.pps_pin": GPIO_PIN,
        "gpio.flash_pin": GPIO_PIN,
        "rtk.max_base_age_s": Bound(0, 300, " s", True),
        "rtk.preflight_base_timeout_s": Bound(0, 300, " s", True),
        "autopilot.system_id": Bound(0, 255, why="a MAVLink system id, 0 = the autopilot's own"),
        "autopilot.fast_interval_s": Bound(0, 10, " s", True),
        "autopilot.slow_interval_s": Bound(0, 10, " s", True),
        "autopilot.link_timeout_s": Bound(0, 60, " s", True),
        "autopilot.rerequest_s": Bound(0, 300, " s", True),
        "autopilot.settle_s": Bound(0, 3600, " s", True),
        "upload.chunk_mib": Bound(0.01, 1024, " MiB", why="each chunk is held in memory twice"),
        "upload.backoff_min_s": Bound(0, 3600, " s", True),
        "upload.backoff_max_s": Bound(0, 86400, " s", True),
        "upload.poll_s": Bound(0, 3600, " s", True),
        "base.budget_bytes_s": Bound(0, 100_000, " B/s", True),
        "base.obs_interval_s": Bound(0, 3600, " s", True),
        "base.position_interval_s": Bound(0, 3600, " s", True),
        "base.ephemeris_interval_s": Bound(0, 3600, " s", True),
        "base.glonass_bias_interval_s": Bound(0, 3600, " s", True),
        # receiver options the receiver profile does not bound itself
        "receiver.ant_cable_delay_ns": Bound(-32768, 32767, " ns", why="CFG-TP5 holds it in 16 signed bits"),
        "receiver.pulse_len_ms": Bound(0, 3000, " ms", True, "shorter than the camera period, at most 3 s"),
        "receiver.ack_timeout_s": Bound(0, 30, " s", True),
        "receiver.retries": Bound(0, 10),
        "receiver.aid_eph_poll_s": Bound(0, 86400, " s", why="0 = never"),
    }
)


def _number(key: str, value: Any, integer: bool, from_text: bool) -> float | int:
    """A numeric key's value, finite and within BOUNDS[key] when it has one (ValueError in validate's words)."""
    if isinstance(value, str) and not from_text:
        raise ValueError(f"{key} {value!r}: must be a number, not text (write it without quotes)")
    if not isinstance(value, (int, float, str)):
        raise ValueError(f"{key} {value!r}: must be a {'whole ' if integer else ''}number")  # noqa: TRY004
    bound = BOUNDS.get(key)
    kw: dict[str, Any] = {} if bound is None else {"unit": bound.unit, "minimum": bound.minimum,
                                                   "maximum": bound.maximum}
    try:
        if integer:
            return check.integer(value, name=key, **kw)
        return check.number(value, name=key, exclusive_minimum=bound is not None and bound.exclusive_minimum, **kw)
    except ValueError as exc:
        if bound is not None and bound.why and "must be a" not in str(exc):
            raise ValueError(f"{exc} ({bound.why})") from None
        raise


def _convert(key: str, value: Any, kind: Any, from_text: bool) -> Any:
    """Convert a TOML or environment value to the field's type; ConfigFileError naming `key` if it cannot."""
    kind_name = kind if isinstance(kind, str) else getattr(kind, "__name__", str(kind))
    try:
        if kind_name == "bool":
            if isinstance(value, bool):
                return value
            if from_text and str(value).lower() in ("1", "true", "yes", "on", "0", "false", "no", "off"):
                return str(value).lower() in ("1", "true", "yes", "on")
            raise ValueError(f"{key} {value!r}: must be true or false")
        if kind_name in ("int", "float"):
            return _number(key, value, kind_name == "int", from_text)
        if kind_name in ("Path", "str"):
            if not isinstance(value, str) or (kind_name == "Path" and not value):
                raise ValueError(f"{key} {value!r}: must be {'a path' if kind_name == 'Path' else 'text'}"
                                 f"{' in quotes' if not from_text else ''}")
            if "\x00" in value:
                raise ValueError(f"{key} {value!r}: must not contain a NUL character")
            return Path(value) if kind_name == "Path" else value
    except ValueError as exc:
        raise ConfigFileError(str(exc)) from exc
    raise ConfigFileError(f"{key}: unsupported type {kind_name}")


SECTIONS = frozenset({k.rsplit(".", 1)[0] for k in KEYS} | {"receiver", RTK_ENGINE.rstrip(".")})
"""The tables of the file: one left empty (every key commented out) is fine."""


def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """`section.key` → value; an empty table other than a known section stays a value (`pps_pin = {}` is a bad
    value of gpio.pps_pin, not nothing)."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and (v or key in SECTIONS):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _apply(values: dict[str, Any], receiver: dict[str, Any], flat: Mapping[str, Any], source: str,
           from_text: bool, rtk_engine: dict[str, Any]) -> None:
    types = _field_types()
    options = _receiver_option_fields()
    engine = _rtk_engine_kinds()
    for key, raw in flat.items():
        if key in KEYS:
            name = KEYS[key]
            values[name] = _convert(key, raw, types[name], from_text)
        elif key.startswith("receiver.") and key.split(".", 1)[1] in options:
            opt = key.split(".", 1)[1]
            receiver[opt] = _convert(key, raw, type(options[opt]).__name__, from_text)
        elif key.startswith(RTK_ENGINE) and key[len(RTK_ENGINE):] in engine:
            opt = key[len(RTK_ENGINE):]
            rtk_engine[opt] = _convert(key, raw, engine[opt], from_text)
        else:
            raise ConfigFileError(f"{source}: unknown key {key!r}")


def load_toml(path: Path) -> dict[str, Any]:
    """Read a TOML file into flat `section.key` values (ConfigFileError if unreadable or malformed)."""
    try:
        with open(path, "rb") as f:
            return _flatten(tomllib.load(f))
    except OSError as exc:
        raise ConfigFileError(f"cannot read configuration file {path}: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigFileError(f"{path}: not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x}): "
                              "a configuration file is UTF-8 TOML") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigFileError(f"{path}: not valid TOML: {exc}") from exc


def env_values(environ: Mapping[str, str]) -> dict[str, str]:
    """`ONBOARD_SECTION_KEY` variables as flat `section.key` values (unknown ONBOARD_ names are errors,
    except the test hooks `ONBOARD_TEST_*`)."""
    known = {ENV_PREFIX + k.upper().replace(".", "_"): k for k in KEYS}
    known.update(
        {ENV_PREFIX + "RECEIVER_" + opt.upper(): f"receiver.{opt}" for opt in _receiver_option_fields()}
    )
    known.update({ENV_PREFIX + "RTK_ENGINE_" + opt.upper(): RTK_ENGINE + opt for opt in _rtk_engine_kinds()})
    out: dict[str, str] = {}
    for name, value in environ.items():
        if not name.startswith(ENV_PREFIX) or name.startswith(ENV_PREFIX + "TEST_"):
            continue
        if name not in known:
            raise ConfigFileError(f"environment: unknown variable {name}")
        out[known[name]] = value
    return out


def default_config_path() -> Path:
    """The packaged, documented default configuration file."""
    return Path(str(resources.files("onboard.recorder").joinpath("default_config.toml")))


def load_settings(
    config_file: Path | None = None,
    environ: Mapping[str, str] | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> Settings:
    """Build the settings: dataclass defaults → `config_file` → `ONBOARD_*` environment → `overrides`.

    `overrides` uses `section.key` names (the CLI flags map onto them). Raises ConfigFileError.
    """
    values: dict[str, Any] = {}
    receiver: dict[str, Any] = {}
    engine: dict[str, Any] = {}
    if config_file is not None:
        _apply(values, receiver, load_toml(Path(config_file)), str(config_file), False, engine)
    _apply(values, receiver, env_values(os.environ if environ is None else environ), "environment", True, engine)
    if overrides:
        _apply(values, receiver, {k: v for k, v in overrides.items() if v is not None}, "command line", False,
               engine)
    settings = Settings(**values, receiver_options=MappingProxyType(receiver), rtk_engine=MappingProxyType(engine))
    validate(settings)
    return settings


def validate(s: Settings) -> None:
    """Cross-field checks (ConfigFileError naming the key)."""
    if s.receiver_model not in MODELS:
        raise ConfigFileError(f"receiver.model: must be one of {MODELS}, got {s.receiver_model!r}")
    if s.base_observations not in BASE_OBSERVATIONS:
        raise ConfigFileError(f"base.observations: must be one of {BASE_OBSERVATIONS}, got {s.base_observations!r}")
    if len(s.base_receiver_descriptor) > 31 or not s.base_receiver_descriptor.isascii():
        raise ConfigFileError(f"base.receiver_descriptor {s.base_receiver_descriptor!r}: at most 31 ASCII "
                              "characters (RTCM 1033)")
    if s.gpio_pin_factory not in PIN_FACTORIES:
        raise ConfigFileError(f"gpio.pin_factory: must be one of {PIN_FACTORIES}, got {s.gpio_pin_factory!r}")
    if s.port_reopen_max_s < s.port_reopen_min_s:
        raise ConfigFileError(f"port.reopen_max_s {s.port_reopen_max_s:g}: must be ≥ port.reopen_min_s "
                              f"({s.port_reopen_min_s:g} s)")
    if s.watchdog_writer_stall_s <= s.port_read_timeout_s:
        raise ConfigFileError(f"watchdog.writer_stall_s {s.watchdog_writer_stall_s:g}: must be > port.read_timeout_s "
                              f"({s.port_read_timeout_s:g} s): one read may wait that long")
    opts = _check_receiver_options(s)
    if opts.trigger == "gpio" and (s.gpio_trigger_pin < 0 or s.gpio_pps_pin < 0):
        raise ConfigFileError("receiver.trigger = \"gpio\" needs gpio.trigger_pin and gpio.pps_pin (BCM numbers)")
    if s.gpio_flash_pin >= 0 and s.gpio_pps_pin < 0:
        raise ConfigFileError("gpio.flash_pin needs gpio.pps_pin (BCM number): GPIO edges are timed through PPS")
    if s.rtk_base_stream == MAVLINK_BASE_STREAM:
        if not s.autopilot_link:
            raise ConfigFileError("rtk.base_stream = \"mavlink\" needs autopilot.link (the corrections come "
                                  "through the autopilot's GPS_RTCM_DATA)")
    elif s.rtk_base_stream and not s.rtk_base_stream.startswith(("serial:", "tcp://", "ntrip://")):
        raise ConfigFileError(f"rtk.base_stream: expected serial:DEV[@BAUD], tcp://HOST:PORT, "
                              f"ntrip://[USER:PASS@]HOST[:PORT]/MOUNT or mavlink, got {s.rtk_base_stream!r}")
    if s.autopilot_link:
        from onboard.hw.mavlink_link import parse_link_spec

        try:
            parse_link_spec(s.autopilot_link)
        except ValueError as exc:
            raise ConfigFileError(f"autopilot.link {exc}") from exc
    if s.upload_url:
        try:
            check.http_url(s.upload_url, name="upload.url")
        except ValueError as exc:
            raise ConfigFileError(str(exc)) from exc
        if not s.upload_token_file:
            raise ConfigFileError("upload.url needs upload.token_file (the file holding the ground API's token)")
    if s.upload_backoff_max_s < s.upload_backoff_min_s:
        raise ConfigFileError(f"upload.backoff_max_s {s.upload_backoff_max_s:g}: must be ≥ upload.backoff_min_s "
                              f"({s.upload_backoff_min_s:g} s)")
    try:
        takeoff_position_ecef_m(s)
    except ValueError as exc:
        raise ConfigFileError(f"rtk.takeoff_position: {exc}") from exc
    if "max_age_s" in s.rtk_engine:  # the service sets it from rtk.max_base_age_s: one place for one value
        raise ConfigFileError(f"{RTK_ENGINE}max_age_s: set rtk.max_base_age_s instead")
    from onboard.rtk.options import options_from_mapping

    for key, value in s.rtk_engine.items():  # one at a time, so that an error names its key
        try:
            options_from_mapping({key: value})
        except (TypeError, ValueError) as exc:
            raise ConfigFileError(f"{RTK_ENGINE}{key} {value!r}: {exc}") from exc
    try:
        rtk_engine_options(s)
    except (TypeError, ValueError) as exc:
        raise ConfigFileError(f"rtk.engine: {exc}") from exc
    used = [p for p in (s.gpio_trigger_pin if opts.trigger == "gpio" else -1, s.gpio_pps_pin, s.gpio_flash_pin)
            if p >= 0]
    if len(used) != len(set(used)):
        raise ConfigFileError(f"gpio: trigger_pin, pps_pin and flash_pin must be different pins, got {used}")


def _check_receiver_options(s: Settings) -> Any:
    """The receiver options, each given key checked alone first so that an error names it (ConfigFileError)."""
    from onboard.receiver.profiles import ReceiverOptions

    base = {"baud": s.receiver_options.get("baud", s.port_baud)}
    try:
        ReceiverOptions(**base)
    except (TypeError, ValueError) as exc:
        key = "receiver.baud" if "baud" in s.receiver_options else "port.baud (receiver.baud follows it unless set)"
        raise ConfigFileError(f"{key} {base['baud']}: {exc}") from exc
    for opt, value in s.receiver_options.items():
        try:
            ReceiverOptions(**{**base, opt: value})
        except (TypeError, ValueError, ArithmeticError) as exc:
            raise ConfigFileError(f"receiver.{opt} {value!r}: {exc}") from exc
    try:
        return receiver_options(s)
    except (TypeError, ValueError) as exc:  # a combination (a pulse as long as its period)
        raise ConfigFileError(f"receiver: {exc}") from exc


def check_recording_paths(s: Settings) -> None:
    """Before recording starts: `journal.data_dir` and the folder of `status.path` are folders this process can
    write (created if missing, as the recorder would); ConfigFileError naming the key and the path otherwise.

    Tried by creating (and removing) a file there: permissions, read-only file systems and /proc all answer."""
    _writable_dir("journal.data_dir", s.data_dir)
    if s.status_path.is_dir():
        raise ConfigFileError(f"status.path {s.status_path}: must be a file name, not a folder")
    _writable_dir("status.path", s.status_path.parent, what=f" (the folder of {s.status_path})")


def _writable_dir(key: str, path: Path, what: str = "") -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ConfigFileError(f"{key} {path}: must be a folder, but a file of that name exists{what}") from None
    except OSError as exc:
        raise ConfigFileError(f"{key} {path}: cannot create the folder{what}: {exc.strerror or exc}") from exc
    if not path.is_dir():
        raise ConfigFileError(f"{key} {path}: must be a folder, but it is not one{what}")
    try:
        fd, probe = tempfile.mkstemp(dir=path, prefix=".directgeo-write-check-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ConfigFileError(f"{key} {path}: must be a folder this process can write{what}: "
                              f"{exc.strerror or exc}") from exc


def takeoff_position_ecef_m(s: Settings) -> tuple[float, float, float] | None:
    """The surveyed take-off antenna position of `rtk.takeoff_position` ("X,Y,Z", ECEF m), None when empty;
    ValueError if it is not three finite numbers or lies off the Earth's surface by more than 100 km."""
    text = s.rtk_takeoff_position.strip()
    if not text:
        return None
    from onboard.rtk.geodesy import parse_xyz_m

    xyz = parse_xyz_m(text)
    if not all(math.isfinite(v) for v in xyz):
        raise ValueError(f"expected X,Y,Z in ECEF metres, got {text!r}")
    if not 6.25e6 < math.sqrt(sum(v * v for v in xyz)) < 6.48e6:
        raise ValueError(f"{text!r} is not near the Earth's surface (ECEF metres expected, not degrees)")
    return xyz


def rtk_engine_options(s: Settings) -> Any:
    """The RTK engine's `RtkOptions` from the `[rtk.engine]` table (defaults for keys not given)."""
    from onboard.rtk.options import options_from_mapping

    if "max_age_s" in s.rtk_engine:  # the service sets it from rtk.max_base_age_s: one place for one value
        raise ValueError(f"{RTK_ENGINE}max_age_s: set rtk.max_base_age_s instead")
    return options_from_mapping(s.rtk_engine)  # RtkOptions checks its values (e.g. ar_mode) itself


def receiver_options(s: Settings) -> Any:
    """The `ReceiverOptions` built from the `[receiver]` section (baud defaults to `port.baud`)."""
    from onboard.receiver.profiles import ReceiverOptions

    opts = dict(s.receiver_options)
    opts.setdefault("baud", s.port_baud)
    return ReceiverOptions(**opts)


def add_recorder_arguments(parser: Any) -> None:
    """The command-line overrides shared by every recorder command (`run`, `base`): config file, line rate,
    data folder, status path, and recording without configuring the receiver."""
    parser.add_argument("--config", type=Path, help="TOML configuration file (see onboard/recorder/default_config.toml)")
    parser.add_argument("--baud", type=int, help="line rate to open the port at (overrides port.baud)")
    parser.add_argument("--data-dir", type=Path, help="where flights are recorded (overrides journal.data_dir)")
    parser.add_argument("--status", type=Path, help="status snapshot JSON path (overrides status.path)")
    parser.add_argument("--no-configure", action="store_true", help="record only; never configure the receiver")


def recorder_overrides(args: Any) -> dict[str, Any]:
    """Settings overrides (dotted key → value, None = not given) from the arguments of
    add_recorder_arguments plus `--port`."""
    return {
        "port.device": args.port,
        "port.baud": args.baud,
        "journal.data_dir": str(args.data_dir) if args.data_dir else None,
        "status.path": str(args.status) if args.status else None,
        "receiver.configure": False if args.no_configure else None,
    }
