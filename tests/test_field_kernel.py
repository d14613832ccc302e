"""The compiled field kernel gives the same field on one thread and in parallel over samples."""

from __future__ import annotations

import multiprocessing
import os

import numpy as np
import pytest

from orbitcal.field import _kernel, get_field

pytestmark = pytest.mark.skipif(not _kernel.HAVE_NUMBA, reason="numba not installed")


def test_parallel_kernel_gives_the_serial_result_exactly() -> None:
    field = get_field("IGRF-14")
    rng = np.random.default_rng(0)
    n = 3 * _kernel.MIN_SAMPLES_PER_THREAD + 17  # uneven chunks
    t = 1.6e9 + np.sort(rng.uniform(0.0, 3e7, n))  # crosses pieces of the model
    radius = 6371.2 + rng.uniform(300.0, 800.0, n)
    colat = np.radians(rng.uniform(0.0, 180.0, n))  # poles included
    lon = np.radians(rng.uniform(-180.0, 180.0, n))
    idx, dt = field._piece_and_offset(field.check_range(t))
    args = (field._pp_blocks, idx.astype(np.int64), dt, radius, colat, lon)
    kw = {"nmin": field.nmin, "nmax": field.nmax}
    serial = _kernel.synth_pp_nec_nt(*args, **kw, threads=1)
    for threads in (2, 3):
        parallel = _kernel.synth_pp_nec_nt(*args, **kw, threads=threads)
        np.testing.assert_array_equal(parallel, serial)  # same code, same path per sample
    assert np.all(np.isfinite(serial)) and np.abs(serial).max() > 1e4
    # and the field model's own path agrees with the kernel it calls
    via_model = field.b_nec_nt(t, radius, np.degrees(colat), np.degrees(lon))
    np.testing.assert_allclose(via_model, serial, rtol=0.0, atol=1e-9)


def test_lanes_and_single_samples_agree_for_mixed_pieces_and_models_of_any_order() -> None:
    # Times on both sides of a break of the model: unsorted, most blocks of LANES samples mix
    # two pieces and go one sample at a time; sorted, the same samples go through the lanes
    # (one block straddles the break). Both match numpy's path.
    for name in ("IGRF-14", "CHAOS-8.1"):
        field = get_field(name)
        rng = np.random.default_rng(1)
        n = 5 * _kernel.LANES + 3  # a tail as well
        brk = field.breaks_mjd2000[np.searchsorted(field.breaks_mjd2000, 7000.0)]
        mjd = brk + rng.uniform(-30.0, 30.0, n)
        t = mjd * 86400.0 + 946684800.0  # MJD2000 -> Unix seconds
        radius = 6371.2 + rng.uniform(300.0, 800.0, n)
        colat = rng.uniform(0.0, 180.0, n)
        lon = rng.uniform(-180.0, 180.0, n)
        numpy_path = field.evaluate(t, radius, colat, lon, backend="numpy")
        mixed = field.evaluate(t, radius, colat, lon, backend="numba")
        idx, _ = field._piece_and_offset(field.check_range(t))
        assert np.unique(idx).size == 2
        order = np.argsort(t)
        in_lanes = field.evaluate(
            t[order], radius[order], colat[order], lon[order], backend="numba"
        )
        np.testing.assert_allclose(mixed, numpy_path, rtol=0.0, atol=1e-8)
        np.testing.assert_allclose(in_lanes, mixed[order], rtol=0.0, atol=1e-9)


def test_a_static_model_takes_the_linear_lanes_and_matches_numpy() -> None:
    # LCS-1 (degree 185, one piece, order 1) runs in the order-2 lanes with a zero slope.
    field = get_field("LCS-1")
    rng = np.random.default_rng(2)
    n = 2 * _kernel.LANES + 5
    t = 1.6e9 + np.arange(n) * 10.0
    radius = 6371.2 + rng.uniform(300.0, 800.0, n)
    colat = rng.uniform(0.0, 180.0, n)
    lon = rng.uniform(-180.0, 180.0, n)
    numpy_path = field.evaluate(t, radius, colat, lon, backend="numpy")
    numba_path = field.evaluate(t, radius, colat, lon, backend="numba")
    assert np.abs(numpy_path).max() > 1.0
    np.testing.assert_allclose(numba_path, numpy_path, rtol=0.0, atol=1e-9)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_parallel_kernel_works_in_a_forked_child_after_the_parent_used_it() -> None:
    # The worker threads do not survive fork; a prefork worker must not wait on them.
    field = get_field("IGRF-14")
    n = 2 * _kernel.MIN_SAMPLES_PER_THREAD
    t = 1.6e9 + np.arange(n, dtype=float)
    args = (t, np.full(n, 6800.0), np.linspace(1.0, 179.0, n), np.linspace(-180.0, 180.0, n))
    parent = field.b_nec_nt(*args)
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(1) as pool:
        child = pool.apply_async(field.b_nec_nt, args).get(timeout=120)
    np.testing.assert_allclose(child, parent, rtol=0.0, atol=1e-9)
