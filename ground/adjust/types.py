"""Inputs of the final adjustment, already converted to our conventions by the importers.

Conventions (shared/docs/adjustment.md): camera axes are computer-vision axes (x right, y down,
z forward); `r_cam_to_rel` maps camera-frame vectors into the bundle adjustment's relative frame;
the lever arm O is antenna phase centre minus optical centre in the camera frame
(antenna = C + R_cam→world·O); the shutter delay t_d (s) is the time from the event (trigger pulse or flash
mark) to the exposure. Ground/antenna coordinates are local ENU metres about a stated ECEF origin.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import GpsTime


@dataclass(frozen=True)
class CameraPose:
    """One image's pose from the bundle adjustment: centre (relative frame, its units) and camera→relative rotation."""

    image: str
    centre_rel: npt.NDArray[np.float64]
    r_cam_to_rel: npt.NDArray[np.float64]


@dataclass(frozen=True)
class ImageEvent:
    """The GPS time of one image's event (trigger pulse or flash mark) and what kind of event it is."""

    image: str
    time: GpsTime
    kind: str = "flash"  # "flash" (TIM-TM2 flash mark) or "trigger" (trigger pulse time)
    measured_delay_s: float | None = None  # trigger→flash delay measured onboard, when both were seen


@dataclass(frozen=True)
class Trajectory:
    """Antenna trajectory from an RTK solution (RTKLIB .pos), ECEF metres.

    `t_ns` (n,) GPS time as ns since the GPS epoch (int64), `pos_ecef_m` (n,3), `vel_ecef_m_s` (n,3) or None
    (then derived by differencing), `sd_m` (n,3) σ of x,y,z, `q` (n,) RTKLIB quality (1 fix, 2 float, 5 single).
    """

    t_ns: npt.NDArray[np.int64]
    pos_ecef_m: npt.NDArray[np.float64]
    vel_ecef_m_s: npt.NDArray[np.float64] | None
    sd_m: npt.NDArray[np.float64]
    q: npt.NDArray[np.int8]


@dataclass(frozen=True)
class ControlPoint:
    """A ground control or check point: its coordinates in the relative frame and on the ground (ENU m)."""

    name: str
    role: str  # "gcp" or "check"
    rel: npt.NDArray[np.float64]
    ground_enu_m: npt.NDArray[np.float64]
    sigma_m: npt.NDArray[np.float64] = field(default_factory=lambda: np.full(3, 0.01))
