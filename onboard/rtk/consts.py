"""Physical and GPS constants (IS-GPS-200, WGS 84), and the L1-band carriers of the other systems."""

from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS, GNSS_SBAS

CLIGHT_M_S = 299_792_458.0
"""Speed of light in vacuum, m/s."""
MU_GPS_M3_S2 = 3.986005e14
"""Earth's gravitational constant used by GPS, m³/s²."""
OMEGA_E_RAD_S = 7.2921151467e-5
"""Earth rotation rate (WGS 84), rad/s."""
PR_MIN_M = 1.0e6
PR_MAX_M = 1.0e8
"""Pseudoranges (m) outside [PR_MIN_M, PR_MAX_M] are corrupt values, not measurements: a satellite's range from
the ground is 19 100-42 000 km (GPS to BeiDou GEO), and a receiver clock milliseconds off moves it by thousands of
km (the M8P logs of ../shared: 15 500-23 100 km, clocks up to about 12 ms off)."""
DOPPLER_MAX_HZ = 50_000.0
"""|Doppler| (Hz) beyond which a value is corrupt: a satellite's range rate gives ±5 kHz at L1 and a receiver
oscillator's offset a few kHz (±2.5 ppm: ±4 kHz); the M8P logs stay within ±5.4 kHz."""
CN0_MAX_DBHZ = 100.0
"""C/N0 (dB-Hz) beyond which, or below 0, a value is corrupt (receivers report 0-63)."""
FREQ_L1_HZ = 1_575_420_000.0
"""GPS L1 carrier frequency, Hz."""
LAMBDA_L1_M = CLIGHT_M_S / FREQ_L1_HZ
"""GPS L1 carrier wavelength, m (≈ 0.1903 m)."""
WGS84_A_M = 6_378_137.0
"""WGS 84 semi-major axis, m."""
WGS84_F = 1.0 / 298.257223563
"""WGS 84 flattening."""
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
"""WGS 84 first eccentricity squared."""
F_REL_S_SQRT_M = -4.442807633e-10
"""Relativistic clock-correction constant F = −2√μ/c², s/√m (IS-GPS-200 20.3.3.3.3.1)."""
MU_GAL_M3_S2 = 3.986004418e14
"""Earth's gravitational constant of Galileo (GTRF, OS SIS ICD 5.1.1), m³/s²."""
OMEGA_E_GAL_RAD_S = 7.2921151467e-5
"""Earth rotation rate used by Galileo, rad/s."""
MU_BDS_M3_S2 = 3.986004418e14
"""Earth's gravitational constant of BeiDou (CGCS2000, B1I ICD 5.2.4.11), m³/s²."""
OMEGA_E_BDS_RAD_S = 7.2921150e-5
"""Earth rotation rate of CGCS2000 used by BeiDou, rad/s."""
MU_GLO_M3_S2 = 3.9860044e14
"""Earth's gravitational constant of PZ-90 (GLONASS ICD 5.1 A.3.1.2), m³/s²."""
OMEGA_E_GLO_RAD_S = 7.292115e-5
"""Earth rotation rate of PZ-90, rad/s."""
J2_GLO = 1.0826257e-3
"""Second zonal harmonic of the geopotential in the GLONASS equations of motion (PZ-90)."""
RE_GLO_M = 6_378_136.0
"""PZ-90 equatorial radius used in the GLONASS equations of motion, m."""
FREQ_G1_HZ = 1_602_000_000.0
"""GLONASS G1 FDMA centre frequency (channel k = 0), Hz; channel k transmits FREQ_G1_HZ + k·DFREQ_G1_HZ."""
DFREQ_G1_HZ = 562_500.0
"""GLONASS G1 channel spacing, Hz."""
FREQ_B1I_HZ = 1_561_098_000.0
"""BeiDou B1I carrier frequency, Hz."""
GLO_FCN_MIN = -7
GLO_FCN_MAX = 6
"""GLONASS frequency channel numbers in use (ICD L1/L2 2008: −7…+6)."""


def l1_wavelength_m(gnss_id: int, glo_fcn: int | None = None) -> float | None:
    """Carrier wavelength (m) of a system's L1-band signal that we track (u-blox gnssId): GPS/SBAS/QZSS L1 and
    Galileo E1 1575.42 MHz, BeiDou B1I 1561.098 MHz, GLONASS G1 1602 + 0.5625·k MHz. None for GLONASS without a
    valid channel k (its phase cannot be turned into cycles) or an unknown system."""
    if gnss_id in (GNSS_GPS, GNSS_SBAS, GNSS_GALILEO, GNSS_QZSS):
        return LAMBDA_L1_M
    if gnss_id == GNSS_BEIDOU:
        return CLIGHT_M_S / FREQ_B1I_HZ
    if gnss_id == GNSS_GLONASS and glo_fcn is not None and GLO_FCN_MIN <= glo_fcn <= GLO_FCN_MAX:
        return CLIGHT_M_S / (FREQ_G1_HZ + glo_fcn * DFREQ_G1_HZ)
    return None
