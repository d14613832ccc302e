"""``cosmos`` (issue 21) run by OpenC3 COSMOS's own Python package: the plugin's telemetry file
(after the plugin install's ERB step, which substitutes the plugin variables) is processed by
``openc3.packets.packet_config.PacketConfig`` beside the mission's packet definition; COSMOS
instantiates ``MagCalibration`` with the config line's arguments, and reading the DERIVED items
of packets holding held-out samples gives ``orbitcal apply``'s values to 1e-6 nT.

Needs the ``openc3`` package (``pip install --no-deps openc3 valkey``: the conversion and packet
modules import nothing else this test reaches).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from export_consumers import run_cosmos
from export_worlds import ALL_METHODS, EXACT_NT, Fitted, fitted

from orbitcal.export import ExportOptions, calibration_form, export


def _cosmos_read(f: Fitted, tmp_path: Path, hk_names: dict[str, str]) -> tuple[np.ndarray, Any]:
    files = export(f.document, ExportOptions(format="cosmos", hk_names=hk_names)).files
    assert files is not None
    hk_items = [hk_names.get(c, c.upper()) for c in calibration_form(f.document).hk_names]
    rows = np.flatnonzero(f.holdout)
    x = None if f.x_hk is None else f.x_hk[rows]
    return run_cosmos(files, hk_items, f.telemetry.b_raw_nt[rows], x)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_cosmos_conversion_in_openc3_equals_apply(
    method: str, tmp_path: Path, swarm_a_temperature_world: Any
) -> None:
    from openc3.conversions.conversion import Conversion

    f = fitted(swarm_a_temperature_world, method)
    b, conversion = _cosmos_read(f, tmp_path, {"temperature": "MAG_TEMP"})
    assert isinstance(conversion, Conversion) and type(conversion).__name__ == "MagCalibration"
    assert conversion.converted_type == "FLOAT"
    assert np.max(np.abs(b - f.b_apply_nt[f.holdout])) < EXACT_NT


def test_cosmos_fragment_names_the_version_and_digest(
    tmp_path: Path, swarm_a_temperature_world: Any
) -> None:
    f = fitted(swarm_a_temperature_world, "linear-hk")
    result = export(f.document, ExportOptions(format="cosmos"))
    zpath = tmp_path / "frag.zip"
    result.write(zpath)
    with zipfile.ZipFile(zpath) as zf:
        names = set(zf.namelist())
        plugin = zf.read("plugin.txt").decode()
        tlm = zf.read("targets/MAGCAL/cmd_tlm/magcal_tlm.txt").decode()
    assert names == {
        "plugin.txt",
        "vars.json",
        "README.txt",
        "targets/MAGCAL/cmd_tlm/magcal_tlm.txt",
        "targets/MAGCAL/lib/mag_calibration.py",
    }
    assert f"VARIABLE magcal_sha256 {result.info['document_sha256']}" in plugin
    assert "VARIABLE magcal_version 1" in plugin and "VARIABLE magcal_m_0_0 " in plugin
    assert tlm.count(" DERIVED ") == 3 and tlm.count("READ_CONVERSION mag_calibration.py") == 3
    # same bytes twice: the zip is deterministic
    assert result.zip_bytes() == export(f.document, ExportOptions(format="cosmos")).zip_bytes()


def test_a_new_version_is_a_new_vars_json(tmp_path: Path, swarm_a_temperature_world: Any) -> None:
    """Same layout, new coefficients: only vars.json changes, and the same conversion file
    rendered with the new values computes the new calibration."""
    f = fitted(swarm_a_temperature_world, "linear-hk")
    doc2 = json.loads(json.dumps(f.document))
    doc2["version"] = 2
    doc2["model"]["o"] = [v + 5.0 for v in doc2["model"]["o"]]
    a = export(f.document, ExportOptions(format="cosmos")).files
    b = export(doc2, ExportOptions(format="cosmos")).files
    assert a is not None and b is not None
    changed = {k for k in a if a[k] != b[k]}
    assert "vars.json" in changed and "targets/MAGCAL/cmd_tlm/magcal_tlm.txt" not in changed
    assert "targets/MAGCAL/lib/mag_calibration.py" not in changed
    from dataclasses import replace

    from orbitcal import pipeline

    f2 = replace(f, document=doc2, b_apply_nt=pipeline.apply_document(doc2, f.telemetry))
    b2, _ = _cosmos_read(f2, tmp_path, {})
    assert np.max(np.abs(b2 - f2.b_apply_nt[f.holdout])) < EXACT_NT
    assert np.max(np.abs(b2 - f.b_apply_nt[f.holdout])) > 1.0  # it is the new version
