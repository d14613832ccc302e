"""The CONTRACT section-1 telemetry table: round trips, row-level validation, time scales."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from orbitcal.telemetry import (
    ReadResult,
    RowError,
    Telemetry,
    TelemetryError,
    from_frame,
    parse_telemetry,
    read_telemetry,
    write_field_csv,
    write_telemetry,
)

FORMATS = ("csv", "parquet", "ndjson", "json")
T0_UTC_S = 1_690_000_000.0  # 2023-07-22T04:26:40Z
ONE_MICROSECOND_S = 1e-6  # the writers' time resolution (ISO-8601 with µs)


def _table(n: int = 50, *, seed: int = 0) -> Telemetry:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    r = rng.normal(size=(n, 3))
    r *= 6800.0 / np.linalg.norm(r, axis=1, keepdims=True)
    return Telemetry(
        t_utc_s=T0_UTC_S + np.arange(n) * 1.5 + 0.123456,
        b_raw_nt=rng.normal(size=(n, 3)) * 3e4,
        q_wxyz=q,
        r_itrs_km=r,
        temperature_c=rng.normal(20.0, 5.0, size=n),
        mtq_am2=rng.normal(size=(n, 3)),
        hk={
            "hk_current_a": rng.uniform(0, 2, size=n),
            "hk_mode": np.array(["SAFE" if i % 3 else "NOMINAL" for i in range(n)], dtype=object),
        },
    )


def _assert_same(a: Telemetry, b: Telemetry) -> None:
    assert len(a) == len(b)
    np.testing.assert_allclose(a.t_utc_s, b.t_utc_s, rtol=0, atol=ONE_MICROSECOND_S)
    for name in ("b_raw_nt", "q_wxyz", "r_itrs_km", "temperature_c", "mtq_am2"):
        x, y = getattr(a, name), getattr(b, name)
        if x is None:
            assert y is None, name
        else:
            np.testing.assert_array_equal(x, y, err_msg=name)  # full precision, bit for bit
    assert set(a.hk) == set(b.hk)
    for k in a.hk:
        if a.hk[k].dtype.kind == "f":
            np.testing.assert_array_equal(a.hk[k], b.hk[k])
        else:
            assert list(a.hk[k]) == list(b.hk[k])


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_every_format(tmp_path: Path, fmt: str) -> None:
    tel = _table()
    path = tmp_path / f"t.{fmt}"
    write_telemetry(path, tel)
    res = read_telemetry(path)
    assert res.rejected == []
    _assert_same(tel, res.telemetry)
    # parse_telemetry on the same bytes gives the same table
    res2 = parse_telemetry(path.read_bytes(), fmt=fmt)  # type: ignore[arg-type]
    _assert_same(tel, res2.telemetry)


def test_minimal_table_has_no_optional_parts() -> None:
    csv = b"time,b_x,b_y,b_z\n2023-01-01T00:00:00Z,1,2,3\n2023-01-01T00:00:01.5Z,4,5,6\n"
    res = parse_telemetry(csv, fmt="csv")
    tel = res.telemetry
    assert res.rejected == []
    assert tel.q_wxyz is None and tel.r_itrs_km is None and tel.temperature_c is None
    assert tel.mtq_am2 is None and tel.hk == {}
    np.testing.assert_array_equal(tel.t_utc_s, [1672531200.0, 1672531201.5])
    np.testing.assert_array_equal(tel.b_raw_nt, [[1, 2, 3], [4, 5, 6]])


def test_unix_seconds_and_iso_give_the_same_time() -> None:
    csv = b"time,b_x,b_y,b_z\n1672531200.25,1,2,3\n"
    iso = b"time,b_x,b_y,b_z\n2023-01-01T00:00:00.250Z,1,2,3\n"
    t_num = parse_telemetry(csv, fmt="csv").telemetry.t_utc_s
    t_iso = parse_telemetry(iso, fmt="csv").telemetry.t_utc_s
    np.testing.assert_array_equal(t_num, t_iso)
    nd = b'{"time": 1672531200.25, "b_x": 1, "b_y": 2, "b_z": 3}\n'
    np.testing.assert_array_equal(parse_telemetry(nd, fmt="ndjson").telemetry.t_utc_s, t_iso)


def _reasons(res: ReadResult) -> dict[int, str]:
    return {e.row: e.reason for e in res.rejected}


def test_every_bad_row_kind_is_rejected_with_its_reason_and_the_rest_kept() -> None:
    header = "time,b_x,b_y,b_z,q_w,q_x,q_y,q_z,r_x,r_y,r_z,temperature\n"
    good = "1,0,0,0,7000,0,0,20"
    rows = [
        f"2023-01-01T00:00:00Z,100,200,300,{good}",  # 0 ok
        f"not-a-time,100,200,300,{good}",  # 1 time
        f"2023-01-01T00:00:02Z,nan,200,300,{good}",  # 2 b_x non-finite
        f"2023-01-01T00:00:03Z,100,inf,300,{good}",  # 3 b_y non-finite
        f"2023-01-01T00:00:04Z,2e6,0,0,{good}",  # 4 absurd |b|
        "2023-01-01T00:00:05Z,1,2,3,1.01,0,0,0,7000,0,0,20",  # 5 non-unit q
        "2023-01-01T00:00:06Z,1,2,3,1,0,,0,7000,0,0,20",  # 6 partial quaternion
        "2023-01-01T00:00:07Z,1,2,3,1,0,0,0,7000,,0,20",  # 7 partial position
        f"2023-01-01T00:00:00Z,9,9,9,{good}",  # 8 duplicate of row 0
        f"2023-01-01T00:00:09Z,1,2,abc,{good}",  # 9 b_z not a number
        "2023-01-01T00:00:10Z,1,2,3,1,0,0,0,100,0,0,20",  # 10 position inside the Earth
        "2023-01-01T00:00:11Z,1,2,3,1,0,0,0,7000,0,0,-300",  # 11 below absolute zero
        "2023-01-01T00:00:12,1,2,3,1,0,0,0,7000,0,0,20",  # 12 ISO without zone
        f"2023-01-01T00:00:13Z,1,2,3,{good}",  # 13 ok
        "2023-01-01T00:00:14Z,1,2,3,0.9995,0,0,0,7000,0,0,20",  # 14 within 1e-3: ok
    ]
    res = parse_telemetry((header + "\n".join(rows) + "\n").encode(), fmt="csv")
    why = _reasons(res)
    assert sorted(why) == [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]
    assert "time" in why[1]
    assert "b_x" in why[2] and "not finite" in why[2]
    assert "b_y" in why[3]
    assert "|b|" in why[4]
    assert "not unit" in why[5] and "1.01" in why[5]
    assert "q_y" in why[6]
    assert "r_y" in why[7]
    assert "duplicate" in why[8] and "row 0 kept" in why[8]
    assert "b_z is not a number" in why[9]
    assert "position" in why[10]
    assert "temperature" in why[11]
    assert "zone" in why[12]
    tel = res.telemetry
    assert len(tel) == 3
    np.testing.assert_array_equal(tel.b_raw_nt[0], [100, 200, 300])  # the first of the duplicates
    assert all(isinstance(e, RowError) for e in res.rejected)


def test_several_reasons_for_one_row_are_all_named() -> None:
    res = parse_telemetry(b"time,b_x,b_y,b_z\nbad,nan,1,1\n2023-01-01T00:00:00Z,1,1,1\n", fmt="csv")
    (err,) = res.rejected
    assert err.row == 0 and "time" in err.reason and "b_x" in err.reason
    assert len(res.telemetry) == 1


def test_unsorted_rows_are_sorted_not_rejected() -> None:
    csv = (
        b"time,b_x,b_y,b_z\n2023-01-01T00:00:02Z,2,0,0\n2023-01-01T00:00:00Z,0,0,0\n"
        b"2023-01-01T00:00:01Z,1,0,0\n"
    )
    res = parse_telemetry(csv, fmt="csv")
    assert res.rejected == []
    np.testing.assert_array_equal(res.telemetry.b_raw_nt[:, 0], [0, 1, 2])
    assert np.all(np.diff(res.telemetry.t_utc_s) > 0)


def test_missing_required_column_fails_the_table_naming_it() -> None:
    with pytest.raises(TelemetryError, match="'b_z'"):
        parse_telemetry(b"time,b_x,b_y\n2023-01-01T00:00:00Z,1,2\n", fmt="csv")
    with pytest.raises(TelemetryError, match="'time'"):
        parse_telemetry(b'[{"b_x": 1, "b_y": 2, "b_z": 3}]', fmt="json")


def test_partial_optional_column_group_fails_the_table() -> None:
    csv = b"time,b_x,b_y,b_z,q_w,q_x,q_y\n2023-01-01T00:00:00Z,1,2,3,1,0,0\n"
    with pytest.raises(TelemetryError, match="q_z"):
        parse_telemetry(csv, fmt="csv")


def test_unknown_time_scale_is_a_clear_error() -> None:
    with pytest.raises(TelemetryError, match=r"unknown time scale 'TT'.*UTC, TAI, GPS"):
        parse_telemetry(b"time,b_x,b_y,b_z\n0,1,2,3\n", fmt="csv", time_scale="TT")


def test_unknown_columns_warn_and_are_ignored() -> None:
    with pytest.warns(UserWarning, match="colour"):
        res = parse_telemetry(b"time,b_x,b_y,b_z,colour\n0,1,2,3,red\n", fmt="csv")
    assert len(res.telemetry) == 1


def test_ndjson_bad_line_is_a_row_error_and_the_rest_is_kept() -> None:
    nd = (
        b'{"time": "2023-01-01T00:00:00Z", "b_x": 1, "b_y": 2, "b_z": 3}\n'
        b'{"time": "2023-01-01T00:00:01Z", "b_x": 1, "b_y": \n'
        b"[1, 2]\n"
        b'{"time": "2023-01-01T00:00:03Z", "b_x": null, "b_y": 2, "b_z": 3}\n'
        b'{"time": "2023-01-01T00:00:04Z", "b_x": 4, "b_y": 2, "b_z": 3}\n'
    )
    res = parse_telemetry(nd, fmt="ndjson")
    why = _reasons(res)
    assert sorted(why) == [1, 2, 3]
    assert "JSON" in why[1] and "JSON object" in why[2] and "b_x" in why[3]
    np.testing.assert_array_equal(res.telemetry.b_raw_nt[:, 0], [1, 4])


def test_tai_and_gps_times_give_utc_with_leap_seconds() -> None:
    # 2017-01-01T00:00:00Z is 00:00:37 TAI and 00:00:18 GPS (TAI−UTC = 37 s since 2017-01-01).
    t_utc = pd.Timestamp("2017-01-01T00:00:00Z").timestamp()
    tai = b"time,b_x,b_y,b_z\n2017-01-01T00:00:37Z,1,2,3\n"
    gps = b"time,b_x,b_y,b_z\n2017-01-01T00:00:18Z,1,2,3\n"
    assert parse_telemetry(tai, fmt="csv", time_scale="TAI").telemetry.t_utc_s[0] == t_utc
    assert parse_telemetry(gps, fmt="csv", time_scale="GPS").telemetry.t_utc_s[0] == t_utc
    # Before the 2016-12-31 leap second TAI−UTC was 36 s: the same reading is 1 s later in UTC.
    tai_2016 = b"time,b_x,b_y,b_z\n2016-12-31T12:00:36Z,1,2,3\n"
    t_2016 = pd.Timestamp("2016-12-31T12:00:00Z").timestamp()
    assert parse_telemetry(tai_2016, fmt="csv", time_scale="TAI").telemetry.t_utc_s[0] == t_2016
    # Numbers are Unix-style seconds of the declared scale.
    num = f"time,b_x,b_y,b_z\n{t_utc + 18.0},1,2,3\n".encode()
    assert parse_telemetry(num, fmt="csv", time_scale="gps").telemetry.t_utc_s[0] == t_utc


def test_parquet_with_a_timestamp_column(tmp_path: Path) -> None:
    df = pd.DataFrame(
        {
            "time": pd.to_datetime(["2023-01-01T00:00:00Z", "2023-01-01T00:00:01Z"], utc=True),
            "b_x": [1.0, 2.0],
            "b_y": [0.0, 0.0],
            "b_z": [0.0, 0.0],
        }
    )
    path = tmp_path / "ts.parquet"
    df.to_parquet(path)
    res = read_telemetry(path)
    np.testing.assert_array_equal(res.telemetry.t_utc_s, [1672531200.0, 1672531201.0])


def test_regressors_select_sort_and_frame() -> None:
    tel = _table(10)
    x_hk, names = tel.regressors()
    assert names == ["temperature", "mtq_x", "mtq_y", "mtq_z", "hk_current_a"]  # text hk left out
    assert x_hk.shape == (10, 5)
    np.testing.assert_array_equal(x_hk[:, 0], tel.temperature_c)  # type: ignore[arg-type]
    np.testing.assert_array_equal(x_hk[:, 1:4], tel.mtq_am2)  # type: ignore[arg-type]
    sub = tel.select(tel.t_utc_s > tel.t_utc_s[4])
    assert len(sub) == 5 and sub.hk["hk_mode"].shape == (5,)
    rev = tel.select(np.arange(10)[::-1]).sort_by_time()
    _assert_same(tel, rev)
    frame = tel.to_table_frame()
    assert list(frame.columns[:4]) == ["time", "b_x", "b_y", "b_z"]
    assert frame["time"].iloc[0] == "2023-07-22T04:26:40.123456Z"
    res = from_frame(frame)
    _assert_same(tel, res.telemetry)
    # to_frame: indexed by UTC time like CalibrationRun.to_frame(), and read back as it is
    by_time = tel.to_frame()
    assert isinstance(by_time.index, pd.DatetimeIndex) and str(by_time.index.tz) == "UTC"
    assert by_time.index.name == "time" and "time" not in by_time.columns
    assert by_time.index[0] == pd.Timestamp("2023-07-22T04:26:40.123456Z")
    assert list(by_time.columns) == list(frame.columns[1:])
    from orbitcal.api import read_table

    _assert_same(tel, read_table(by_time))


def test_write_field_csv(tmp_path: Path) -> None:
    path = tmp_path / "f.csv"
    write_field_csv(path, [T0_UTC_S, T0_UTC_S + 1], [[1.5, -2, 3], [4, 5, 6]])
    df = pd.read_csv(path)
    assert list(df.columns) == ["time", "b_x", "b_y", "b_z"]
    assert df["time"].iloc[0] == "2023-07-22T04:26:40.000000Z"
    np.testing.assert_array_equal(df[["b_x", "b_y", "b_z"]].to_numpy()[0], [1.5, -2, 3])


def test_json_array_and_column_json_are_read() -> None:
    rows = [{"time": "2023-01-01T00:00:00Z", "b_x": 1, "b_y": 2, "b_z": 3}]
    assert len(parse_telemetry(json.dumps(rows).encode(), fmt="json").telemetry) == 1
    cols = {"time": ["2023-01-01T00:00:00Z"], "b_x": [1], "b_y": [2], "b_z": [3]}
    assert len(parse_telemetry(json.dumps(cols).encode(), fmt="json").telemetry) == 1
    with pytest.raises(TelemetryError, match="JSON"):
        parse_telemetry(b"{not json", fmt="json")


def test_unknown_extension(tmp_path: Path) -> None:
    with pytest.raises(TelemetryError, match=r"\.txt"):
        read_telemetry(tmp_path / "x.txt")


finite = st.floats(min_value=-9e5 / 2, max_value=9e5 / 2, allow_nan=False, width=64)


@st.composite
def tables(draw: st.DrawFn) -> Telemetry:
    n = draw(st.integers(min_value=1, max_value=20))
    steps = draw(st.lists(st.integers(1, 10**9), min_size=n, max_size=n))
    t = T0_UTC_S + np.cumsum(steps) * 1e-6  # distinct µs times
    b = np.array(draw(st.lists(st.tuples(finite, finite, finite), min_size=n, max_size=n)))
    with_q = draw(st.booleans())
    q = None
    if with_q:
        raw = np.array(
            draw(
                st.lists(
                    st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4), min_size=n, max_size=n
                )
            )
        )
        raw[:, 0] += 2.0  # never the zero vector
        q = raw / np.linalg.norm(raw, axis=1, keepdims=True)
    temp = np.array(draw(st.lists(st.floats(-100, 150), min_size=n, max_size=n)))
    r = mtq = None
    hk = {}
    if draw(st.booleans()):
        dirs = np.array(draw(st.lists(st.tuples(finite, finite, finite), min_size=n, max_size=n)))
        dirs[:, 2] = np.abs(dirs[:, 2]) + 1.0
        r = dirs / np.linalg.norm(dirs, axis=1, keepdims=True) * draw(st.floats(6500, 50000))
    if draw(st.booleans()):
        mtq = np.array(draw(st.lists(st.tuples(finite, finite, finite), min_size=n, max_size=n)))
        hk["hk_bus_v"] = np.array(draw(st.lists(finite, min_size=n, max_size=n)))
    return Telemetry(
        t_utc_s=t, b_raw_nt=b, q_wxyz=q, r_itrs_km=r, temperature_c=temp, mtq_am2=mtq, hk=hk
    )


@pytest.mark.parametrize("fmt", FORMATS)
@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(tel=tables())
def test_random_tables_survive_write_then_read(tmp_path: Path, fmt: str, tel: Telemetry) -> None:
    path = tmp_path / f"h.{fmt}"
    write_telemetry(path, tel)
    res = read_telemetry(path)
    assert res.rejected == []
    _assert_same(tel, res.telemetry)


def test_parse_accepts_a_bytes_stream_of_a_frame_written_by_pandas() -> None:
    df = pd.DataFrame(
        {"time": [T0_UTC_S, T0_UTC_S + 1], "b_x": [1, 2], "b_y": [3, 4], "b_z": [5, 6]}
    )
    buf = io.StringIO()
    df.to_csv(buf, index=False)
    res = parse_telemetry(buf.getvalue().encode(), fmt="csv")
    np.testing.assert_array_equal(res.telemetry.t_utc_s, [T0_UTC_S, T0_UTC_S + 1])


def test_ragged_csv_rows_are_rejected_with_their_data_row_number() -> None:
    csv = (
        b"time,b_x,b_y,b_z\n"
        b"2023-01-01T00:00:00Z,1,2,3\n"
        b"2023-01-01T00:00:01Z,1,2,3,4\n"
        b"\n"
        b"2023-01-01T00:00:02Z,1,2\n"
        b"2023-01-01T00:00:03Z,7,2,3\n"
    )
    res = parse_telemetry(csv, fmt="csv")
    assert _reasons(res) == {
        1: "row has 5 fields, the header has 4",
        2: "row has 3 fields, the header has 4",
    }
    np.testing.assert_array_equal(res.telemetry.b_raw_nt[:, 0], [1, 7])


def test_ndjson_text_channel_with_braces_round_trips(tmp_path: Path) -> None:
    tel = Telemetry(
        t_utc_s=np.array([T0_UTC_S, T0_UTC_S + 1]),
        b_raw_nt=np.array([[1.0, 2, 3], [4, 5, 6]]),
        hk={"hk_note": np.array(['{"a": 1},{"b": 2}', "plain"], dtype=object)},
    )
    path = tmp_path / "b.ndjson"
    write_telemetry(path, tel)
    assert path.read_bytes().count(b"\n") == 2
    res = read_telemetry(path)
    assert list(res.telemetry.hk["hk_note"]) == ['{"a": 1},{"b": 2}', "plain"]


def test_spreadsheet_csv_with_bom_and_spaced_header() -> None:
    csv = "\ufefftime, b_x, b_y, b_z\n2023-01-01T00:00:00Z, 1, 2, 3\n".encode()
    res = parse_telemetry(csv, fmt="csv")
    assert res.rejected == []
    np.testing.assert_array_equal(res.telemetry.b_raw_nt, [[1, 2, 3]])


# --- issue 10: limits and malformed values, at the library level (the CLI reads files too) -------


def test_limits_are_enforced_before_parsing_and_name_the_limit() -> None:
    from orbitcal.errors import LimitExceededError
    from orbitcal.telemetry import ParseLimits

    small = ParseLimits(max_rows=3, max_columns=5, max_json_depth=3, max_string_chars=8)
    rows = b"time,b_x,b_y,b_z\n" + b"1690000000,1,2,3\n" * 4
    cases = [
        (rows, "csv", "max_rows"),
        (b"time,b_x,b_y,b_z,hk_a,hk_b\n1,2,3,4,5,6\n", "csv", "max_columns"),
        (b'{"time": 1690000000, "b_x": [[[1]]], "b_y": 2, "b_z": 3}', "ndjson", "max_json_depth"),
        (
            b'[{"time": 1690000000, "b_x": 1, "b_y": 2, "b_z": 3, "hk_s": "0123456789"}]',
            "json",
            "max_string_chars",
        ),
    ]
    for body, fmt, name in cases:
        with pytest.raises(LimitExceededError, match=name) as info:
            parse_telemetry(body, fmt=fmt, limits=small)  # type: ignore[arg-type]
        assert info.value.limit_name == name


def test_booleans_are_not_numbers_and_flags_stay_text() -> None:
    body = (
        b'[{"time": 1690000000, "b_x": true, "b_y": 2, "b_z": 3},'
        b' {"time": 1690000001, "b_x": 1, "b_y": 2, "b_z": 3, "hk_flag": false}]'
    )
    res = parse_telemetry(body, fmt="json")
    assert [(e.row, e.reason) for e in res.rejected] == [
        (0, "b_x is a boolean (true/false), not a number")
    ]
    assert res.telemetry.hk["hk_flag"].tolist() == ["false"]


def test_leap_second_is_rejected_and_the_next_second_kept() -> None:
    body = b"time,b_x,b_y,b_z\n2016-12-31T23:59:60Z,1,2,3\n2017-01-01T00:00:00Z,4,5,6\n"
    res = parse_telemetry(body, fmt="csv")
    assert [e.row for e in res.rejected] == [0] and "leap second" in res.rejected[0].reason
    assert res.telemetry.t_utc_s.tolist() == [1_483_228_800.0]
    assert res.telemetry.b_raw_nt[0].tolist() == [4.0, 5.0, 6.0]


def test_times_equal_to_the_microsecond_are_duplicates() -> None:
    body = b"time,b_x,b_y,b_z\n1690000000.0000001,1,2,3\n1690000000.0000004,4,5,6\n"
    res = parse_telemetry(body, fmt="csv")
    assert [e.row for e in res.rejected] == [1]
    assert "microsecond resolution (row 0 kept)" in res.rejected[0].reason


def test_repeated_columns_and_non_utf8_text_name_the_place() -> None:
    with pytest.raises(TelemetryError, match="repeated column name 'b_x'"):
        parse_telemetry(b"time,b_x,b_x,b_z\n1690000000,1,2,3\n", fmt="csv")
    with pytest.raises(TelemetryError, match="row 1 is not UTF-8"):
        parse_telemetry(b"time,b_x,b_y,b_z,hk_s\n1,2,3,4,a\n2,2,3,4,\xe9\n", fmt="csv")


def test_a_reader_failure_nobody_foresaw_is_a_telemetry_error_not_a_crash(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The last resort around the third-party readers (orbitcal.errors.reading_untrusted_input)."""
    import orbitcal.telemetry as telemetry_module
    from orbitcal.errors import UnreadableInputError

    def broken_reader(data: bytes, limits: object) -> None:
        raise KeyError("a pandas internal")

    monkeypatch.setattr(telemetry_module.readers, "_read_csv_bytes", broken_reader)
    with pytest.raises(TelemetryError, match=r"the csv table could not be read \(KeyError") as info:
        parse_telemetry(b"time,b_x,b_y,b_z\n1690000000,1,2,3\n", fmt="csv")
    assert isinstance(info.value, UnreadableInputError) and info.value.http_status == 400
    assert info.value.exit_code == 2


def test_an_undecodable_packet_stream_is_a_packet_error(monkeypatch: pytest.MonkeyPatch) -> None:
    from orbitcal import ccsds

    def broken_scan(data: bytes, apid: object, max_packets: int) -> None:
        raise IndexError("index 7 is out of bounds")

    monkeypatch.setattr(ccsds, "_scan", broken_scan)
    with pytest.raises(ccsds.PacketError, match="packet stream could not be read") as info:
        ccsds.decode_packets(b"\x08" * 64)
    assert info.value.http_status == 400
    with pytest.raises(ccsds.PacketError, match="no packets"):
        ccsds.decode_packets(b"")
