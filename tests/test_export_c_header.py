"""``c-header`` (issue 21) compiled with ``cc`` and run: the float64 function equals ``orbitcal
apply`` to 1e-6 nT for an affine method and the network's affine part otherwise (with the loss
stated), the float32 one within float32 rounding, and the tables' CRC-32s check on board."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from export_worlds import EXACT_NT, Fitted, fitted

from orbitcal.export import ExportOptions, affine_part, calibration_form, evaluate, export

MAIN_C = r"""
#include <stdio.h>
#include "orbitcal_magcal.h"

int main(void)
{
    double raw[3], hk[ORBITCAL_MAGCAL_N_HK + 1], out[3];
    float rawf[3], hkf[ORBITCAL_MAGCAL_N_HK + 1], outf[3];
    int i;
    printf("%d %d\n", orbitcal_magcal_table_ok(), ORBITCAL_MAGCAL_VERSION);
    while (scanf("%lf %lf %lf", &raw[0], &raw[1], &raw[2]) == 3) {
        for (i = 0; i < ORBITCAL_MAGCAL_N_HK; i++) if (scanf("%lf", &hk[i]) != 1) return 2;
        for (i = 0; i < 3; i++) rawf[i] = (float)raw[i];
        for (i = 0; i < ORBITCAL_MAGCAL_N_HK; i++) hkf[i] = (float)hk[i];
        orbitcal_magcal_apply_f64(raw, hk, out);
        orbitcal_magcal_apply_f32(rawf, hkf, outf);
        printf("%.17g %.17g %.17g %.9g %.9g %.9g\n", out[0], out[1], out[2],
               (double)outf[0], (double)outf[1], (double)outf[2]);
    }
    return 0;
}
"""


def _run_c(f: Fitted, tmp_path: Path, header: bytes) -> tuple[int, int, np.ndarray]:
    cc = shutil.which("cc")
    assert cc is not None, "a C compiler (cc) is needed"
    (tmp_path / "orbitcal_magcal.h").write_bytes(header)
    (tmp_path / "main.c").write_text(MAIN_C)
    exe = tmp_path / "magcal"
    subprocess.run(
        [
            cc,
            "-std=c99",
            "-Wall",
            "-Werror",
            "-pedantic",
            "-O2",
            "-o",
            str(exe),
            str(tmp_path / "main.c"),
        ],
        check=True,
        capture_output=True,
    )
    rows = np.flatnonzero(f.holdout)
    inputs = f.telemetry.b_raw_nt[rows]
    if f.x_hk is not None:
        inputs = np.hstack([inputs, f.x_hk[rows]])
    text = "\n".join(" ".join(repr(float(v)) for v in row) for row in inputs) + "\n"
    out = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
    first, *lines = out.stdout.splitlines()
    ok, version = (int(v) for v in first.split())
    return ok, version, np.asarray([[float(v) for v in ln.split()] for ln in lines])


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
