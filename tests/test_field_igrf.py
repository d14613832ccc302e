"""IGRF-13/14 against independent implementations: ppigrf, chaosmagpy and ESA VirES."""

from __future__ import annotations

import contextlib
import datetime as dt
import io
from pathlib import Path

import chaosmagpy
import h5py
import numpy as np
import pandas as pd
import ppigrf
import ppigrf.ppigrf
import pytest

from orbitcal.field import FieldRangeError, get_field
from orbitcal.field.igrf import igrf_shc_path
from orbitcal.timescales import iso_to_utc_s

#: Agreement required with an independent IGRF implementation (issue 2): 0.1 nT.
TENTH_NT = 0.1
#: POSIX seconds at 2016-01-01T00:00Z (the Swarm files' Timestamp origin).
T_2016_S = 1_451_606_400.0


def _random_samples(
    rng: np.random.Generator, n: int, t0_s: float, t1_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = rng.uniform(t0_s, t1_s, n)
    r = 6371.2 + rng.uniform(0.0, 1000.0, n)
    colat = np.degrees(np.arccos(rng.uniform(-1.0, 1.0, n)))
    lon = rng.uniform(-180.0, 180.0, n)
    return t, r, colat, lon


def test_igrf14_matches_ppigrf_points(authorities: Path) -> None:
    table = pd.read_csv(authorities / "igrf" / "igrf14_ppigrf_points.csv")
    t = iso_to_utc_s(list(table["time"]))
    b = get_field("IGRF-14").b_nec_nt(
        t, table["radius_km"].to_numpy(), table["colat_deg"].to_numpy(), table["lon_deg"].to_numpy()
    )
    ref = table[["b_n_nt", "b_e_nt", "b_c_nt"]].to_numpy()
    # the file is rounded to 1e-4 nT
    assert np.abs(b - ref).max() < TENTH_NT


def test_igrf_coefficients_match_ppigrf_time_interpolation() -> None:
    """Per-sample coefficients equal ppigrf's pandas time interpolation of the same file."""
    model = get_field("IGRF-14")
    times = pd.DatetimeIndex(
        [
            "1903-05-17 03:00",
            "1999-12-31 23:00",
            "2016-01-01 00:15",
            "2024-02-29 12:00",
            "2025-01-01 00:00",
            "2028-07-04 06:00",
        ]
    )
    g, h = ppigrf.ppigrf.read_shc(str(igrf_shc_path("IGRF-14")))
    index = g.index.union(times)
    g_i = g.reindex(index).interpolate(method="time").loc[times]
    h_i = h.reindex(index).interpolate(method="time").loc[times]
    t_s = (times - pd.Timestamp("1970-01-01")).total_seconds().to_numpy()
    ours = model.gauss_coeffs(t_s)
    for (n, m), col in g_i.items():
        assert np.abs(ours[:, n * n - 1 + max(2 * m - 1, 0)] - col.to_numpy()).max() < 1e-9
    for (n, m), col in h_i.items():
        if m > 0:
            assert np.abs(ours[:, n * n - 1 + 2 * m] - col.to_numpy()).max() < 1e-9


@pytest.mark.parametrize("name", ["IGRF-14", "IGRF-13"])
def test_igrf_synthesis_matches_chaosmagpy(name: str) -> None:
    """Same per-sample coefficients through chaosmagpy's synth_values: < 0.1 nT (seen 1e-10)."""
    rng = np.random.default_rng(20260101)
    model = get_field(name)
    t, r, colat, lon = _random_samples(rng, 3000, -1.5e9, 1.7e9)
    coeffs = model.gauss_coeffs(t)
    b_r, b_t, b_p = chaosmagpy.model_utils.synth_values(coeffs, r, colat, lon)
    ref = np.stack([-b_t, b_p, -b_r], axis=-1)
    assert np.abs(model.b_nec_nt(t, r, colat, lon) - ref).max() < TENTH_NT


def test_sign_conventions_against_ppigrf_east_north_up() -> None:
    """ppigrf returns (east, north, up); orbitcal (north, east, centre=down).

    At geodetic latitude 0 the geodetic and geocentric frames coincide, so
    ``(Be, Bn, Bu) == (E, N, -C)``.
    """
    when = dt.datetime(2021, 6, 1)
    h_km = 500.0
    lons = np.array([-150.0, -30.0, 0.0, 75.0, 160.0])
    with contextlib.redirect_stdout(io.StringIO()):
        be, bn, bu = ppigrf.igrf(lons, 0.0, h_km, when)
    t = np.full(lons.shape, (when - dt.datetime(1970, 1, 1)).total_seconds())
    b = get_field("IGRF-14").b_nec_nt(t, np.full(lons.shape, 6378.137 + h_km), 90.0, lons)
    np.testing.assert_allclose(b[:, 0], bn.ravel(), atol=TENTH_NT)
    np.testing.assert_allclose(b[:, 1], be.ravel(), atol=TENTH_NT)
    np.testing.assert_allclose(b[:, 2], -bu.ravel(), atol=TENTH_NT)
    # Physical signs: near the geographic equator the field points north; at high northern
    # latitude it points down (C > 0), at high southern latitude up (C < 0).
    assert np.all(b[:, 0] > 0)
    hemis = get_field("IGRF-14").b_nec_nt(t[:2], np.array([6871.0, 6871.0]), [10.0, 170.0], 0.0)
    assert hemis[0, 2] > 0 > hemis[1, 2]


@pytest.mark.parametrize("spacecraft", ["A", "B"])
def test_igrf14_matches_vires_swarm(authorities: Path, spacecraft: str) -> None:
    """ESA VirES (eoxmagmod) IGRF along Swarm: IGRF-14 within 0.1 nT (seen 0.04), not IGRF-13."""
    with h5py.File(authorities / f"fixture_paldata_item_MAG{spacecraft}.nc4", "r") as f:
        g = f[f"SW_OPER_MAG{spacecraft}_LR_1B"]
        t = g["Timestamp"][:] + T_2016_S
        lat, lon, r = g["Latitude"][:], g["Longitude"][:], g["Radius"][:] / 1e3
        ref = g["B_NEC_IGRF"][:]
    assert np.abs(get_field("IGRF-14").b_nec_nt(t, r, 90.0 - lat, lon) - ref).max() < TENTH_NT
    # IGRF-13's non-definitive 2020 epoch already shows here (0.2-0.6 nT in 2016).
    assert np.abs(get_field("IGRF-13").b_nec_nt(t, r, 90.0 - lat, lon) - ref).max() > 0.15


def test_igrf13_and_igrf14_are_named_and_differ_after_2022() -> None:
    i13, i14 = get_field("IGRF-13"), get_field("IGRF-14")
    assert (i13.name, i14.name) == ("IGRF-13", "IGRF-14")
    rng = np.random.default_rng(7)
    n = 4000
    t = np.full(n, dt.datetime(2024, 11, 1, tzinfo=dt.UTC).timestamp())
    r = np.full(n, 6371.2 + 450.0)
    colat = np.degrees(np.arccos(rng.uniform(-1, 1, n)))
    lon = rng.uniform(-180, 180, n)
    diff = np.linalg.norm(i13.b_nec_nt(t, r, colat, lon) - i14.b_nec_nt(t, r, colat, lon), axis=1)
    assert 100.0 < diff.max() < 600.0  # hundreds of nT: IGRF-13's forecast error
    t2010 = np.full(n, dt.datetime(2010, 6, 1, tzinfo=dt.UTC).timestamp())
    same = np.linalg.norm(
        i13.b_nec_nt(t2010, r, colat, lon) - i14.b_nec_nt(t2010, r, colat, lon), axis=1
    )
    assert same.max() < 1e-6  # identical definitive coefficients (DGRF 2010, 2015)


def test_out_of_range_dates_raise_with_date_and_range() -> None:
    t = np.array(
        [
            dt.datetime(2024, 1, 1, tzinfo=dt.UTC).timestamp(),
            dt.datetime(2026, 3, 1, 12, tzinfo=dt.UTC).timestamp(),
        ]
    )
    with pytest.raises(FieldRangeError) as err:
        get_field("IGRF-13").b_nec_nt(t, np.full(2, 6800.0), [50.0, 60.0], [0.0, 10.0])
    message = str(err.value)
    assert "IGRF-13" in message and "2025-01-01" in message and "2026-03-01T12:00:00Z" in message
    assert isinstance(err.value, ValueError)
    with pytest.raises(FieldRangeError, match="2030-01-01"):
        get_field("IGRF-14").b_nec_nt(
            [dt.datetime(2031, 1, 1, tzinfo=dt.UTC).timestamp()], [6800.0], [50.0], [0.0]
        )
    # the range is inclusive at both ends
    get_field("IGRF-14").b_nec_nt(
        [
            dt.datetime(1900, 1, 1, tzinfo=dt.UTC).timestamp(),
            dt.datetime(2030, 1, 1, tzinfo=dt.UTC).timestamp(),
        ],
        [6800.0, 6800.0],
        [50.0, 50.0],
        [0.0, 0.0],
    )
