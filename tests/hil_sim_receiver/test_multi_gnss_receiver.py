"""The emulated M8T in multi-constellation worlds: RXM-RAWX of every system, RXM-SFRBX GLONASS strings, QZSS LNAV
subframes and Galileo I/NAV page pairs that onboard's decoders read back to the broadcast ephemerides."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hil_sim import galileo_pages as galp
from hil_sim import glonass_strings as gls
from hil_sim.scenario import Scenario
from hil_sim.world import World
from onboard.receiver.decode import decode_rxm_rawx
from onboard.receiver.framing import Protocol
from onboard.receiver.sfrbx import iter_navigation
from onboard.rtk.galileo_inav import DATA_SOURCE_E1B, GalileoNavError, ephemeris_from_words, inav_word
from onboard.rtk.glonass_nav import GlonassStringAssembler, hamming_ok
from onboard.rtk.types import GNSS_GALILEO, GNSS_GLONASS, GNSS_QZSS, GlonassEphemeris
from tests.hil_sim_receiver.test_core import acked, configure, core_for, poll, run, send, ubx_of


def _glonass_ephemerides(world: World) -> dict[int, GlonassEphemeris]:
    nav = world.broadcast_navigation()
    out = {}
    for g, sv in nav.satellites():
        e = nav.select(g, sv, world.start)
        if g == GNSS_GLONASS and isinstance(e, GlonassEphemeris):
            out[sv] = e
    return out


def _same(a: GlonassEphemeris, b: GlonassEphemeris) -> None:
    """Equal to the broadcast resolution (RINEX prints 12 digits: < 1 mm, < 1 µm/s)."""
    assert (a.slot, a.channel, a.toe, a.health, a.iode) == (b.slot, b.channel, b.toe, b.health, b.iode)
    assert np.allclose(a.pos_m, b.pos_m, atol=1e-3) and np.allclose(a.vel_m_s, b.vel_m_s, atol=1e-6)
    assert np.allclose(a.acc_m_s2, b.acc_m_s2, atol=1e-12)
    assert a.tau_n_s == pytest.approx(b.tau_n_s, abs=1e-15) and a.gamma_n == pytest.approx(b.gamma_n, abs=1e-20)


def _same_kepler(a, b) -> None:
    """Equal fields; floats to the RINEX file's 12 printed digits (the broadcast values are binary)."""
    for f in dataclasses.fields(b):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(y, float):
            assert x == pytest.approx(y, rel=1e-9, abs=1e-18), f.name
        else:
            assert x == y, f.name


def test_glonass_strings_round_trip_through_the_decoder_and_the_hamming_code() -> None:
    world = World(Scenario.multi("gr-2012", duration_s=120.0))
    leap = 16
    shift = 3 * 3600 - leap
    frame_start = world.start.add_s(-((world.start.tow_s + shift) % gls.FRAME_S))
    ephs = _glonass_ephemerides(world)
    assert len(ephs) == 24
    for eph in ephs.values():
        strings = gls.strings(eph, frame_start, leap)
        asm = GlonassStringAssembler(leap)
        got = None
        for m in (5, 1, 2, 3, 4):
            assert hamming_ok(strings[m])
            assert not hamming_ok(strings[m] ^ (1 << 40))  # a flipped data bit is caught
            got = asm.add_sfrbx(eph.slot, eph.channel + 7, gls.sfrbx_words(strings[m], frame_start, leap),
                                frame_start) or got
        assert got is not None
        _same(got, eph)
        assert got.tof == frame_start  # tk: the frame's own time


def test_emulated_m8t_sends_glonass_rawx_and_strings_the_decoders_read_back() -> None:
    world = World(Scenario.multi("gr-2012", duration_s=120.0))
    core = core_for("m8t", world, time_valid_after_s=1.0)
    configure(core, meas_ms=1000)
    assert poll(core, "CFG-GNSS")["numConfigBlocks"] == 7
    # factory: GLONASS off; swap BeiDou for GLONASS (3 major systems at most)
    rows = [{**b, "flags": (b["flags"] | 1) if g == 6 else (b["flags"] & ~1) if g == 3 else b["flags"]}
            for g, b in sorted(core.config.gnss.items())]
    assert acked(_cfg_gnss(core, rows))
    frames = run(core, 40.0, step_s=0.5)
    raw = [decode_rxm_rawx(f.payload) for f in ubx_of(frames, (0x02, 0x15))]
    glo = [ep for ep in raw if ep is not None and np.any(ep.gnss_id == GNSS_GLONASS)]
    assert len(glo) >= 35
    ep = glo[-1]
    truth = world.glonass_channels()
    for s, k in zip(ep.sv_id[ep.gnss_id == GNSS_GLONASS], ep.glo_fcn[ep.gnss_id == GNSS_GLONASS], strict=True):
        assert truth[int(s)] == int(k)
    decoded = [e for e in iter_navigation(f for f in frames if f.protocol is Protocol.UBX)
               if isinstance(e, GlonassEphemeris)]
    tracked = {int(s) for s in ep.sv_id[ep.gnss_id == GNSS_GLONASS]}
    assert {e.slot for e in decoded} == tracked
    ephs = _glonass_ephemerides(world)
    for e in decoded:
        _same(e, ephs[e.slot])


def _cfg_gnss(core, rows: list[dict]) -> list:
    from hil_sim import ubx_encode as enc

    payload = enc.pack(enc.LAYOUTS["CFG-GNSS"], {"msgVer": 0, "numTrkChHw": 32, "numTrkChUse": 32}, rows)
    return send(core, "CFG-GNSS", raw_payload=payload)


def test_galileo_inav_words_round_trip_through_the_decoder_and_the_crc() -> None:
    world = World(Scenario.multi("gej-2021", duration_s=120.0))
    nav = world.broadcast_navigation()
    sats = [sv for g, sv in nav.satellites() if g == GNSS_GALILEO]
    assert len(sats) >= 10
    for sv in sats:
        eph = nav.select(GNSS_GALILEO, sv, world.start)
        assert eph is not None and eph.code_on_l2 & 0x001  # the world broadcasts I/NAV (E1-B) sets
        words = galp.words(eph)
        pages = {t: galp.sfrbx_words(w) for t, w in words.items()}
        with pytest.raises(GalileoNavError):
            inav_word([pages[1][0] ^ 0x1000, *pages[1][1:]])  # a flipped data bit fails the CRC
        got = ephemeris_from_words({t: inav_word(p) for t, p in pages.items()})
        _same_kepler(got, dataclasses.replace(eph, code_on_l2=DATA_SOURCE_E1B))


def test_emulated_m8t_sends_qzss_lnav_subframes_and_galileo_rawx() -> None:
    world = World(Scenario.multi("gej-2021", duration_s=120.0))
    core = core_for("m8t", world, time_valid_after_s=1.0)  # factory CFG-GNSS: GPS, Galileo, BeiDou, QZSS on
    configure(core, meas_ms=1000)
    frames = run(core, 40.0, step_s=0.5)
    raw = [decode_rxm_rawx(f.payload) for f in ubx_of(frames, (0x02, 0x15))]
    last = next(ep for ep in reversed(raw) if ep is not None)
    assert {GNSS_GALILEO, GNSS_QZSS} <= set(last.gnss_id.tolist())
    decoded = [e for e in iter_navigation(f for f in frames if f.protocol is Protocol.UBX)
               if not isinstance(e, GlonassEphemeris) and e.gnss_id == GNSS_QZSS]
    tracked = {int(s) for s in last.sv_id[last.gnss_id == GNSS_QZSS]}
    assert {e.prn for e in decoded} == tracked and len(tracked) >= 3
    nav = world.broadcast_navigation()
    for e in decoded:
        ref = nav.select(GNSS_QZSS, e.prn, world.start)
        assert ref is not None and e.toe == ref.toe and e.iode == ref.iode
        assert e.sqrt_a == pytest.approx(ref.sqrt_a, rel=1e-9) and e.e == pytest.approx(ref.e, abs=1e-9)
        assert e.af0_s == pytest.approx(ref.af0_s, abs=1e-12)
    gal = [e for e in iter_navigation(f for f in frames if f.protocol is Protocol.UBX)
           if not isinstance(e, GlonassEphemeris) and e.gnss_id == GNSS_GALILEO]
    assert {e.prn for e in gal} == {int(s) for s in last.sv_id[last.gnss_id == GNSS_GALILEO]}
    for e in gal:
        ref = nav.select(GNSS_GALILEO, e.prn, world.start)
        assert ref is not None
        _same_kepler(e, dataclasses.replace(ref, code_on_l2=DATA_SOURCE_E1B))
