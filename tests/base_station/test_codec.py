"""Pure encode/decode of the PLC register image."""

from __future__ import annotations

import dataclasses

import pytest
from hypothesis import given
from hypothesis import strategies as st

from base_station.plc import ChargerState, FaultBit, PowerSource, RawImage, decode, encode
from base_station.plc.codec import DecodeError


def raw(**ir: int) -> RawImage:
    inputs = [0] * 20
    inputs[11] = 65535
    for k, v in ir.items():
        inputs[int(k[1:])] = v
    return RawImage((False,) * 7, (False,) * 11, tuple(inputs), (0, 0))


def test_scale_mass_is_uint32_high_word_first() -> None:
    s = decode(raw(r0=0x0001, r1=0x86A0))
    assert s.scale_mass_g == 100_000


def test_temperature_is_int16_tenths() -> None:
    assert decode(raw(r6=(-85) & 0xFFFF)).temperature_c == -8.5
    assert decode(raw(r6=215)).temperature_c == 21.5


def test_units_of_every_scaled_register() -> None:
    s = decode(
        raw(
            r2=345,
            r3=1210,
            r4=270,
            r5=25,
            r7=655,
            r9=4000,
            r10=2520,
            r11=937,
            r12=850,
            r13=1265,
            r14=220,
            r15=1,
            r16=400,
            r17=1000,
            r18=33,
            r19=7,
        )
    )
    assert (s.wind_speed_mps, s.wind_gust_mps, s.wind_direction_deg) == (3.45, 12.1, 270)
    assert (s.rain_rate_mm_h, s.humidity_pct) == (2.5, 65.5)
    assert (s.charge_current_ma, s.charge_voltage_v, s.uav_battery_soc_pct) == (4000, 25.2, 93.7)
    assert (s.base_battery_soc_pct, s.base_battery_voltage_v, s.solar_power_w) == (85.0, 12.65, 220)
    assert s.power_source is PowerSource.SOLAR
    assert (s.panel_position_pct, s.lift_position_pct) == (40.0, 100.0)
    assert s.fault_bits == FaultBit.PANEL_STALL | FaultBit.ESTOP
    assert s.fault_names == ("PANEL_STALL", "ESTOP")
    assert s.heartbeat == 7


def test_unknown_soc_and_undefined_enum_codes_decode_to_none() -> None:
    s = decode(raw(r8=9, r15=7))
    assert s.uav_battery_soc_pct is None and s.charger_state is None and s.power_source is None


def test_short_image_is_a_decode_error() -> None:
    with pytest.raises(DecodeError):
        decode(RawImage((False,) * 7, (False,) * 11, (0,) * 5, (0, 0)))


def test_pending_command_coils_decode() -> None:
    image = RawImage(
        (True, False, False, False, False, True, False), (False,) * 11, raw().inputs, (0, 0)
    )
    s = decode(image)
    assert s.charger_enable and [c.name for c in s.pending_commands] == ["PANELS_OPEN"]


u16 = st.integers(0, 65535)


@given(
    coils=st.tuples(*[st.booleans()] * 7),
    discrete=st.tuples(*[st.booleans()] * 11),
    inputs=st.tuples(
        u16,
        u16,
        u16,
        u16,
        st.integers(0, 359),
        u16,
        u16,
        u16,
        st.sampled_from([0, 1, 2, 3]),
        u16,
        u16,
        u16,
        u16,
        u16,
        u16,
        st.sampled_from([0, 1, 2]),
        st.integers(0, 1000),
        st.integers(0, 1000),
        st.integers(0, 63),
        u16,
    ),
    holding=st.tuples(u16, u16),
)
def test_decode_then_encode_is_identity(coils, discrete, inputs, holding) -> None:  # type: ignore[no-untyped-def]
    image = RawImage(coils, discrete, inputs, holding)
    assert encode(decode(image)) == image


def test_encode_then_decode_keeps_values() -> None:
    s = decode(raw(r0=0, r1=1515, r8=1, r11=500))
    s2 = dataclasses.replace(s, charger_state=ChargerState.COMPLETE, temperature_c=-3.2)
    assert decode(encode(s2)) == s2
