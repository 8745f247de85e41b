"""Ambiguity resolution and slip detection on real L1 data (GEONET 0759/3040 static, GEONET 3034/Septentrio)."""

from __future__ import annotations

import numpy as np

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.geodesy import ecef_to_enu
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import pair_epochs
from onboard.rtk.rtkpos import Nav, rtk_init, rtk_pos
from onboard.rtk.types import Q_FIX
from tests.conftest import shared_file

GEONET_0759_ECEF_M = np.array([-3976219.1873, 3382371.6051, 3652511.1423])
GEONET_3040_ECEF_M = np.array([-3978241.958, 3382840.234, 3649900.853])
GEONET_3034_ECEF_M = np.array([-3959400.631, 3385704.533, 3667523.111])


def _nav(path) -> Nav:
    f = read_rinex_nav(path)
    return Nav(EphemerisStore(f.ephemerides), (f.iono_alpha, f.iono_beta))


def test_geonet_static_fixes_when_the_full_integer_set_wins_a_second_time_never_at_the_first_epochs():
    """3.3 km, 30 s epochs: the bootstrapped success rate stays under 0.99 for 510 s, but the ratio test picks
    the same (right) full integer set from the second epoch on; confirmed by its second win (30 s later) it fixes
    at the third epoch (60 s; was the fourth, 90 s, with the 60 s wall-time span). The first epoch (code only)
    and the set's first win never fix."""
    rover = read_rinex_obs(shared_file("gnss/geonet-0759-3040-20050402/07590920.05o.gz")).epochs[:12]
    base = read_rinex_obs(shared_file("gnss/geonet-0759-3040-20050402/30400920.05o.gz")).epochs
    nav = _nav(shared_file("gnss/geonet-0759-3040-20050402/07590920.05n.gz"))
    st = rtk_init(RtkOptions())
    sols = [rtk_pos(st, r, b, nav, GEONET_3040_ECEF_M) for r, b in zip(rover, pair_epochs(rover, base))]
    q = [s.q for s in sols]
    assert Q_FIX not in q[:2]
    assert all(x == Q_FIX for x in q[2:]), q
    for s in sols[2:]:
        e = ecef_to_enu(s.pos_ecef_m, GEONET_0759_ECEF_M)
        assert np.hypot(e[0], e[1]) < 0.02 and abs(e[2]) < 0.03


def test_septentrio_phase_gap_without_lli_resets_the_ambiguity():
    """The moving Septentrio rover (no Doppler in its RINEX) loses G20's phase for 3 epochs (file epochs
    310-312) and comes back a whole cycle off with LLI 0: the ambiguity must restart at epoch 313."""
    sept = "gnss/geonet-3034-sept-20210922/"
    rover = read_rinex_obs(shared_file(sept + "SEPT265G.21O.gz")).epochs[290:316]
    base = read_rinex_obs(shared_file(sept + "3034265G.21O.gz")).epochs
    nav = _nav(shared_file(sept + "SEPT2650.21P.gz"))
    st = rtk_init(RtkOptions())
    slips = []
    for r, b in zip(rover, pair_epochs(rover, base)):
        before = st.slips
        rtk_pos(st, r, b, nav, GEONET_3034_ECEF_M)
        slips.append(st.slips - before)
    assert slips[313 - 290] == 1
    assert st.lock[20 - 1] == 316 - 313

