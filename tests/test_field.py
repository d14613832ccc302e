"""CHAOS-8.1 core, crustal models, name parsing and the synthesis kernel, against chaosmagpy."""

from __future__ import annotations

import datetime as dt
import warnings

import chaosmagpy
import numpy as np
import pytest

import orbitcal.field as field_pkg
from orbitcal.field import CompositeField, FieldRangeError, get_field
from orbitcal.field._base import utc_s_to_mjd2000
from orbitcal.field.chaos import field_data_path
from orbitcal.field.synthesis import n_block_coeffs, synth_internal_nec_nt, to_degree_blocks

#: Agreement required with chaosmagpy on the same coefficient file: 0.1 nT (seen ~1e-10 nT).
TENTH_NT = 0.1


def _chaosmagpy_model(filename: str) -> chaosmagpy.chaos.BaseModel:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return chaosmagpy.chaos.BaseModel.from_shc(str(field_data_path(filename)))


def _points(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r = 6371.2 + rng.uniform(0.0, 900.0, n)
    colat = np.degrees(np.arccos(rng.uniform(-1.0, 1.0, n)))
    lon = rng.uniform(-180.0, 180.0, n)
    return r, colat, lon


def _nec(b_r: np.ndarray, b_t: np.ndarray, b_p: np.ndarray) -> np.ndarray:
    return np.stack([-b_t, b_p, -b_r], axis=-1)


def test_chaos_core_matches_chaosmagpy_spline_and_field() -> None:
    rng = np.random.default_rng(81)
    model = get_field("CHAOS-8.1")
    ref = _chaosmagpy_model("CHAOS-8.1_core.shc")
    start, end = model.valid_mjd2000
    mjd = rng.uniform(start, end, 2000)
    t = mjd * 86400.0 + 946_684_800.0
    r, colat, lon = _points(rng, 2000)
    # coefficients: the quintic B-spline rebuilt as chaosmagpy does
    assert np.abs(model.gauss_coeffs(t) - ref.synth_coeffs(mjd)).max() < 1e-6
    b_ref = _nec(*ref.synth_values(mjd, r, colat, lon))
    assert np.abs(model.b_nec_nt(t, r, colat, lon) - b_ref).max() < TENTH_NT
    # knots are hit exactly too (piece boundaries)
    knots = ref.breaks[[0, 1, 30, -1]]
    tk = knots * 86400.0 + 946_684_800.0
    assert np.abs(model.gauss_coeffs(tk) - ref.synth_coeffs(knots)).max() < 1e-6


def test_chaos_core_range() -> None:
    model = get_field("CHAOS-8.1")
    late = dt.datetime(2025, 6, 1, tzinfo=dt.UTC).timestamp()
    with pytest.raises(FieldRangeError, match=r"CHAOS-8\.1 is valid from 1997-.* to 2025-02-"):
        model.b_nec_nt([late], [6800.0], [40.0], [0.0])


@pytest.mark.parametrize(
    ("name", "filename", "nmin", "nmax"),
    [
        ("CHAOS-8.1-static", "CHAOS-8.1_static.shc", 21, 185),
        ("LCS-1", "LCS-1.shc", 1, 185),
        ("MF7", "MF7.shc", 16, 133),
    ],
)
def test_crustal_models_match_chaosmagpy(name: str, filename: str, nmin: int, nmax: int) -> None:
    rng = np.random.default_rng(5)
    model = get_field(name)
    assert (model.name, model.nmin, model.nmax) == (name, nmin, nmax)
    r, colat, lon = _points(rng, 150)
    r[:50] = 6371.2  # at the surface the high degrees matter most
    b_ref = _nec(*_chaosmagpy_model(filename).synth_values(0.0, r, colat, lon))
    b = model.b_nec_nt(np.zeros(150), r, colat, lon)  # static: any time (here 1970)
    assert np.abs(b - b_ref).max() < 1e-6
    # crustal fields: a few nT rms at 450 km, hundreds at the surface
    assert 1.0 < np.sqrt(np.mean(b[50:] ** 2)) < 20.0


def test_a_crustal_model_above_the_main_field_leaves_out_its_low_degrees() -> None:
    """What a crustal model adds to IGRF (degree 13) is its part above 13: LCS-1 from degree 14 is
    chaosmagpy's LCS-1 with its degrees 1..13 zeroed; MF7 (from 16) is unchanged."""
    from orbitcal.diagnose.prepare import main_field_nmax
    from orbitcal.field.crust import crustal_field_above

    assert main_field_nmax("IGRF-14") == 13 and main_field_nmax("CHAOS-8.1+LCS-1+RC") == 20
    rng = np.random.default_rng(6)
    r, colat, lon = _points(rng, 60)
    above = crustal_field_above("LCS-1", 14)
    assert (above.nmin, above.nmax) == (14, 185)
    ref = _chaosmagpy_model("LCS-1.shc")
    coeffs = np.array(ref.coeffs, copy=True)
    coeffs[..., : 13 * 15] = 0.0  # degrees 1..13: n (n + 2) = 195 coefficients
    b_ref = _nec(*chaosmagpy.model_utils.synth_values(coeffs.reshape(-1), r, colat, lon))
    b = above.b_nec_nt(np.zeros(60), r, colat, lon)
    assert np.abs(b - b_ref).max() < 1e-6
    assert crustal_field_above("MF7", 14) is get_field("MF7")


def test_get_field_names_and_composition() -> None:
    assert get_field().name == "IGRF-14" == field_pkg.DEFAULT_FIELD
    combo = get_field("CHAOS-8.1+CHAOS-8.1-static+RC")
    assert isinstance(combo, CompositeField)
    assert combo.name == "CHAOS-8.1+CHAOS-8.1-static+RC"
    assert get_field("IGRF-14 + LCS-1").name == "IGRF-14+LCS-1"
    t = np.full(5, dt.datetime(2016, 1, 1, tzinfo=dt.UTC).timestamp())
    r, colat, lon = _points(np.random.default_rng(3), 5)
    parts = sum(
        get_field(n).b_nec_nt(t, r, colat, lon) for n in ("CHAOS-8.1", "CHAOS-8.1-static", "RC")
    )
    np.testing.assert_allclose(combo.b_nec_nt(t, r, colat, lon), parts, atol=1e-9)
    with pytest.raises(ValueError, match="name the generation"):
        get_field("IGRF")
    with pytest.raises(ValueError, match="unknown field model"):
        get_field("WMM")
    with pytest.raises(ValueError, match="repeats"):
        get_field("LCS-1+LCS-1")
    with pytest.raises(ValueError, match="main-field"):
        get_field("IGRF-14+CHAOS-8.1")
    assert get_field("IGRF-13") is get_field("IGRF-13")  # loaded once


def test_synthesis_static_per_sample_and_poles_agree_with_chaosmagpy() -> None:
    rng = np.random.default_rng(11)
    nmax = 8
    flat = rng.normal(0.0, 100.0, nmax * (nmax + 2))
    flat[0] = -30000.0
    r = np.array([6371.2, 6800.0, 7000.0, 6800.0, 6800.0])
    colat = np.array([0.0, 180.0, 1e-4, 90.0, 33.0])  # poles included
    lon = np.array([0.0, 45.0, -90.0, 179.9, -10.0])
    b_static = synth_internal_nec_nt(to_degree_blocks(flat, nmax), r, colat, lon, nmax=nmax)
    per_sample = np.repeat(to_degree_blocks(flat, nmax)[None], r.size, axis=0)
    b_rows = synth_internal_nec_nt(per_sample, r, colat, lon, nmax=nmax, chunk_size=2)
    np.testing.assert_allclose(b_rows, b_static, atol=1e-9)
    assert np.all(np.isfinite(b_static))
    # away from the exact poles chaosmagpy is the authority; at the poles compare with a point
    # 1e-4 deg (11 m) away: the field is continuous; chaosmagpy's B_phi is 0/0 exactly there
    b_ref = _nec(*chaosmagpy.model_utils.synth_values(flat, r[2:], colat[2:], lon[2:]))
    assert np.abs(b_static[2:] - b_ref).max() < 1e-6
    near = _nec(*chaosmagpy.model_utils.synth_values(flat, r[:2], [1e-4, 180 - 1e-4], lon[:2]))
    assert np.abs(b_static[:2] - near).max() < 1.0  # gradient x 11 m
    assert n_block_coeffs(nmax) == nmax * (nmax + 3)


def test_nmin_leaves_out_low_degrees() -> None:
    rng = np.random.default_rng(2)
    nmax = 6
    flat = rng.normal(0.0, 10.0, nmax * (nmax + 2))
    r, colat, lon = _points(rng, 20)
    high = flat.copy()
    high[: 3 * 5] = 0.0  # zero degrees 1..3 (n^2 - 1 = 15 coefficients)
    a = synth_internal_nec_nt(to_degree_blocks(flat, nmax), r, colat, lon, nmax=nmax, nmin=4)
    b = synth_internal_nec_nt(to_degree_blocks(high, nmax), r, colat, lon, nmax=nmax)
    np.testing.assert_allclose(a, b, atol=1e-10)


def test_mjd2000_origin() -> None:
    assert utc_s_to_mjd2000(np.array([946_684_800.0]))[0] == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert chaosmagpy.data_utils.mjd2000(2016, 1, 1) == utc_s_to_mjd2000(1_451_606_400.0)


@pytest.mark.parametrize("name", ["IGRF-14", "CHAOS-8.1", "MF7"])
def test_numba_and_numpy_backends_agree(name: str) -> None:
    """The compiled kernel and the numpy recursion are two implementations of one algorithm."""
    from orbitcal.field._kernel import HAVE_NUMBA

    assert HAVE_NUMBA, "numba is a dependency of orbitcal (pyproject.toml)"
    rng = np.random.default_rng(17)
    model = get_field(name)
    start, end = (max(v, 0.0) for v in model.valid_mjd2000) if not model.static else (0.0, 9000.0)
    end = min(end, 9300.0)
    n = 300 if name != "MF7" else 60
    t = rng.uniform(start, end, n) * 86400.0 + 946_684_800.0
    r, colat, lon = _points(rng, n)
    colat[:2] = [0.0, 180.0]
    a = model.evaluate(t, r, colat, lon, backend="numba")
    b = model.evaluate(t, r, colat, lon, backend="numpy")
    assert np.abs(a - b).max() < 1e-6
