"""The simulated base receiver's RTCM3 messages: bit-exact, CRC-correct, decoded right by pyrtcm."""

from __future__ import annotations

import math

import pytest
from pyrtcm import RTCMReader
from pyrtcm.rtcmhelpers import parse_msm

from protocol.rtcm import Reframer, frame_ok, message_type
from sim.gnss import BaseStationModel, GnssConfig
from sim.gnss.bits import BitWriter
from sim.gnss.messages import LIGHT_MS_M, lock_indicator_msm4, lock_indicator_msm7
from sim.gnss.sky import WGS84_A, WGS84_F, geodetic_to_ecef


def ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    """Independent inverse (fixed-point iteration) to check the 1005 round trip."""
    e2 = WGS84_F * (2 - WGS84_F)
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1 - e2))
    h = 0.0
    for _ in range(10):
        n = WGS84_A / math.sqrt(1 - e2 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - n
        lat = math.atan2(z, p * (1 - e2 * n / (n + h)))
    return math.degrees(lat), math.degrees(lon), h


def test_bit_writer_packs_msb_first_and_rejects_overflow() -> None:
    w = BitWriter().uint(0b101, 3).sint(-1, 4).uint(1, 1)
    assert w.nbits == 8
    assert w.to_bytes() == bytes([0b10111111])
    assert BitWriter().sint(-2, 38).to_bytes() == ((1 << 38) - 2 << 2).to_bytes(5, "big")
    assert BitWriter().uint(1, 1).to_bytes() == b"\x80"
    with pytest.raises(ValueError):
        BitWriter().uint(8, 3)
    with pytest.raises(ValueError):
        BitWriter().sint(8, 4)
    with pytest.raises(ValueError):
        BitWriter().uint(-1, 4)


def test_geodetic_to_ecef_known_points() -> None:
    x, y, z = geodetic_to_ecef(0.0, 0.0, 0.0)
    assert (x, y, z) == pytest.approx((WGS84_A, 0.0, 0.0), abs=1e-6)
    x, y, z = geodetic_to_ecef(90.0, 0.0, 0.0)
    assert z == pytest.approx(6_356_752.314245, abs=1e-3)
    assert math.hypot(x, y) < 1e-6


def test_lock_time_indicators_follow_the_tables() -> None:
    assert [lock_indicator_msm4(t) for t in (0, 31, 32, 64, 1000, 10**9)] == [0, 0, 1, 2, 5, 15]
    # DF407: i -> minimum lock time, inverted
    assert lock_indicator_msm7(63) == 63
    assert lock_indicator_msm7(64) == 64
    assert lock_indicator_msm7(65) == 64
    assert lock_indicator_msm7(127) == 95
    assert lock_indicator_msm7(128) == 96
    assert lock_indicator_msm7(1000) == 190  # row 160..191: t = 16i - 2048 = 992 <= 1000
    assert lock_indicator_msm7(10**12) == 704
    previous = -1
    for t in range(0, 70_000, 7):
        i = lock_indicator_msm7(t)
        assert i >= previous
        previous = i


@pytest.mark.parametrize("msm", [4, 7])
def test_every_frame_of_many_epochs_parses_and_decodes_to_the_model(msm: int) -> None:
    cfg = GnssConfig(station_id=2301, msm=msm, seed=7, gps_satellites=10, galileo_satellites=8)
    model = BaseStationModel(cfg)
    pr_tol_m = (2**-24 if msm == 4 else 2**-29) * LIGHT_MS_M
    ph_tol_m = (2**-29 if msm == 4 else 2**-31) * LIGHT_MS_M
    epochs = [*range(0, 20), 3_600, 86_399, 604_790]
    for epoch in epochs:
        frames = model.frames(epoch)
        assert [message_type(f) for f in frames] == [1005, 1070 + msm, 1090 + msm, 1230]
        for frame in frames:
            assert frame_ok(frame)
            msg = RTCMReader.parse(frame, validate=1)  # raises on a bad CRC
            assert msg.DF003 == 2301
        ref = RTCMReader.parse(frames[0])
        assert (ref.DF022, ref.DF023, ref.DF024) == (1, 0, 1)
        lat, lon, h = ecef_to_geodetic(ref.DF025, ref.DF026, ref.DF027)
        assert lat == pytest.approx(41.1780, abs=1e-8)
        assert lon == pytest.approx(-8.5980, abs=1e-8)
        assert h == pytest.approx(120.0, abs=2e-4)
        for frame, sky in ((frames[1], model.gps), (frames[2], model.galileo)):
            msg = RTCMReader.parse(frame)
            meta, sats, cells = parse_msm(msg)
            assert meta["epoch"] == model.tow_ms(epoch)
            assert msg.DF393 == (1 if sky is model.gps else 0)
            assert [int(s["PRN"]) for s in sats] == list(sky.prns)
            assert msg.DF394 == sum(1 << (64 - p) for p in sky.prns)
            assert msg.NSig == 2 and msg.NCell == 2 * len(sky.prns)
            truth = {s.prn: s for s in sky.observe(float(epoch), epoch * 1000 + 500)}
            codes = [o.code for o in sky.constellation.signals]
            for cell in cells:
                prn = int(cell["CELLPRN"])
                assert cell["CELLSIG"] in codes
                sat = next(s for s in sats if int(s["PRN"]) == prn)
                obs = next(o for o in truth[prn].signals if o.signal.code == cell["CELLSIG"])
                rough_ms = sat["DF397"] + sat["DF398"]
                pr_field, ph_field = ("DF400", "DF401") if msm == 4 else ("DF405", "DF406")
                assert (rough_ms + cell[pr_field]) * LIGHT_MS_M == pytest.approx(
                    obs.pseudorange_m, abs=pr_tol_m
                )
                assert (rough_ms + cell[ph_field]) * LIGHT_MS_M == pytest.approx(
                    obs.phase_range_m, abs=ph_tol_m
                )
                if msm == 7:
                    assert cell["DF408"] == pytest.approx(obs.cnr_dbhz, abs=1 / 32)
                    rate = sat["DF399"] + cell["DF404"]
                    assert rate == pytest.approx(obs.phase_range_rate_mps, abs=0.0001)
                else:
                    assert cell["DF403"] == round(obs.cnr_dbhz)
                assert 30 <= obs.cnr_dbhz <= 56
                assert 19_000_000 < obs.pseudorange_m < 30_000_000
        biases = RTCMReader.parse(frames[3])
        assert (biases.DF422_1, biases.DF422_2, biases.DF422_3, biases.DF422_4) == (1, 0, 1, 0)
        assert biases.DF423 == pytest.approx(-71.94) and biases.DF425 == pytest.approx(-71.94)


def test_pyrtcm_stream_reader_reads_a_concatenated_stream_with_crc_checks() -> None:
    import io

    model = BaseStationModel(GnssConfig())
    stream = b"".join(f for e in range(10) for f in model.frames(e))
    reader = RTCMReader(io.BytesIO(stream), validate=1, quitonerror=2)
    identities = [parsed.identity for _, parsed in reader]
    assert identities == ["1005", "1077", "1097", "1230"] * 10


def test_model_is_deterministic_per_seed_and_varies_across_seeds() -> None:
    a, b = BaseStationModel(GnssConfig(seed=3)), BaseStationModel(GnssConfig(seed=3))
    assert a.frames(42) == b.frames(42)
    c = BaseStationModel(GnssConfig(seed=4))
    assert a.gps.prns != c.gps.prns or a.frames(42) != c.frames(42)
    assert a.frames(1) != a.frames(2)


def test_reference_messages_every_n_epochs() -> None:
    model = BaseStationModel(GnssConfig(reference_every=5))
    types = [[message_type(f) for f in model.frames(e)] for e in range(6)]
    assert types[0] == [1005, 1077, 1097, 1230]
    assert types[1] == [1077, 1097]
    assert types[5] == [1005, 1077, 1097, 1230]
    stream = b"".join(f for e in range(6) for f in model.frames(e))
    reframer = Reframer()
    assert len(list(reframer.feed(stream))) == 4 + 4 * 2 + 4
    assert reframer.bad_frames == 0 and reframer.skipped_bytes == 0


@pytest.mark.parametrize(("msm", "per_sat", "per_cell"), [(4, 18, 48), (7, 36, 80)])
def test_msm_payload_sizes_match_the_standard(msm: int, per_sat: int, per_cell: int) -> None:
    """Header 169 bits + cell mask + per-satellite and per-cell fields, padded to a byte."""
    model = BaseStationModel(GnssConfig(msm=msm, gps_satellites=12, galileo_satellites=5))
    for frame, nsat in ((model.frames(3)[1], 12), (model.frames(3)[2], 5)):
        nsig, ncell = 2, 2 * nsat
        bits = 169 + nsat * nsig + per_sat * nsat + per_cell * ncell
        assert len(frame) - 6 == math.ceil(bits / 8)
    assert len(model.frames(0)[0]) - 6 == 152 // 8  # 1005: 152 bits
    assert len(model.frames(0)[3]) - 6 == math.ceil((32 + 2 * 16) / 8)  # 1230 with two biases
