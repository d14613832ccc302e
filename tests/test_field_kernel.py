"""The compiled field kernel gives the same field on one thread and in parallel over samples."""

from __future__ import annotations

import numpy as np
import pytest

from orbitcal.field import _kernel, get_field

pytestmark = pytest.mark.skipif(not _kernel.HAVE_NUMBA, reason="numba not installed")


def test_parallel_kernel_matches_the_serial_one_to_1e_9_nt() -> None:
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
        np.testing.assert_allclose(parallel, serial, rtol=0.0, atol=1e-9)
    assert np.all(np.isfinite(serial)) and np.abs(serial).max() > 1e4
    # and the field model's own path agrees with the kernel it calls
    via_model = field.b_nec_nt(t, radius, np.degrees(colat), np.degrees(lon))
    np.testing.assert_allclose(via_model, serial, rtol=0.0, atol=1e-9)
