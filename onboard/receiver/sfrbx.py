"""RXM-SFRBX of every constellation → `SfrbxWords` (header fields + data words), and the navigation messages
of a UBX byte stream → ephemerides through the pure `onboard.rtk.navdecode.NavMessageDecoder`.

`decode_sfrbx` unpacks any RXM-SFRBX (u-blox 8 / M8 Receiver Description, UBX-RXM-SFRBX): gnssId, svId,
sigId (F9; 0 on the M8), freqId (GLONASS k + 7), the words. `iter_navigation` walks decoded frames, keeps the
latest RXM-RAWX receiver time and leap seconds as the reference the GLONASS/GPS decoders need, and yields each
new ephemeris (GPS, QZSS, GLONASS, Galileo, BeiDou). The GPS-only path of `onboard.receiver.decode` is unchanged.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

from onboard.gnsstime import GpsTime
from onboard.receiver.decode import DecodeError, decode_rxm_rawx
from onboard.receiver.framing import Frame, Protocol
from onboard.rtk.navdecode import NavMessageDecoder
from onboard.rtk.types import Ephemeris, GlonassEphemeris

RXM_SFRBX_HEADER = struct.Struct("<BBBBBBBx")  # gnssId svId sigId freqId numWords chn version reserved
_ID_RXM_SFRBX = (0x02, 0x13)
_ID_RXM_RAWX = (0x02, 0x15)
DEFAULT_LEAP_S = 18
"""GPST − UTC assumed until a RXM-RAWX reports its own (valid since 2017-01-01)."""


@dataclass(frozen=True, slots=True)
class SfrbxWords:
    """One RXM-SFRBX message: `gnss_id`, `sv_id`, `sig_id`, `freq_id` (GLONASS k + 7), `words` (32-bit)."""

    gnss_id: int
    sv_id: int
    sig_id: int
    freq_id: int
    words: tuple[int, ...]


def decode_sfrbx(payload: bytes) -> SfrbxWords:
    """RXM-SFRBX payload → SfrbxWords; DecodeError when the length does not match numWords."""
    if len(payload) < RXM_SFRBX_HEADER.size:
        raise DecodeError("RXM-SFRBX payload shorter than its header")
    gnss, svid, sig, freq, num_words, _chn, _ver = RXM_SFRBX_HEADER.unpack_from(payload)
    if len(payload) != RXM_SFRBX_HEADER.size + 4 * num_words:
        raise DecodeError(f"RXM-SFRBX with numWords={num_words} has {len(payload)} bytes")
    words = struct.unpack_from(f"<{num_words}I", payload, RXM_SFRBX_HEADER.size)
    return SfrbxWords(gnss, svid, sig, freq, tuple(words))


def iter_navigation(frames: Iterable[Frame], decoder: NavMessageDecoder | None = None
                    ) -> Iterator[Ephemeris | GlonassEphemeris]:
    """Every new ephemeris carried by the RXM-SFRBX frames of `frames` (UBX; others are skipped).

    The reference time is the latest RXM-RAWX epoch (SFRBX before the first one are skipped: no week, no day),
    its leap seconds (when the receiver marks them valid) set the GLONASS time offset.
    """
    decoder = decoder or NavMessageDecoder(DEFAULT_LEAP_S)
    reference: GpsTime | None = None
    for frame in frames:
        if frame.protocol is not Protocol.UBX:
            continue
        key = (frame.msg_class, frame.msg_id)
        try:
            if key == _ID_RXM_RAWX:
                epoch = decode_rxm_rawx(frame.payload)
                if epoch is not None:
                    reference = epoch.time
                    if epoch.leap_s is not None:
                        decoder.leap_s = epoch.leap_s
            elif key == _ID_RXM_SFRBX and reference is not None:
                m = decode_sfrbx(frame.payload)
                eph = decoder.add(m.gnss_id, m.sv_id, m.sig_id, m.freq_id, m.words, reference)
                if eph is not None:
                    yield eph
        except DecodeError:
            continue
