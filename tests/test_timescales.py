"""orbitcal.timescales against Skyfield's builtin timescale (IERS leap seconds) and chaosmagpy."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orbitcal import timescales as ts

T_2017 = 1_483_228_800.0  # 2017-01-01T00:00:00Z
DAY_S = 86_400.0


def _skyfield_tai_minus_utc_s(t_utc_s: np.ndarray) -> np.ndarray:
    """TAI − UTC from Skyfield's UTC constructor (its own leap-second table)."""
    sf = ts.skyfield_timescale()
    dt = pd.to_datetime(t_utc_s, unit="s")
    t = sf.utc(
        dt.year.to_numpy(),
        dt.month.to_numpy(),
        dt.day.to_numpy(),
        dt.hour.to_numpy(),
        dt.minute.to_numpy(),
        dt.second.to_numpy() + dt.microsecond.to_numpy() * 1e-6,
    )
    tai_s = (t.whole - 2440587.5) * DAY_S + t.tai_fraction * DAY_S
    return np.asarray(tai_s - t_utc_s)


def test_leap_second_table_matches_skyfield_1972_to_2026() -> None:
    t = np.arange(63_072_000.0, 1.80e9, 3.7 * DAY_S)  # 1972-01-01 .. 2027, every 3.7 days
    np.testing.assert_allclose(ts.tai_minus_utc_s(t), _skyfield_tai_minus_utc_s(t), atol=1e-5)


def test_leap_second_boundaries() -> None:
    edges = [
        T_2017,
        1_435_708_800.0,
        1_341_100_800.0,
        1_230_768_000.0,
    ]  # 2017, 2015-07, 2012-07, 2009
    for edge in edges:
        t = np.array([edge - 1.0, edge - 1e-3, edge, edge + 1e-3])
        np.testing.assert_allclose(ts.tai_minus_utc_s(t), _skyfield_tai_minus_utc_s(t), atol=1e-5)
    np.testing.assert_array_equal(ts.tai_minus_utc_s([T_2017 - 0.5, T_2017]), [36.0, 37.0])
    assert np.isnan(ts.tai_minus_utc_s([0.0])[0])  # 1970: before the table


def test_utc_tai_gps_round_trips() -> None:
    rng = np.random.default_rng(0)
    t = rng.uniform(1.0e8, 1.8e9, 10_000)
    np.testing.assert_array_equal(ts.tai_to_utc(ts.utc_to_tai(t)), t)
    np.testing.assert_array_equal(ts.gps_to_utc(ts.utc_to_gps(t)), t)
    for scale in ts.TIME_SCALES:
        np.testing.assert_array_equal(ts.to_utc_s(ts.from_utc_s(t, scale=scale), scale=scale), t)
    # GPS − UTC = 18 s since 2017, GPS = TAI − 19 s always (IS-GPS-200).
    np.testing.assert_array_equal(ts.utc_to_gps([T_2017]) - T_2017, [18.0])
    np.testing.assert_array_equal(ts.utc_to_tai(t) - ts.utc_to_gps(t), np.full(t.size, 19.0))


def test_tai_inside_leap_second_maps_to_next_day() -> None:
    tai = T_2017 + 36.0 + np.array([-0.5, 0.0, 0.5, 1.0])  # 23:59:59.5, 23:59:60.0, 60.5, 00:00:00
    np.testing.assert_array_equal(ts.tai_to_utc(tai), T_2017 + np.array([-0.5, 0.0, 0.5, 0.0]))


def test_to_utc_s_scales_and_error() -> None:
    np.testing.assert_array_equal(ts.to_utc_s([T_2017 + 37.0], scale="TAI"), [T_2017])
    np.testing.assert_array_equal(ts.to_utc_s([T_2017 + 18.0], scale="gps"), [T_2017])
    with pytest.raises(ts.TimeScaleError, match="UTC, TAI, GPS"):
        ts.to_utc_s([0.0], scale="TT")
    assert issubclass(ts.TimeScaleError, ValueError)


def test_skyfield_round_trip_across_2016_leap_second() -> None:
    t = T_2017 + np.array([-2.0, -1.0, -0.25, 0.0, 0.25, 1.0, 3600.0])
    sky = ts.utc_s_to_skyfield(t)
    assert sky.utc_iso()[1] == "2016-12-31T23:59:59Z"
    assert sky.utc_iso()[3] == "2017-01-01T00:00:00Z"
    # TT − UTC = 32.184 s + TAI − UTC
    np.testing.assert_allclose(
        (sky.tt - 2440587.5) * DAY_S - t, 32.184 + np.r_[[36.0] * 3, [37.0] * 4], atol=2e-5
    )
    np.testing.assert_allclose(ts.skyfield_to_utc_s(sky), t, atol=1e-6)
    ref = ts.skyfield_timescale().utc(2016, 12, 31, 23, 59, 59.75)
    np.testing.assert_allclose(ts.utc_s_to_skyfield(T_2017 - 0.25).tt, ref.tt, atol=1e-11)


def test_ut1_minus_utc_from_skyfield() -> None:
    # IERS: UT1 − UTC jumped by +1 s at the 2016 leap second (−0.41 s → +0.59 s).
    dut1 = ts.ut1_minus_utc_s([T_2017 - 10.0, T_2017 + 10.0])
    assert dut1[1] - dut1[0] == pytest.approx(1.0, abs=1e-3)
    assert np.all(np.abs(dut1) < 0.9)


def test_parse_iso_and_numbers() -> None:
    values = [
        "2017-01-01T00:00:00Z",
        "2017-01-01T00:00:00.5+00:00",
        "2017-01-01T02:00:00+02:00",
        "1483228800.25",
        1483228800.75,
        "2016-12-31T23:59:60Z",  # leap second: POSIX reads it as the next day's first second
        "2017-01-01T00:00:00",  # no zone
        "yesterday",
        None,
        float("nan"),
        True,
    ]
    t, errors = ts.parse_time_values(values)
    np.testing.assert_array_equal(t[:6], T_2017 + np.array([0.0, 0.5, 0.0, 0.25, 0.75, 0.0]))
    assert np.all(np.isnan(t[6:]))
    rows = [row for row, _ in errors]
    assert rows == [6, 7, 8, 9, 10]
    assert "time zone" in errors[0][1]
    assert "yesterday" in errors[1][1]


@pytest.mark.parametrize("dtype", [object, "string", "string[pyarrow]"])
def test_parse_pandas_string_dtypes(dtype: str) -> None:
    series = pd.Series(["2017-01-01T00:00:00Z", "1483228800.5", "bad", None], dtype=dtype)
    t, errors = ts.parse_time_values(series)
    np.testing.assert_array_equal(t[:2], [T_2017, T_2017 + 0.5])
    assert [row for row, _ in errors] == [2, 3]


def test_parse_numeric_array_and_nonfinite() -> None:
    t, errors = ts.parse_time_values(np.array([1.0, np.inf, 3.0]))
    assert [r for r, _ in errors] == [1]
    assert t[0] == 1.0 and np.isnan(t[1])


def test_iso_round_trip_microseconds() -> None:
    rng = np.random.default_rng(5)
    t = np.round(rng.uniform(0.0, 1.8e9, 20_000) * 1e6) / 1e6
    iso = ts.utc_s_to_iso(t)
    assert all(s.endswith("Z") and len(s) == 27 for s in iso)
    back, errors = ts.parse_time_values(iso)
    assert not errors
    np.testing.assert_allclose(back, t, atol=1e-6, rtol=0)
    np.testing.assert_allclose(ts.iso_to_utc_s(iso), t, atol=1e-6, rtol=0)
    assert ts.utc_s_to_iso([T_2017 + 0.5]) == ["2017-01-01T00:00:00.500000Z"]
    assert ts.utc_s_to_iso([np.nan]) == ["NaT"]


def test_mjd2000_and_decimal_year_match_chaosmagpy() -> None:
    from chaosmagpy import data_utils

    rng = np.random.default_rng(6)
    t = rng.uniform(9.0e8, 1.8e9, 2000)
    mjd = ts.utc_s_to_mjd2000(t)
    assert ts.utc_s_to_mjd2000([ts.MJD2000_EPOCH_UTC_S])[0] == 0.0
    assert data_utils.mjd2000(2016, 12, 31, 12) == pytest.approx(
        ts.utc_s_to_mjd2000(T_2017 - 43200.0)
    )
    np.testing.assert_allclose(
        data_utils.mjd_to_dyear(mjd, leap_year=True),
        ts.utc_s_to_decimal_year(t),
        atol=1e-10,
        rtol=0,
    )
    np.testing.assert_allclose(ts.mjd2000_to_utc_s(mjd), t, atol=1e-6, rtol=0)
    np.testing.assert_allclose(
        ts.decimal_year_to_utc_s(ts.utc_s_to_decimal_year(t)), t, atol=1e-5, rtol=0
    )
    assert ts.utc_s_to_decimal_year([T_2017])[0] == 2017.0


@settings(max_examples=200, deadline=None)
@given(st.integers(min_value=-2_208_988_800 * 10**6, max_value=7_258_118_400 * 10**6))
def test_iso_round_trip_property_1900_2200(t_us: int) -> None:
    t = t_us / 1e6
    iso = ts.utc_s_to_iso([t])[0]
    assert iso == np.datetime_as_string(np.datetime64(t_us, "us"), unit="us") + "Z"
    back, errors = ts.parse_time_values([iso])
    assert not errors
    assert abs(back[0] - t) < 1e-6


def test_one_instant_from_a_user_iso_or_seconds_and_errors_name_the_field() -> None:
    from orbitcal.errors import BadInputError

    assert ts.parse_instant_utc_s("2022-08-01T00:00:00Z", field="start") == 1_659_312_000.0
    assert ts.parse_instant_utc_s("2022-08-01T02:00:00+02:00", field="start") == 1_659_312_000.0
    assert ts.parse_instant_utc_s(1_659_312_000, field="start") == 1_659_312_000.0
    # numeric text is seconds only where asked (query parameters); else it must be ISO-8601
    assert ts.parse_instant_utc_s("1659312000", field="end", numeric_text=True) == 1_659_312_000.0
    cases: list[tuple[float | str, bool, str]] = [
        ("1659312000", False, "is not an ISO-8601 time"),
        ("yesterday", True, "'yesterday' is not an ISO-8601 time"),
        ("2022-08-01T00:00:00", False, "needs a UTC offset"),
        ("nan", True, "nan is not a finite time within ±1e11 s of 1970"),
        ("-Infinity", True, "-Infinity is not a finite time"),
        ("1_000", True, "'1_000' is not an ISO-8601 time nor a number"),  # issue 44
        ("١٢", True, "nor a number in ASCII decimals"),
        (" 12", True, "nor a number in ASCII decimals"),
        ("+12", True, "nor a number in ASCII decimals"),
        (float("-inf"), False, "-inf is not a finite time"),
        (1e300, False, "1e+300 is not a finite time"),
        (10**400, False, "is not a finite time"),  # too large for a float: no OverflowError
        (-(10**30), False, "is not a finite time"),
    ]
    for value, numeric_text, message in cases:
        with pytest.raises(BadInputError) as info:
            ts.parse_instant_utc_s(value, field="end", numeric_text=numeric_text)
        assert message in str(info.value)
        assert info.value.field == "end" and str(info.value).startswith("end: ")
        assert len(str(info.value)) < 120  # a huge value is cut, not echoed whole
