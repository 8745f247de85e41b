"""Low CPU and I/O priority for the uploader: it must never slow the recorder's writes on a shared SD card.

CPU: `os.setpriority(PRIO_PROCESS, 0, 10)` (nice 10, never lowered if already nicer). I/O: the idle class of
the kernel's I/O schedulers (what `ionice -c3` sets) through the `ioprio_set` system call (ctypes: the Python
standard library has no wrapper). Both apply to the calling thread and are inherited by threads it starts
afterwards: call this first, before any other thread exists. The systemd unit sets the same (`Nice=10`,
`IOSchedulingClass=idle`), so a run outside systemd behaves alike.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import platform

log = logging.getLogger(__name__)

NICE = 10
IOPRIO_CLASS_SHIFT = 13
IOPRIO_CLASS_IDLE = 3
IOPRIO_WHO_PROCESS = 1
IOPRIO_CLASS_NAMES = {0: "none", 1: "realtime", 2: "best-effort", 3: "idle"}
# (ioprio_set, ioprio_get) system call numbers by machine (Linux asm/unistd.h)
SYSCALLS = {"x86_64": (251, 252), "aarch64": (30, 31), "armv7l": (314, 315), "armv6l": (314, 315),
            "i686": (289, 290), "i386": (289, 290)}


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)


def io_class(pid: int = 0) -> str:
    """The I/O scheduling class of process (thread) `pid`, 0 = the calling thread ("idle", "best-effort", ...;
    "unknown" off Linux)."""
    numbers = SYSCALLS.get(platform.machine())
    if numbers is None:
        return "unknown"
    value = _libc().syscall(numbers[1], IOPRIO_WHO_PROCESS, pid)
    if value < 0:
        return "unknown"
    return IOPRIO_CLASS_NAMES.get(value >> IOPRIO_CLASS_SHIFT, str(value >> IOPRIO_CLASS_SHIFT))


def lower_priority() -> dict[str, object]:
    """Nice 10 and the idle I/O class for the calling thread; returns what is in force (for upload.json)."""
    applied: dict[str, object] = {}
    try:
        current = os.getpriority(os.PRIO_PROCESS, 0)
        if current < NICE:
            os.setpriority(os.PRIO_PROCESS, 0, NICE)
        applied["nice"] = os.getpriority(os.PRIO_PROCESS, 0)
    except OSError as exc:
        log.warning("cannot lower the CPU priority: %s", exc)
        applied["nice"] = None
    numbers = SYSCALLS.get(platform.machine())
    if numbers is None:
        log.warning("ioprio_set: unknown system call number on %s; I/O priority unchanged", platform.machine())
    elif _libc().syscall(numbers[0], IOPRIO_WHO_PROCESS, 0, IOPRIO_CLASS_IDLE << IOPRIO_CLASS_SHIFT) != 0:
        log.warning("ioprio_set failed: %s; I/O priority unchanged", os.strerror(ctypes.get_errno()))
    applied["io_class"] = io_class()
    return applied
