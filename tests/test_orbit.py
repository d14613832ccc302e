"""orbitcal.orbit against the Vallado SGP4 verification (SGP4-VER.TLE / tcppver.out, shipped in the
sgp4 wheel), sgp4's own OMM exporter, and real CelesTrak TLEs (Swarm, ISS)."""

from __future__ import annotations

import pkgutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from sgp4.api import Satrec
from sgp4.exporter import export_omm
from shared_worlds import REAL_TLES_FILE

from orbitcal import frames
from orbitcal.errors import OrbitProblemError
from orbitcal.orbit import (
    Ephemeris,
    OMMError,
    Orbit,
    OrbitError,
    PropagationError,
    StaleElementsError,
    StaleElementsWarning,
    TLEError,
    check_epoch_near,
    propagate_many,
    read_orbits,
    read_tle_sets,
    require_valid,
    select_orbit,
    tle_checksum,
)

AUTHORITIES = Path(__file__).resolve().parent / "authorities"

# Tolerances in physical units. Vallado's tcppver.out prints 1e-8 km; orbitcal takes float64
# POSIX seconds (resolution 2.4e-7 s near 2006), so a sample instant epoch + tsince can be off by
# ~2.4e-7 s, i.e. up to ~2.5 mm at 10 km/s. Measured: worst 0.9 mm (22312), most < 1e-8 km.
FIVE_MM_KM = 5e-6
ONE_MM_S_KM_S = 1e-6

# The errors sgp4's own test expects from this file, in order (sgp4 2.27 tests.py).
VALLADO_ERRORS = [1, 1, 6, 6, 4, 3, 6]

SWARM_A = """SWARM A
1 39452U 13067B   23225.54459796  .00004290  00000+0  15767-3 0  9996
2 39452  87.3500  73.6396 0002838 100.3993 259.7575 15.27620058546627
"""


def _vallado_cases() -> list[tuple[str, str, list[list[float]]]]:
    """(line1, line2 incl. start/stop/step, expected rows [tsince_min, r(3) km, v(3) km/s])."""
    tle = pkgutil.get_data("sgp4", "SGP4-VER.TLE")
    out = pkgutil.get_data("sgp4", "tcppver.out")
    assert tle is not None and out is not None
    tle_lines = [ln for ln in tle.decode("ascii").splitlines() if ln[:2] in ("1 ", "2 ")]
    pairs = list(zip(tle_lines[::2], tle_lines[1::2], strict=True))
    blocks: list[list[list[float]]] = []
    for line in out.decode("ascii").replace("\r", "").splitlines():
        if "xx" in line:
            blocks.append([])
        elif line.strip():
            blocks[-1].append([float(x) for x in line.split()[:7]])
    assert len(blocks) == len(pairs) == 33
    return [(l1, l2, rows) for (l1, l2), rows in zip(pairs, blocks, strict=True)]


def test_vallado_verification_through_orbitcal() -> None:
    cases = _vallado_cases()
    errors: list[int] = []
    n_compared = 0
    worst_r_km = worst_v_km_s = 0.0
    for line1, line2, rows in cases:
        text = line1[:69] + "\n" + line2[:69]
        checksum_ok = tle_checksum(line1) == int(line1[68]) and tle_checksum(line2) == int(
            line2[68]
        )
        if not checksum_ok:
            # Five of Vallado's test lines carry wrong checksums: orbitcal rejects them by default.
            with pytest.raises(TLEError, match="checksum"):
                Orbit.from_tle(text)
        try:
            orbit = Orbit.from_tle(text, verify_checksum=False)
        except TLEError as exc:
            # Elements that fail at epoch (33334: perturbed eccentricity) are refused up front.
            assert "error 3" in str(exc)
            errors.append(3)
            continue
        expected = np.array(rows)
        t = orbit.epoch_utc_s + expected[:, 0] * 60.0
        eph = orbit.propagate(t, max_age_days=None)
        assert np.all(eph.error_code == 0), line1
        dr = np.abs(eph.r_teme_km - expected[:, 1:4]).max()
        dv = np.abs(eph.v_teme_km_s - expected[:, 4:7]).max()
        worst_r_km, worst_v_km_s = max(worst_r_km, dr), max(worst_v_km_s, dv)
        n_compared += len(rows)
        # Where Vallado's run stopped early, SGP4 reports the error on the next step.
        start, stop, step = (float(x) for x in line2[69:].split())
        grid = np.arange(start, stop + 1e-9, step)
        if stop not in grid:
            grid = np.append(grid, stop)
        full = orbit.propagate(orbit.epoch_utc_s + grid * 60.0, max_age_days=None)
        bad = np.flatnonzero(full.error_code)
        if bad.size:
            errors.append(int(full.error_code[bad[0]]))
            assert np.all(np.isnan(full.r_itrs_km[bad]))
            with pytest.raises(PropagationError, match=f"row {bad[0]}|rows {bad[0]}"):
                require_valid(full)
    assert n_compared > 600
    assert worst_r_km < FIVE_MM_KM, worst_r_km
    assert worst_v_km_s < ONE_MM_S_KM_S, worst_v_km_s
    assert sorted(errors) == sorted(VALLADO_ERRORS)


def test_itrs_output_matches_frames() -> None:
    orbit = Orbit.from_tle(SWARM_A)
    t = orbit.epoch_utc_s + np.arange(0.0, 5400.0, 10.0)
    eph = orbit.propagate(t)
    r, v = frames.teme_to_itrs(eph.r_teme_km, eph.v_teme_km_s, t)
    np.testing.assert_allclose(eph.r_itrs_km, r, atol=1e-9)
    np.testing.assert_allclose(eph.v_itrs_km_s, v, atol=1e-12)
    # Swarm A: ~460 km altitude, polar (|latitude| reaches > 87 deg), ~7.6 km/s inertial.
    radius, colat, _ = frames.itrs_to_spherical(eph.r_itrs_km)
    assert radius.min() > 6780.0 and radius.max() < 6880.0
    assert colat.min() < 3.0 and colat.max() > 177.0
    speed = np.linalg.norm(eph.v_teme_km_s, axis=1)
    assert speed.min() > 7.5 and speed.max() < 7.7


def test_real_tles_parse() -> None:
    text = (AUTHORITIES / "swarm_iss_real_tles.tle").read_text().splitlines()
    orbits = [Orbit.from_tle("\n".join(text[i : i + 3])) for i in range(0, len(text), 3)]
    assert len(orbits) == 56
    ids = {o.name: o.norad_id for o in orbits}
    assert ids == {"ISS (ZARYA)": 25544, "SWARM A": 39452, "SWARM B": 39451, "SWARM C": 39453}
    # Epoch 22213.47757853 = 2022-08-01 (day 213) 11:27:42.785 UTC.
    assert orbits[0].epoch_utc_s == pytest.approx(1_659_312_000.0 + 0.47757853 * 86_400.0, abs=1e-5)
    for o in orbits:
        eph = o.propagate(o.epoch_utc_s + np.arange(0.0, 6000.0, 600.0))
        require_valid(eph)


def test_tle_without_name_and_with_0_prefix() -> None:
    lines = SWARM_A.splitlines()
    assert Orbit.from_tle("\n".join(lines[1:])).name == ""
    assert Orbit.from_tle("0 SWARM A\n" + "\n".join(lines[1:])).name == "SWARM A"


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda ls: [ls[0], ls[1][:-1] + "7", ls[2]], "line 1: checksum is 7"),
        (lambda ls: [ls[0], ls[1], ls[2][:-1] + "0"], "line 2: checksum"),
        (lambda ls: [ls[0], ls[1][:60], ls[2]], "line 1 has 60 characters"),
        (lambda ls: [ls[0], ls[2], ls[1]], "line 1 must start"),
        (lambda ls: [ls[1]], "got 1 non-blank"),
        (lambda ls: [ls[0], ls[1], ls[2].replace("39452", "39451")], "catalogue number"),
        (lambda ls: [ls[0], ls[1], ls[2][:9] + "8x.3500" + ls[2][16:]], "columns 9-16"),
    ],
)
def test_bad_tles_are_rejected_clearly(mutate: object, match: str) -> None:
    lines = mutate(SWARM_A.splitlines())  # type: ignore[operator]
    if "catalogue" in match or "columns" in match:  # right checksum: the content check must fail
        l2 = lines[2][:68]
        lines[2] = l2 + str(tle_checksum(l2))
    with pytest.raises(TLEError, match=match):
        Orbit.from_tle("\n".join(lines))
    assert issubclass(TLEError, ValueError)


def test_omm_matches_tle() -> None:
    orbit = Orbit.from_tle(SWARM_A)
    fields = export_omm(Satrec.twoline2rv(*SWARM_A.splitlines()[1:]), "SWARM A")
    from_omm = Orbit.from_omm(fields)
    assert (from_omm.norad_id, from_omm.name) == (39452, "SWARM A")
    assert from_omm.epoch_utc_s == pytest.approx(orbit.epoch_utc_s, abs=1e-4)
    t = orbit.epoch_utc_s + np.arange(0.0, 86_400.0, 300.0)
    a, b = orbit.propagate(t), from_omm.propagate(t)
    # OMM carries the same mean elements in decimal text: identical to < 1 m over a day.
    assert np.abs(a.r_teme_km - b.r_teme_km).max() < 1e-3
    bad = dict(fields)
    del bad["MEAN_MOTION"]
    with pytest.raises(OMMError, match="MEAN_MOTION"):
        Orbit.from_omm(bad)
    with pytest.raises(OMMError, match="REF_FRAME"):
        Orbit.from_omm({**fields, "REF_FRAME": "GCRF"})
    # Epoch written with a Z and without fractional seconds (as some providers do).
    whole = {**fields, "EPOCH": "2023-08-13T13:04:13Z"}
    assert Orbit.from_omm(whole).epoch_utc_s == pytest.approx(1_691_931_853.0, abs=1e-5)


def test_propagate_many_equals_one_by_one() -> None:
    text = (AUTHORITIES / "swarm_iss_real_tles.tle").read_text().splitlines()
    orbits = [Orbit.from_tle("\n".join(text[i : i + 3])) for i in range(0, len(text), 3)][-12:]
    t = orbits[0].epoch_utc_s + np.arange(0.0, 7200.0, 60.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaleElementsWarning)
        many = propagate_many(orbits, t)
        assert many.r_itrs_km.shape == (12, t.size, 3)
        assert many.error_code.shape == (12, t.size)
        for i, o in enumerate(orbits):
            one = o.propagate(t)
            # Same elements; SatrecArray takes one Julian-date split (the first orbit's epoch), so
            # the float64 rounding of two POSIX epochs (~2e-7 s each) enters: < 5 mm at 7.6 km/s.
            np.testing.assert_allclose(many.r_teme_km[i], one.r_teme_km, atol=5e-6)
            np.testing.assert_allclose(many.r_itrs_km[i], one.r_itrs_km, atol=5e-6)


def test_stale_warning_and_decay_reported() -> None:
    orbit = Orbit.from_tle(SWARM_A)
    with pytest.warns(StaleElementsWarning, match="days from the element epoch"):
        orbit.propagate(orbit.epoch_utc_s + np.array([0.0, 20.0 * 86_400.0]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        orbit.propagate(orbit.epoch_utc_s + np.array([0.0, 20.0 * 86_400.0]), max_age_days=30.0)
    # 2000 days on, the ISS elements of 2022-08-09 (no reboosts in SGP4) have decayed: error 6.
    iss = Orbit.from_tle(
        "ISS (ZARYA)\n"
        "1 25544U 98067A   22221.57604654  .00011001  00000+0  19835-3 0  9997\n"
        "2 25544  51.6434  72.1103 0005051  94.7546 308.5806 15.50298045353465"
    )
    t = iss.epoch_utc_s + np.array([0.0, np.nan, 2.0e3 * 86_400.0])
    eph = iss.propagate(t, max_age_days=None)
    assert eph.error_code.tolist() == [0, -1, 6]
    assert np.isnan(eph.r_itrs_km[1:]).all() and np.isfinite(eph.r_itrs_km[0]).all()
    with pytest.raises(PropagationError) as info:
        eph.require_valid()
    message = str(info.value)
    assert "error -1 (the sample time is not a finite number) at rows 1" in message
    assert (
        "error 6 (mrt is less than 1.0 which indicates the satellite has decayed) at rows 2"
        in message
    )
    assert list(info.value.rows) == [1, 2]


def test_ephemeris_is_a_frozen_dataclass() -> None:
    eph = Orbit.from_tle(SWARM_A).propagate([Orbit.from_tle(SWARM_A).epoch_utc_s])
    assert isinstance(eph, Ephemeris)
    assert eph.valid.tolist() == [True]
    with pytest.raises(AttributeError):
        eph.error_code = np.zeros(1, dtype=np.int64)  # type: ignore[misc]


def test_orbit_pickles_and_writes_its_tle() -> None:
    import pickle

    orbit = Orbit.from_tle(SWARM_A)
    again = pickle.loads(pickle.dumps(orbit))
    assert again == orbit and again.name == "SWARM A"
    assert orbit.to_tle_text() == SWARM_A
    omm = Orbit.from_omm(export_omm(orbit.satrec, "SWARM A"))
    again = pickle.loads(pickle.dumps(omm))
    t = orbit.epoch_utc_s + np.arange(0.0, 3600.0, 60.0)
    np.testing.assert_array_equal(again.propagate(t).r_teme_km, omm.propagate(t).r_teme_km)
    assert Orbit.from_tle(omm.to_tle_text()).norad_id == 39452


# --- one parser for TLE and OMM files; physical validation (issue 10 item 4, issue 11 item 7) ----

REAL_TLES = REAL_TLES_FILE  # tests/shared_worlds.py


def _swarm_a_omm() -> dict[str, str]:
    orbit = select_orbit(REAL_TLES.read_text(), norad_id=39452, at_utc_s=1_659_398_400.0)
    return {k: str(v) for k, v in export_omm(orbit.satrec, "SWARM A").items()}


def test_read_orbits_reads_tle_and_omm_json_csv_xml_alike() -> None:
    import csv
    import io
    import json

    fields = _swarm_a_omm()
    ref = Orbit.from_omm(fields)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(fields))
    writer.writeheader()
    writer.writerow(fields)
    meta_keys = {"OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "REF_FRAME", "TIME_SYSTEM"}
    mean_keys = {"EPOCH", "MEAN_MOTION", "ECCENTRICITY", "INCLINATION", "RA_OF_ASC_NODE"}
    mean_keys |= {"ARG_OF_PERICENTER", "MEAN_ANOMALY"}

    def tags(keys: set[str]) -> str:
        return "".join(f"<{k}>{v}</{k}>" for k, v in fields.items() if k in keys)

    rest = set(fields) - meta_keys - mean_keys
    xml = (  # the CCSDS NDM/XML layout CelesTrak serves (FORMAT=xml)
        '<?xml version="1.0"?><ndm><omm><body><segment>'
        f"<metadata>{tags(meta_keys)}</metadata><data><meanElements>{tags(mean_keys)}"
        f"</meanElements><tleParameters>{tags(rest)}</tleParameters></data>"
        "</segment></body></omm></ndm>"
    )
    for text in (json.dumps([fields]), json.dumps(fields), buf.getvalue(), xml):
        (orbit,) = read_orbits(text)
        assert orbit.norad_id == 39452
        assert abs(orbit.epoch_utc_s - ref.epoch_utc_s) < 1e-5
    tles = read_orbits(REAL_TLES.read_text())
    assert len(tles) == 56 and {o.norad_id for o in tles} == {25544, 39451, 39452, 39453}


def test_select_orbit_takes_the_set_nearest_the_data() -> None:
    sets = read_tle_sets(REAL_TLES.read_text())
    swarm_a = sorted((o for o in sets if o.norad_id == 39452), key=lambda o: o.epoch_utc_s)
    target = swarm_a[len(swarm_a) // 2]
    span = (target.epoch_utc_s + 3600.0, target.epoch_utc_s + 7200.0)
    chosen = select_orbit(sets, norad_id=39452, at_utc_s=span)
    distances = [min(abs(o.epoch_utc_s - span[0]), abs(o.epoch_utc_s - span[1])) for o in swarm_a]
    assert chosen.epoch_utc_s == swarm_a[int(np.argmin(distances))].epoch_utc_s
    with pytest.raises(OrbitError, match="--norad"):
        select_orbit(sets, at_utc_s=span)
    with pytest.raises(OrbitError, match="no element set for NORAD 1"):
        select_orbit(sets, norad_id=1)


def test_stale_elements_are_refused_with_the_distance() -> None:
    orbit = Orbit.from_tle(SWARM_A)
    assert check_epoch_near(orbit, [orbit.epoch_utc_s + 86400.0]) == pytest.approx(1.0)
    with pytest.raises(StaleElementsError, match=r"20\.0 days from the data, more than 14") as e:
        check_epoch_near(orbit, [orbit.epoch_utc_s - 20 * 86400.0])
    assert e.value.field == "epoch" and isinstance(e.value, OrbitProblemError)


@pytest.mark.parametrize(
    ("key", "value", "words"),
    [
        ("MEAN_MOTION", "nan", "must be finite"),
        ("MEAN_MOTION", "-15.3", "> 0"),
        ("MEAN_MOTION", "0", "> 0"),
        ("MEAN_MOTION", "inf", "must be finite"),
        ("ECCENTRICITY", "1.0", "< 1"),
        ("ECCENTRICITY", "-0.001", "≥ 0"),
        ("INCLINATION", "180.5", "≤ 180"),
        ("RA_OF_ASC_NODE", "1e308", "≤ 360"),
        ("MEAN_ANOMALY", "x", "not a number"),
        ("BSTAR", "1e30", "|x| < 1"),
        ("ELEMENT_SET_NO", str(10**30), "largest allowed is 9999"),
        ("ELEMENT_SET_NO", "-1", "whole number"),
        ("REV_AT_EPOCH", "100000", "largest allowed is 99999"),
        ("NORAD_CAT_ID", "340000", "largest allowed is 339999"),
        ("NORAD_CAT_ID", "1e3", "whole number"),
        ("CLASSIFICATION_TYPE", "UU", "one letter"),
    ],
)
def test_unphysical_omm_values_name_the_field(key: str, value: str, words: str) -> None:
    fields = _swarm_a_omm()
    fields[key] = value
    with pytest.raises(OMMError) as e:
        Orbit.from_omm(fields)
    assert e.value.field == key and key in str(e.value) and words in str(e.value)
    assert isinstance(e.value, OrbitProblemError)


def test_unphysical_tle_values_name_the_field() -> None:
    line1, line2 = SWARM_A.strip().splitlines()[-2:]

    def with_checksum(line: str) -> str:
        return line[:68] + str(tle_checksum(line))

    bad_inclination = with_checksum(line2[:8] + "187.3500" + line2[16:])
    with pytest.raises(TLEError, match="INCLINATION") as e:
        Orbit.from_tle(f"{line1}\n{bad_inclination}")
    assert e.value.field == "INCLINATION"
    bad_motion = with_checksum(line2[:52] + "-5.27620058" + line2[63:])
    with pytest.raises(TLEError, match="MEAN_MOTION"):
        Orbit.from_tle(f"{line1}\n{bad_motion}")


def test_decayed_elements_are_refused_naming_the_field() -> None:
    fields = _swarm_a_omm()
    fields["MEAN_MOTION"] = "18.5"  # a semi-major axis below the Earth's radius
    with pytest.raises(OMMError, match="SGP4 initialisation") as e:
        Orbit.from_omm(fields)
    assert e.value.field in {"ECCENTRICITY", "MEAN_MOTION", "EPOCH"}
