"""Bit-exact RTCM 10403.3 payload encoders: 1005, MSM4/MSM7 observations and 1230.

Field widths and resolutions follow the standard's data-field table (DF numbers in comments).
Every function returns a message payload; wrap it with `protocol.rtcm.build_frame`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from sim.gnss.bits import BitWriter
from sim.gnss.sky import SPEED_OF_LIGHT, SatelliteObservation

LIGHT_MS_M = SPEED_OF_LIGHT / 1000.0  # metres per light-millisecond
P2_10, P2_24, P2_29, P2_31 = 2.0**-10, 2.0**-24, 2.0**-29, 2.0**-31


def encode_1005(
    station_id: int,
    ecef_m: tuple[float, float, float],
    *,
    gps: bool = True,
    glonass: bool = False,
    galileo: bool = True,
) -> bytes:
    """1005: stationary reference station antenna reference point, ECEF at 0.1 mm."""
    x, y, z = (round(v / 0.0001) for v in ecef_m)
    w = BitWriter()
    w.uint(1005, 12)  # DF002
    w.uint(station_id, 12)  # DF003
    w.uint(0, 6)  # DF021 ITRF realisation year (reserved)
    w.flag(gps).flag(glonass).flag(galileo)  # DF022, DF023, DF024
    w.flag(False)  # DF141 physical reference station
    w.sint(x, 38)  # DF025
    w.flag(False)  # DF142 single receiver oscillator
    w.uint(0, 1)  # DF001 reserved
    w.sint(y, 38)  # DF026
    w.uint(0, 2)  # DF364 quarter cycle indicator
    w.sint(z, 38)  # DF027
    return w.to_bytes()


def encode_1230(
    station_id: int,
    biases_m: tuple[float | None, float | None, float | None, float | None],
    *,
    aligned: bool = False,
) -> bytes:
    """1230: GLONASS L1 C/A, L1 P, L2 C/A, L2 P code-phase biases (None = not sent), 0.02 m."""
    w = BitWriter()
    w.uint(1230, 12)  # DF002
    w.uint(station_id, 12)  # DF003
    w.flag(aligned)  # DF421
    w.uint(0, 3)  # DF001 reserved
    for bias in biases_m:  # DF422 signals mask, 4 bits
        w.flag(bias is not None)
    for bias in biases_m:  # DF423..DF426
        if bias is not None:
            w.sint(round(bias / 0.02), 16)
    return w.to_bytes()


def lock_indicator_msm4(lock_ms: int) -> int:
    """DF402: 4-bit lock time indicator, i such that lock time >= 2**(i+4) ms."""
    if lock_ms < 32:
        return 0
    return min(15, int(math.log2(lock_ms)) - 4)


def lock_indicator_msm7(lock_ms: int) -> int:
    """DF407: 10-bit extended lock time indicator (largest i whose minimum lock time is reached)."""
    if lock_ms < 64:
        return max(0, lock_ms)
    n = min(int(math.log2(lock_ms)) - 5, 21)
    if n == 21:  # the top row holds a single value, 704
        return 704
    return 64 + 32 * (n - 1) + (lock_ms - (1 << (n + 5))) // (1 << n)


def encode_msm(
    message_number: int,
    station_id: int,
    tow_ms: int,
    satellites: Sequence[SatelliteObservation],
    *,
    multiple_message: bool,
) -> bytes:
    """MSM4 (107x/109x with x=4) or MSM7 (x=7) for GPS/Galileo-style epoch time (DF004/DF248)."""
    msm = message_number % 10
    if msm not in (4, 7):
        raise ValueError(f"only MSM4 and MSM7 are supported, not {message_number}")
    sats = sorted(satellites, key=lambda s: s.prn)
    sig_ids = sorted({o.signal.rtcm_id for s in sats for o in s.signals})
    if len(sats) * len(sig_ids) > 64:
        raise ValueError("MSM cell mask is limited to 64 cells")

    w = BitWriter()
    w.uint(message_number, 12)  # DF002
    w.uint(station_id, 12)  # DF003
    w.uint(tow_ms, 30)  # DF004 / DF248 epoch time, ms of week
    w.flag(multiple_message)  # DF393
    w.uint(0, 3)  # DF409 IODS
    w.uint(0, 7)  # DF001 reserved
    w.uint(0, 2)  # DF411 clock steering
    w.uint(0, 2)  # DF412 external clock
    w.flag(False)  # DF417 smoothing
    w.uint(0, 3)  # DF418 smoothing interval
    sat_mask = 0
    for s in sats:
        sat_mask |= 1 << (64 - s.prn)
    w.uint(sat_mask, 64)  # DF394
    sig_mask = 0
    for sid in sig_ids:
        sig_mask |= 1 << (32 - sid)
    w.uint(sig_mask, 32)  # DF395
    cells = []
    for s in sats:  # DF396 cell mask, satellite-major
        by_id = {o.signal.rtcm_id: o for o in s.signals}
        for sid in sig_ids:
            w.flag(sid in by_id)
            if sid in by_id:
                cells.append((s.prn, by_id[sid]))

    # satellite data: rough range (integer ms + 2^-10 ms) from the geometric+clock range
    rough_units = [round(s.range_m / LIGHT_MS_M / P2_10) for s in sats]
    rough_ms = {s.prn: u * P2_10 for s, u in zip(sats, rough_units, strict=True)}
    for u in rough_units:
        w.uint(u >> 10, 8)  # DF397
    if msm == 7:
        for _ in sats:
            w.uint(0, 4)  # extended satellite information
    for u in rough_units:
        w.uint(u & 0x3FF, 10)  # DF398
    rough_rates = {s.prn: round(s.range_rate_mps) for s in sats}
    if msm == 7:
        for s in sats:
            w.sint(rough_rates[s.prn], 14)  # DF399

    # signal data, cell by cell in the order of the cell mask
    pr_res, ph_res, pr_bits, ph_bits = (
        (P2_29, P2_31, 20, 24) if msm == 7 else (P2_24, P2_29, 15, 22)
    )
    for prn, obs in cells:
        fine = obs.pseudorange_m / LIGHT_MS_M - rough_ms[prn]
        w.sint(round(fine / pr_res), pr_bits)  # DF400 / DF405
    for prn, obs in cells:
        fine = obs.phase_range_m / LIGHT_MS_M - rough_ms[prn]
        w.sint(round(fine / ph_res), ph_bits)  # DF401 / DF406
    for _, obs in cells:
        if msm == 7:
            w.uint(lock_indicator_msm7(obs.lock_time_ms), 10)  # DF407
        else:
            w.uint(lock_indicator_msm4(obs.lock_time_ms), 4)  # DF402
    for _ in cells:
        w.flag(False)  # DF420 half-cycle ambiguity
    for _, obs in cells:
        if msm == 7:
            w.uint(min(1023, max(1, round(obs.cnr_dbhz * 16))), 10)  # DF408, 2^-4 dB-Hz
        else:
            w.uint(min(63, max(1, round(obs.cnr_dbhz))), 6)  # DF403, 1 dB-Hz
    if msm == 7:
        for prn, obs in cells:
            fine_rate = obs.phase_range_rate_mps - rough_rates[prn]
            w.sint(round(fine_rate / 0.0001), 15)  # DF404
    return w.to_bytes()
