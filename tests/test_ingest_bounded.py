"""The mission-file readers are bounded in what a file *expands* to, not only in bytes on disk
(issue 44 item 8).

A kilobyte of YAML aliases describes 10^10 nodes ("billion laughs"); a kilobyte of ``.gz`` holds
hundreds of megabytes of one line. Each is refused with an ``IngestError`` naming the file and the
reason, within a bounded memory: the command runs in a child process whose peak RSS growth
(``resource.getrusage``) is measured around the call, under an address-space cap so that a
regression fails here instead of exhausting the machine.
"""

from __future__ import annotations

import gzip
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from orbitcal.ingest import IngestError
from orbitcal.ingest.l1b_ascii import END_OF_HEADER, MAX_LINE_BYTES, L1BFile

DATA = Path(__file__).parent / "authorities" / "gracefo"
PRODUCTS = ("MAG1B", "GNV1B", "SCA1B", "IHK1B")
#: Growth of the peak RSS allowed for refusing a hostile file [bytes]: the refusal reads the
#: header (a few kB) and at most one bounded line; the unbounded readers grew past 1.5 GB.
RSS_GROWTH_MAX = 64 * 2**20

_CHILD = r"""
import json, resource, sys
resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))
from orbitcal.cli import main
import orbitcal.ingest.gracefo, pandas, yaml  # imports before the baseline
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
code = main(sys.argv[1:])
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"code": code, "growth": after - before}))
"""


def _copy_set(d: Path) -> Path:
    d.mkdir()
    for p in PRODUCTS:
        shutil.copy(DATA / f"{p}_2023-06-01_C_04.txt", d)
    return d / "MAG1B_2023-06-01_C_04.txt"


def _alias_bomb(levels: int) -> tuple[str, str]:
    """Anchors ``a0 …`` (each ten aliases of the one before) and a value of 10^levels nodes."""
    lines = ["  bomb:", '    a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, levels):
        lines.append(f"    a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 10) + "]")
    return "\n".join(lines) + "\n", "[" + ",".join([f"*a{levels - 1}"] * 10) + "]"


def _run_cli(tmp_path: Path, d: Path) -> tuple[dict[str, int], str]:
    out = tmp_path / "out.csv"
    argv = ["ingest", "gracefo", str(d), "--out", str(out)]
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD, *argv], capture_output=True, text=True, timeout=600
    )
    assert proc.stdout.strip(), proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


@pytest.mark.parametrize("where", ["platform", "a variable's units"])
def test_a_yaml_alias_bomb_in_the_header_is_refused_in_bounded_memory(
    tmp_path: Path, where: str
) -> None:
    mag = _copy_set(tmp_path / "l1b")
    text = mag.read_text()
    anchors, value = _alias_bomb(10)
    text = text.replace("  global_attributes:\n", anchors + "  global_attributes:\n", 1)
    if where == "platform":
        text = text.replace("    platform: GRACE C\n", f"    platform: {value}\n", 1)
    else:
        text = text.replace("units: microTesla", f"units: {value}", 1)
    mag.write_text(text)
    assert len(text.split(END_OF_HEADER)[0].split("bomb:")[1].split("global_attributes")[0]) < 1500
    with pytest.raises(IngestError, match=r"MAG1B_2023-06-01_C_04\.txt:\d+: .*YAML alias") as e:
        L1BFile.open(mag)
    assert "without bound" in str(e.value)
    result, err = _run_cli(tmp_path, tmp_path / "l1b")
    lines = err.strip().splitlines()
    assert result["code"] != 0 and len(lines) == 1 and "YAML alias" in lines[0], err
    assert result["growth"] < RSS_GROWTH_MAX, result


def test_a_decompression_bomb_line_is_refused_in_bounded_memory(tmp_path: Path) -> None:
    mag = _copy_set(tmp_path / "l1b")
    head, _ = mag.read_text().split(END_OF_HEADER, 1)
    gz = mag.with_name(mag.name + ".gz")
    with gzip.open(gz, "wb", compresslevel=9) as fh:
        fh.write((head + END_OF_HEADER + "\n").encode())
        block = b"1" * 2**20
        for _ in range(256):  # 256 MiB of one record, ~250 kB on disk
            fh.write(block)
    mag.unlink()
    assert gz.stat().st_size < 2**20
    with pytest.raises(
        IngestError,
        match=rf"MAG1B_2023-06-01_C_04\.txt\.gz: a line longer than {MAX_LINE_BYTES:,} bytes",
    ):
        f = L1BFile.open(gz)
        for _ in f.chunks(["MfvX_RAW"]):
            pass
    result, err = _run_cli(tmp_path, tmp_path / "l1b")
    lines = err.strip().splitlines()
    assert result["code"] != 0 and len(lines) == 1 and "a line longer than" in lines[0], err
    assert result["growth"] < RSS_GROWTH_MAX, result


def test_a_long_header_line_is_refused_before_yaml_reads_it(tmp_path: Path) -> None:
    mag = _copy_set(tmp_path / "l1b")
    text = mag.read_text()
    mag.write_text(text.replace("    platform: GRACE C\n", "    platform: " + "C" * 10**6 + "\n"))
    with pytest.raises(IngestError, match="a line longer than"):
        L1BFile.open(mag)


def test_the_real_files_still_read(tmp_path: Path) -> None:
    for p in PRODUCTS:
        f = L1BFile.open(DATA / f"{p}_2023-06-01_C_04.txt")
        assert f.attributes["platform"] == "GRACE C"


def test_a_cdf_declaring_more_than_the_decoded_limit_is_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The Swarm reader sums what each CDF variable declares (records × elements × dimensions ×
    the widest type) before ``varget`` decodes it; the real file passes the default limit and is
    refused, naming the variable, under a limit below its size."""
    from orbitcal.ingest import swarm

    path = Path(__file__).parent / "authorities" / "swarm" / "vires_export_test_data_01.cdf"
    assert len(swarm._read_cdf(path).t_utc_s) > 0
    monkeypatch.setattr(swarm, "MAX_CDF_DECODED_BYTES", 1000)
    with pytest.raises(
        IngestError, match=r"vires_export_test_data_01\.cdf: .*MAX_CDF_DECODED_BYTES"
    ):
        swarm._read_cdf(path)
