"""orbitcal.auxdata: update, validation, fallback and provenance against a loopback HTTP server.

The server (http.server on 127.0.0.1 in a thread) serves fixture files: the real IERS
leap-seconds.list shipped with orbitcal (current), the real tzdata 2025b copy (expired), corrupted
and truncated variants, and small synthetic EOP/RC/Kp/Dst tables written here in their published
formats (synthetic values, labelled as such: they test the machinery, not geophysics).
"""

from __future__ import annotations

import http.server
import json
import threading
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from orbitcal import auxdata, frames, timescales
from orbitcal.auxdata.formats import (
    TableFormatError,
    parse_dst_wdc,
    parse_finals2000a,
    parse_kp_gfz,
    parse_leap_seconds,
    write_leap_second_dat,
)
from orbitcal.cli import main as cli_main
from orbitcal.provenance import result_provenance

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "auxdata"
SHIPPED_LEAP = (
    Path(__file__).resolve().parents[1] / "orbitcal" / "auxdata" / "shipped" / "leap-seconds.list"
)
ARCSEC = np.pi / (180.0 * 3600.0)


def _ts(y: int, m: int, d: int, h: int = 0) -> float:
    return datetime(y, m, d, h, tzinfo=UTC).timestamp()


# --- synthetic tables in the published formats ---------------------------------------------------


def finals_text(
    mjd0: int, n_days: int, *, x: float, y: float, first_predicted_mjd: int, dut1_0: float = 0.05
) -> str:
    """finals2000A rows (Bulletin A columns) with constant polar motion and a slow UT1 drift."""
    lines = []
    for k in range(n_days):
        mjd = mjd0 + k
        d = datetime.fromtimestamp((mjd - 40587) * 86400.0, tz=UTC)
        flag = "P" if mjd >= first_predicted_mjd else "I"
        dut1 = dut1_0 - 0.0003 * k
        line = (
            f"{d.year % 100:02d}{d.month:02d}{d.day:02d} {mjd:8.2f} {flag} {x:9.6f}{0.0:9.6f} "
            f"{y:9.6f}{0.0:9.6f}  {flag}{dut1:10.7f}{0.0:10.7f}"
        )
        assert line[57] == flag and float(line[58:68]) == pytest.approx(dut1)
        lines.append(line.ljust(80))
    return "\n".join(lines) + "\n"


def rc_dat_text(t0_mjd2000: float, n_hours: int, value_nt: float) -> str:
    rows = ["# time RC RC_e RC_i flag (synthetic test table)"]
    for k in range(n_hours):
        t = t0_mjd2000 + k / 24.0
        rows.append(f"{t:.6f} {value_nt:.3f} {0.7 * value_nt:.3f} {0.3 * value_nt:.3f} Q")
    return "\n".join(rows) + "\n"


def kp_text(start: datetime, kps: list[float]) -> str:
    rows = ["#YYY MM DD hh.h hh._m        days      days_m     Kp  ap D"]
    for k, kp in enumerate(kps):
        t = start.timestamp() + k * 3 * 3600.0
        d = datetime.fromtimestamp(t, tz=UTC)
        rows.append(
            f"{d.year} {d.month:02d} {d.day:02d} {d.hour:04.1f} {d.hour + 1.5:05.2f} "
            f"{k / 8:11.5f} {k / 8 + 0.0625:11.5f} {kp:6.3f} {7:4d} 0"
        )
    return "\n".join(rows) + "\n"


def dst_wdc_text(day: datetime, hourly: list[int]) -> str:
    values = "".join(f"{v:4d}" for v in hourly)
    mean = round(sum(hourly) / 24)
    line = (
        f"DST{day.year % 100:02d}{day.month:02d}*{day.day:02d}  X0{day.year // 100:2d}"
        f"{0:4d}{values}{mean:4d}"
    )
    assert len(line) == 120
    return line + "\n"


# --- the loopback server -------------------------------------------------------------------------


class _Handler(http.server.BaseHTTPRequestHandler):
    files: ClassVar[dict[str, bytes]] = {}
    lie_length: ClassVar[set[str]] = set()

    def do_GET(self) -> None:
        body = self.files.get(self.path)
        if body is None:
            self.send_error(404)
            return
        self.send_response(200)
        declared = len(body) + (500 if self.path in self.lie_length else 0)
        self.send_header("Content-Length", str(declared))
        self.end_headers()
        self.wfile.write(body)
        if self.path in self.lie_length:
            self.close_connection = True

    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def server() -> Iterator[tuple[str, dict[str, bytes], set[str]]]:
    files: dict[str, bytes] = {}
    lie: set[str] = set()
    handler = type("H", (_Handler,), {"files": files, "lie_length": lie})
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}", files, lie
    finally:
        httpd.shutdown()
        httpd.server_close()


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    d = tmp_path / "orbitcal-data"
    monkeypatch.setenv("ORBITCAL_DATA_DIR", str(d))
    auxdata.reload()
    yield d
    monkeypatch.delenv("ORBITCAL_DATA_DIR")
    auxdata.reload()  # the next tests see the shipped tables again


# --- formats ------------------------------------------------------------------------------------


def test_shipped_leap_list_verifies_and_equals_the_written_table() -> None:
    table = parse_leap_seconds(SHIPPED_LEAP.read_bytes())
    assert table.format == "IERS leap-seconds.list"
    assert (
        datetime.fromtimestamp(table.valid_until_utc_s, tz=UTC).date().isoformat() == "2027-06-28"
    )
    written = [
        (datetime.fromtimestamp(t, tz=UTC).date().isoformat(), int(o))
        for t, o in zip(table.data["t_utc_s"], table.data["tai_minus_utc_s"], strict=True)
    ]
    assert written == list(timescales.LEAP_SECOND_TABLE)
    # The same table as IERS Leap_Second.dat reads back identically.
    dat = write_leap_second_dat(
        table.data["t_utc_s"], table.data["tai_minus_utc_s"], expires="28 June 2027"
    )
    again = parse_leap_seconds(dat.encode())
    assert again.format == "IERS Leap_Second.dat"
    np.testing.assert_array_equal(again.data["t_utc_s"], table.data["t_utc_s"])
    assert again.valid_until_utc_s == table.valid_until_utc_s


def test_leap_list_checksum_truncation_and_garbage_are_refused() -> None:
    raw = SHIPPED_LEAP.read_bytes()
    corrupt = raw.replace(b"3692217600      37", b"3692217600      38")
    with pytest.raises(TableFormatError, match="SHA-1"):
        parse_leap_seconds(corrupt)
    with pytest.raises(TableFormatError, match=r"truncated|'#h'"):
        parse_leap_seconds(raw[: len(raw) // 2])
    with pytest.raises(TableFormatError, match="neither"):
        parse_leap_seconds(b"<html>404 not found</html>")
    with pytest.raises(TableFormatError, match="empty"):
        parse_leap_seconds(b"")
    expired = parse_leap_seconds((FIXTURES / "leap-seconds-2025b.list").read_bytes())
    assert datetime.fromtimestamp(expired.valid_until_utc_s, tz=UTC).date().isoformat() == (
        "2026-06-28"
    )


def test_finals_parser_reads_flags_and_refuses_bad_rows() -> None:
    text = finals_text(61300, 60, x=0.2, y=0.35, first_predicted_mjd=61340)
    table = parse_finals2000a(text.encode())
    assert table.data["mjd"][0] == 61300 and table.data["mjd"].size == 60
    assert table.predictions_from_utc_s == (61340 - 40587) * 86400.0
    np.testing.assert_allclose(table.data["x_arcsec"], 0.2)
    lines = text.splitlines()
    with pytest.raises(TableFormatError, match="not daily"):
        parse_finals2000a(("\n".join(lines[:10] + lines[11:]) + "\n").encode())
    with pytest.raises(TableFormatError, match="truncated"):
        parse_finals2000a(("\n".join(lines[:20]) + "\n").encode())
    bad = lines[5][:58] + " 3.0000000" + lines[5][68:]
    with pytest.raises(TableFormatError, match=r"0\.9 s"):
        parse_finals2000a(("\n".join([*lines[:5], bad, *lines[6:]]) + "\n").encode())


def test_kp_and_dst_parsers() -> None:
    kp = parse_kp_gfz(
        kp_text(datetime(2026, 11, 1, tzinfo=UTC), [1.0, 2.333, 5.667, 1.0] * 4).encode()
    )
    assert kp.data["kp"].size == 16 and kp.data["kp"][2] == pytest.approx(5.667)
    dst = parse_dst_wdc(
        dst_wdc_text(datetime(2026, 11, 1, tzinfo=UTC), [-5] * 12 + [-80] * 12).encode()
    )
    assert dst.data["dst_nt"].size == 24 and dst.data["dst_nt"][-1] == -80
    assert dst.data["t_start_utc_s"][0] == _ts(2026, 11, 1)
    with pytest.raises(TableFormatError, match="DSTyymm"):
        parse_dst_wdc(b"DST2611 garbage\n")


# --- update over HTTP ---------------------------------------------------------------------------


def test_update_installs_valid_files_and_keeps_good_tables_on_bad_downloads(
    server: tuple[str, dict[str, bytes], set[str]], data_dir: Path
) -> None:
    base, files, lie = server
    good_leap = SHIPPED_LEAP.read_bytes()
    files["/leap/current"] = good_leap
    files["/leap/corrupt"] = good_leap.replace(b"      37", b"      38")
    files["/leap/truncated"] = good_leap[: len(good_leap) * 2 // 3]
    files["/leap/expired"] = (FIXTURES / "leap-seconds-2025b.list").read_bytes()
    files["/leap/cut"] = good_leap
    lie.add("/leap/cut")

    def run(path: str) -> dict[str, object]:
        (res,) = auxdata.update(kinds=["leap_seconds"], urls={"leap_seconds": base + path})
        return res

    first = run("/leap/current")
    assert first["status"] == "updated", first
    installed = (data_dir / "leap-seconds.list").read_bytes()
    assert installed == good_leap
    manifest = json.loads((data_dir / "manifest.json").read_text())
    entry = manifest["tables"]["leap_seconds"]
    assert entry["source_url"] == base + "/leap/current"
    assert entry["valid_until"] == "2027-06-28T00:00:00Z"
    assert len(entry["sha256"]) == 64 and entry["retrieved_at"].endswith("Z")
    assert run("/leap/current")["status"] == "unchanged"
    for path, why in [
        ("/leap/corrupt", "SHA-1"),
        ("/leap/truncated", "#h"),
        ("/leap/expired", "earlier than the one in use"),
        ("/leap/cut", "IncompleteRead|truncated"),
        ("/leap/missing", "404"),
    ]:
        res = run(path)
        assert res["status"] == "failed", (path, res)
        assert __import__("re").search(why, str(res["reason"])), (path, res["reason"])
        # The good table is untouched, and no temporary file is left behind.
        assert (data_dir / "leap-seconds.list").read_bytes() == good_leap
        assert json.loads((data_dir / "manifest.json").read_text()) == manifest
        assert not list(data_dir.glob(".*.part"))
    active = auxdata.active_table("leap_seconds")
    assert active is not None and active.origin in ("installed", "shipped")


def test_eop_update_enters_the_frames_with_polar_motion_and_predictions(
    server: tuple[str, dict[str, bytes], set[str]], data_dir: Path
) -> None:
    base, files, _ = server
    # Synthetic finals: 2026-10-01 .. 2027-12-31, observed until 2026-11-15, x = 0.2", y = 0.35".
    mjd0 = 61314  # 2026-10-01
    files["/finals2000A.all"] = finals_text(
        mjd0, 457, x=0.2, y=0.35, first_predicted_mjd=61359
    ).encode()
    t = np.array([_ts(2026, 11, 2, 6), _ts(2026, 11, 20, 18)])
    m_before = frames.gcrs_to_itrs_matrix(t)
    (res,) = auxdata.update(kinds=["eop"], urls={"eop": base + "/finals2000A.all"})
    assert res["status"] == "updated", res
    active = auxdata.active_table("eop")
    assert active is not None and active.origin == "installed"
    # UT1 − UTC is the table's (linear between daily rows).
    k = (t - (mjd0 - 40587) * 86400.0) / 86400.0
    np.testing.assert_allclose(timescales.ut1_minus_utc_s(t), 0.05 - 0.0003 * k, atol=1e-6)
    # Polar motion now rotates ITRS: W ≈ rotation by (x, y) about the y and x axes.
    m_after = frames.gcrs_to_itrs_matrix(t)
    w = np.einsum("nij,nkj->nik", m_after, m_before)  # W_after · (W_before = I)·R·C ... ≈ W · ΔR3
    assert w[0, 0, 2] == pytest.approx(0.2 * ARCSEC, rel=0.02, abs=0.01 * ARCSEC) or w[
        0, 2, 0
    ] == pytest.approx(-0.2 * ARCSEC, rel=0.02, abs=0.01 * ARCSEC)
    tilt = np.degrees(np.arccos(np.clip(w[:, 2, 2], -1, 1))) * 3600.0
    np.testing.assert_allclose(tilt, np.hypot(0.2, 0.35), rtol=0.02)
    # Provenance: observed before 2026-11-15, predicted after, past the end after 2027-12-31.
    assert auxdata.table_status("eop", t[0], t[0])["status"] == "observed"
    assert auxdata.table_status("eop", t[0], t[1])["status"] == "predicted"
    assert auxdata.table_status("eop", t[0], _ts(2028, 3, 1))["status"] == "past_end"
    assert auxdata.table_status("eop", t[0], t[1])["polar_motion"] == "from the table"


def test_rc_index_update_from_the_directory_page_extends_the_external_field(
    server: tuple[str, dict[str, bytes], set[str]], data_dir: Path
) -> None:
    from orbitcal.field.external import ring_current_field

    base, files, _ = server
    nov = _ts(2026, 11, 12)
    with pytest.raises(ValueError, match="RC"):
        ring_current_field().rc_nt(np.array([nov]))  # shipped index ends 2026-05-08
    t0 = (_ts(2026, 5, 1) - 946_684_800.0) / 86400.0
    files["/RC/"] = b'<html><a href="old.dat">old</a> <a href="RC/current/RC_2026_v1.dat">now</a>'
    files["/RC/RC/current/RC_2026_v1.dat"] = rc_dat_text(t0, 24 * 230, -20.0).encode()
    (res,) = auxdata.update(kinds=["rc_index"], urls={"rc_index": base + "/RC/"})
    assert res["status"] == "updated", res
    assert res["url"].endswith("RC/current/RC_2026_v1.dat")
    rc_e, rc_i = ring_current_field().rc_nt(np.array([nov]))
    assert rc_e[0] == pytest.approx(-14.0) and rc_i[0] == pytest.approx(-6.0)
    prov = auxdata.tables_provenance([nov, nov + 3600.0])
    assert prov["tables"]["rc_index"]["status"] == "covered"
    assert prov["tables"]["rc_index"]["origin"] == "installed"
    # A garbage "RC file" (an HTML error page) is refused and the installed one stays.
    files["/RC/RC/current/RC_2026_v1.dat"] = b"<html>maintenance</html>"
    (res,) = auxdata.update(kinds=["rc_index"], urls={"rc_index": base + "/RC/"})
    assert res["status"] == "failed"
    assert auxdata.active_table("rc_index").origin == "installed"  # type: ignore[union-attr]


def test_provenance_past_the_shipped_tables_says_so(data_dir: Path) -> None:
    nov = [_ts(2026, 11, 12), _ts(2026, 11, 13)]
    prov = result_provenance(nov, reference_field="IGRF-14")
    tables = prov["tables"]
    assert tables["rc_index"]["status"] == "past_end"
    assert tables["rc_index"]["coverage_end"].startswith("2026-05-08")
    assert tables["eop"]["status"] == "predicted"
    assert tables["leap_seconds"]["status"] == "valid"
    assert any("RC index" in w for w in prov["warnings"])
    assert prov["reference_field"]["models"][0]["generation"] == "14"
    late = auxdata.tables_provenance([_ts(2027, 8, 1)])
    assert late["tables"]["leap_seconds"]["status"] == "past_expiry"
    assert late["tables"]["eop"]["status"] == "past_end"
    assert any("expiry" in w for w in late["warnings"])


def test_storm_mask_by_kp_and_dst_and_the_rc_stand_in(data_dir: Path) -> None:
    day = datetime(2026, 11, 1, tzinfo=UTC)
    tables = {
        "kp": parse_kp_gfz(kp_text(day, [1.0, 2.0, 5.0, 1.0, 1.0, 1.0, 1.0, 1.0]).encode()),
        "dst": parse_dst_wdc(dst_wdc_text(day, [-5] * 18 + [-60] * 6).encode()),
    }
    t = day.timestamp() + np.arange(0, 86400, 600.0)
    mask = auxdata.storm_mask(t, kp_max=3.0, dst_min_nt=-30.0, tables=tables)
    hour = (t - day.timestamp()) / 3600.0
    expected = ((hour >= 6) & (hour < 9)) | (hour >= 18)
    np.testing.assert_array_equal(mask.storm, expected)
    assert [w["start"] for w in mask.windows] == ["2026-11-01T06:00:00Z", "2026-11-01T18:00:00Z"]
    assert not mask.unknown.any()
    # Without Kp/Dst tables the shipped RC index stands in for Dst (2025-11-12: a storm day).
    t_rc = _ts(2025, 11, 12) + np.arange(0, 86400, 3600.0)
    rc_mask = auxdata.storm_mask(t_rc, kp_max=3.0, dst_min_nt=-30.0)
    assert rc_mask.sources["kp"] is None
    assert "RC index as a Dst-like stand-in" in str(rc_mask.sources["dst"])
    assert not rc_mask.unknown.any()
    rc = auxdata.active_table("rc_index")
    assert rc is not None
    mjd = (t_rc - 946_684_800.0) / 86400.0
    rc_nt = np.interp(mjd, rc.parsed.data["time_mjd2000"], rc.parsed.data["rc_e_nt"]) + np.interp(
        mjd, rc.parsed.data["time_mjd2000"], rc.parsed.data["rc_i_nt"]
    )
    np.testing.assert_array_equal(rc_mask.storm, rc_nt < -30.0)
    # Past every table: nothing known, nothing flagged.
    far = auxdata.storm_mask([_ts(2030, 1, 1)], kp_max=3.0, dst_min_nt=-30.0)
    assert far.unknown.all() and not far.storm.any()


def test_cli_data_update_and_status(
    server: tuple[str, dict[str, bytes], set[str]],
    data_dir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    base, files, _ = server
    files["/leap"] = SHIPPED_LEAP.read_bytes()
    files["/kp"] = kp_text(datetime(2026, 11, 1, tzinfo=UTC), [1.0] * 40).encode()
    other = data_dir.parent / "mirror-dir"
    code = cli_main(
        [
            "data", "update", "--data-dir", str(other), "--only", "leap_seconds", "kp",
            "--url", f"leap_seconds={base}/leap", "--url", f"kp={base}/kp", "--json",
        ]
    )  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and [r["status"] for r in out] == ["updated", "updated"]
    assert cli_main(["data", "status", "--data-dir", str(other), "--json"]) == 0
    status = json.loads(capsys.readouterr().out)
    assert status["tables"]["kp"]["active"]["origin"] == "installed"
    assert status["tables"]["kp"]["active"]["valid_until"] == "2026-11-06T00:00:00Z"
    assert status["tables"]["dst"]["active"] is None
    assert status["tables"]["rc_index"]["active"]["origin"] == "shipped"
    files["/bad"] = b"not a table"
    code = cli_main(["data", "update", "--data-dir", str(other), "--only", "kp",
                     "--url", f"kp={base}/bad"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 1 and "kp" in captured.err and "kept" in captured.err
    assert cli_main(["data", "status", "--data-dir", str(other)]) == 0
    text = capsys.readouterr().out
    assert "kp" in text and "installed: Kp_ap_since_1932.txt" in text


def test_tampered_installed_file_falls_back_to_the_shipped_table(
    server: tuple[str, dict[str, bytes], set[str]], data_dir: Path
) -> None:
    base, files, _ = server
    files["/finals"] = finals_text(61314, 457, x=0.1, y=0.1, first_predicted_mjd=61359).encode()
    auxdata.update(kinds=["eop"], urls={"eop": base + "/finals"})
    assert auxdata.active_table("eop").origin == "installed"  # type: ignore[union-attr]
    path = data_dir / "finals2000A.all"
    path.write_bytes(path.read_bytes()[:-500])
    auxdata.reload()
    active = auxdata.active_table("eop")
    assert active is not None and active.origin == "shipped"
    assert any("sha256" in n for n in active.notes)


def test_using_a_what_if_table_changes_the_frames_and_restores_them() -> None:
    import dataclasses

    eop = auxdata.active_table("eop")
    assert eop is not None
    t = np.array([_ts(2023, 11, 20, 6)])
    before = frames.gcrs_to_itrs_matrix(t)
    shifted = dataclasses.replace(
        eop.parsed, data={**eop.parsed.data, "dut1_s": eop.parsed.data["dut1_s"] + 0.5}
    )
    with auxdata.using({"eop": shifted}):
        assert auxdata.active_table("eop").origin == "override"  # type: ignore[union-attr]
        during = frames.gcrs_to_itrs_matrix(t)
    # 0.5 s more UT1 turns the Earth by ω · 0.5 s about the pole (ERA rate 1.00273781 × 2π/day).
    angle = np.arccos(np.clip((np.trace(during[0] @ before[0].T) - 1.0) / 2.0, -1.0, 1.0))
    assert angle == pytest.approx(0.5 * 7.292115e-5, rel=1e-3)
    np.testing.assert_allclose(frames.gcrs_to_itrs_matrix(t), before, atol=1e-15)


def test_scheduler_table_job_is_off_by_default_and_updates_when_on(
    server: tuple[str, dict[str, bytes], set[str]],
    data_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from service.scheduler import FleetScheduler
    from service.settings import Settings

    base, files, _ = server
    files["/leap"] = SHIPPED_LEAP.read_bytes()
    urls = {k: f"{base}/missing-{k}" for k in auxdata.KINDS}
    urls["leap_seconds"] = base + "/leap"
    monkeypatch.setattr("orbitcal.auxdata.tables.DEFAULT_URLS", urls)
    cases = [(Settings(scheduler_tick_s=3600.0), False)]
    cases.append((Settings(scheduler_tick_s=3600.0, aux_update_s=86400.0), True))
    for settings, expected in cases:
        sched = FleetScheduler(None, settings, None)  # type: ignore[arg-type]
        sched.start()
        try:
            ids = {job.id for job in sched._scheduler.get_jobs()}
        finally:
            sched.shutdown()
        assert ("orbitcal-aux-update" in ids) is expected
    results = FleetScheduler(None, Settings(), None).update_tables()  # type: ignore[arg-type]
    status = {r["kind"]: r["status"] for r in results}
    assert status["leap_seconds"] == "updated"
    assert status["eop"] == status["kp"] == "failed"  # 404s: the shipped tables stay in use
    assert auxdata.active_table("eop").origin == "shipped"  # type: ignore[union-attr]
    assert (data_dir / "leap-seconds.list").exists()


def test_quiet_selection_leaves_storm_rows_out_and_records_them(data_dir: Path) -> None:
    # 2025-11-12 is a storm day in the shipped RC index (the Dst-like stand-in here).
    t = _ts(2025, 11, 11) + np.arange(0, 3 * 86400, 600.0)
    keep, record = auxdata.quiet_selection(t, kp_max=None, dst_min_nt=-50.0)
    assert record is not None and record["applied"]
    storm = auxdata.storm_mask(t, kp_max=None, dst_min_nt=-50.0).storm
    assert 0 < storm.sum() < t.size
    np.testing.assert_array_equal(keep, ~storm)
    assert record["left_out"] == int(storm.sum()) and record["windows"]
    off_keep, off = auxdata.quiet_selection(t, kp_max=None, dst_min_nt=None)
    assert off is None and off_keep.all()
    # A window that is all storm keeps everything and says it did not apply the selection.
    all_keep, rec = auxdata.quiet_selection(t, kp_max=None, dst_min_nt=1000.0)
    assert all_keep.all() and rec is not None and rec["applied"] is False
