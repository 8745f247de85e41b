"""The onboard error taxonomy: callers catch these, never bare exceptions."""

from __future__ import annotations


class OnboardError(Exception):
    """Base of every error the onboard package raises on purpose."""


class ReceiverError(OnboardError, IOError):
    """The receiver did not behave as the protocol says (no answer, bad frame, wrong model)."""


class ConfigRejected(ReceiverError):
    """The receiver NAKed, ignored or altered a configuration message.

    `message` names the UBX message (e.g. "CFG-TP5"), `field` the offending field when known.
    """

    def __init__(self, message: str, detail: str, field: str | None = None) -> None:
        self.message = message
        self.field = field
        self.detail = detail
        where = f"{message}.{field}" if field else message
        super().__init__(f"{where}: {detail}")


class LinkLost(ReceiverError):
    """The serial link disappeared (cable unplugged, USB re-enumeration)."""


class ConfigFileError(OnboardError, ValueError):
    """A TOML configuration file is unreadable or holds an unknown key or a bad value."""


class DiskFull(OnboardError, OSError):
    """The data directory has less free space than the configured floor."""


class InputError(OnboardError, ValueError):
    """A file given to a command cannot be used (unreadable, wrong format, nothing in common)."""


class DataRefused(OnboardError):
    """The inputs are well-formed but cannot support an answer (exit 3): e.g. no ephemeris valid at the
    observations' time, no epoch with a solution. The message says why and what was (not) written."""
