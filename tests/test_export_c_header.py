"""``c-header`` (issue 21) compiled with ``cc`` and run: the float64 function equals ``orbitcal
apply`` to 1e-6 nT for an affine method and the network's affine part otherwise (with the loss
stated), the float32 one within float32 rounding, and the tables' CRC-32s check on board."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from export_consumers import run_c_header
from export_worlds import EXACT_NT, Fitted, fitted

from orbitcal.export import ExportOptions, affine_part, calibration_form, evaluate, export


def _run_c(f: Fitted, tmp_path: Path, header: bytes) -> tuple[int, int, np.ndarray]:
    rows = np.flatnonzero(f.holdout)
    x = None if f.x_hk is None else f.x_hk[rows]
    ok, version, b64, b32 = run_c_header(header, f.telemetry.b_raw_nt[rows], x)
    return ok, version, np.hstack([b64, b32])


@pytest.mark.parametrize("method", ["linear-hk", "lmbp-hk"])
def test_c_header_compiled_and_run(
    method: str, tmp_path: Path, swarm_a_temperature_world: Any
) -> None:
    f = fitted(swarm_a_temperature_world, method)
    result = export(f.document, ExportOptions(format="c-header"))
    assert result.content is not None
    ok, version, out = _run_c(f, tmp_path, result.content)
    assert ok == 1 and version == f.document["version"]
    rows = np.flatnonzero(f.holdout)
    form = calibration_form(f.document)
    expected = evaluate(
        affine_part(form), f.telemetry.b_raw_nt[rows], None if f.x_hk is None else f.x_hk[rows]
    )
    assert np.max(np.abs(out[:, :3] - expected)) < EXACT_NT
    # float32: coefficients and arithmetic rounded (2^-24 relative of terms up to ~|B| + K x)
    assert np.max(np.abs(out[:, 3:] - expected)) < 0.05
    text = result.content.decode()
    assert result.info["document_sha256"] in text
    if method == "linear-hk":
        assert np.max(np.abs(out[:, :3] - f.b_apply_nt[rows])) < EXACT_NT
        assert "this is the whole calibration" in text
    else:
        assert "less than the whole lmbp-hk model" in text
        assert np.max(np.abs(out[:, :3] - f.b_apply_nt[rows])) > 0.1


def test_a_corrupted_table_fails_its_crc(tmp_path: Path, swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, "linear-hk")
    result = export(f.document, ExportOptions(format="c-header"))
    assert result.content is not None
    text = result.content.decode()
    start = text.index("\n", text.index("orbitcal_magcal_table_f64[")) + 1
    end = text.index(",\n", start)
    value = float(text[start:end])
    corrupted = text[:start] + "    " + repr(value * (1 + 1e-9)) + text[end:]  # M[0][0] off by 1e-9
    ok, _, _ = _run_c(f, tmp_path, corrupted.encode())
    assert ok == 0
