"""The README's first command: ``orbitcal demo`` runs the main job end to end (short span)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path


def test_orbitcal_demo_recovers_after_the_parameter_change(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "orbitcal", "demo", "--days", "0.7", "--dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = proc.stdout
    assert proc.returncode == 0, (out[-3000:], proc.stderr[-3000:])
    assert "sensor parameters change at" in out
    assert re.search(r"streamed 6048 samples in 17 uploads", out)
    assert "360 duplicates, 0 new" in out
    m = re.search(r"in service: version (\d+) .* leaves (\d+\.\d+) nT rms", out)
    assert m is not None and int(m.group(1)) >= 2 and float(m.group(2)) < 10.0
    assert "superseded" in out
    assert "/dashboard#key=" in out and (tmp_path / "orbitcal.sqlite").exists()
