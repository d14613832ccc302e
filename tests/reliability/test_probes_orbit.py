"""Black-box probes of orbits: bad TLE/OMM elements against a real ``orbitcal serve`` process.

Issue 10 item 4: TLE and OMM numbers must be finite and in range (mean motion > 0, 0 ≤ e < 1,
inclination 0–180°, angles 0–360°, integer fields within their TLE width, an element-set number of
10^30 refused), decayed elements refused; every refusal is a 422 naming the field, and nothing is
stored. Two routes take elements: ``POST /v1/spacecraft`` (``tle`` or ``omm``) and
``PUT /v1/spacecraft/{id}/orbit``. Each probe asserts the status, the field's name in the answer,
and afterwards that no spacecraft was created (POST) or that the spacecraft still has no orbit
(PUT). The elements are Swarm A's real CelesTrak set of 2022-08-01 with one value changed; class
``orbit`` in the probe summary (framework: ``probes.py``).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest
import sqlalchemy as sa
from probes import Probe, ServeProcess, serve_process
from reliability_helpers import SWARM_A_TLE
from shared_worlds import SWARM_A_2022_OMM

from orbitcal.orbit import tle_checksum

JSON = {"content-type": "application/json"}

#: Swarm A (NORAD 39452), CelesTrak OMM of 2022-08-01 (tests/shared_worlds.py).
OMM: dict[str, Any] = SWARM_A_2022_OMM

#: (probe name, OMM keyword, value): each must be a 422 naming the keyword.
BAD_OMM_VALUES: list[tuple[str, str, Any]] = [
    ("mean-motion-nan", "MEAN_MOTION", "nan"),
    ("mean-motion-inf", "MEAN_MOTION", "inf"),
    ("mean-motion-negative", "MEAN_MOTION", -15.3),
    ("mean-motion-zero", "MEAN_MOTION", 0),
    ("mean-motion-1e300", "MEAN_MOTION", 1e300),
    ("mean-motion-text", "MEAN_MOTION", "fast"),
    ("eccentricity-1", "ECCENTRICITY", 1.0),
    ("eccentricity-1.5", "ECCENTRICITY", 1.5),
    ("eccentricity-negative", "ECCENTRICITY", -0.1),
    ("eccentricity-nan", "ECCENTRICITY", "NaN"),
    ("inclination-181", "INCLINATION", 181.0),
    ("inclination-negative", "INCLINATION", -1.0),
    ("raan-400", "RA_OF_ASC_NODE", 400.0),
    ("arg-perigee-inf", "ARG_OF_PERICENTER", "-inf"),
    ("mean-anomaly-1e30", "MEAN_ANOMALY", 1e30),
    ("bstar-1e30", "BSTAR", 1e30),
    ("ndot-nan", "MEAN_MOTION_DOT", "nan"),
    ("element-set-1e30", "ELEMENT_SET_NO", 10**30),
    ("element-set-10000", "ELEMENT_SET_NO", 10_000),
    ("element-set-negative", "ELEMENT_SET_NO", -1),
    ("element-set-float", "ELEMENT_SET_NO", 1.5),
    ("rev-1e30", "REV_AT_EPOCH", 10**30),
    ("norad-1e30", "NORAD_CAT_ID", 10**30),
    ("norad-340000", "NORAD_CAT_ID", 340_000),
    ("norad-text", "NORAD_CAT_ID", "SWARM"),
    ("ephemeris-type-10", "EPHEMERIS_TYPE", 10),
    ("classification-long", "CLASSIFICATION_TYPE", "UNCLASSIFIED"),
    ("decayed-mean-motion-18.5", "MEAN_MOTION", 18.5),
]

_LINE1, _LINE2 = SWARM_A_TLE.strip().splitlines()[-2:]


def _tle_with(line: int, first_col: int, text: str) -> str:
    """Swarm A's TLE with columns first_col… (1-based) of a line replaced, checksum fixed."""
    original = _LINE1 if line == 1 else _LINE2
    edited = original[: first_col - 1] + text + original[first_col - 1 + len(text) :]
    edited = edited[:68] + str(tle_checksum(edited))
    return f"{edited}\n{_LINE2}" if line == 1 else f"{_LINE1}\n{edited}"


#: (probe name, TLE text, words the answer must contain).
BAD_TLES: list[tuple[str, str, str]] = [
    ("inclination-187", _tle_with(2, 9, "187.3500"), "INCLINATION"),
    ("mean-motion-negative", _tle_with(2, 53, "-5.32769581"), "MEAN_MOTION"),
    ("mean-motion-zero", _tle_with(2, 53, "0.00000000 "), "MEAN_MOTION"),
    ("mean-motion-nan", _tle_with(2, 53, "nan        "), "MEAN_MOTION"),
    ("raan-400", _tle_with(2, 18, "400.0000"), "RA_OF_ASC_NODE"),
    ("decayed", _tle_with(2, 53, "18.50000000"), "SGP4"),
    ("bad-checksum", f"{_LINE1[:68]}{(int(_LINE1[68]) + 1) % 10}\n{_LINE2}", "checksum"),
    ("eccentricity-letters", _tle_with(2, 27, "00a2354"), "eccentricity"),
    ("one-line", _LINE1, "2 lines"),
]


def _json(value: Any) -> bytes:
    return json.dumps(value).encode()


def _no_orbit_stored(server: ServeProcess, sc: str, r: httpx.Response) -> None:
    with server.engine.connect() as conn:
        tle, omm = conn.execute(
            sa.text("SELECT tle, omm FROM spacecraft WHERE id = :s"), {"s": sc}
        ).one()
    assert tle is None and omm in (None, "null"), "a refused orbit was stored"


def _not_created(sc_id: str) -> Callable[[ServeProcess, str, httpx.Response], None]:
    def check(server: ServeProcess, _sc: str, r: httpx.Response) -> None:
        with server.engine.connect() as conn:
            n = conn.execute(
                sa.text("SELECT COUNT(*) FROM spacecraft WHERE id = :s"), {"s": sc_id}
            ).scalar_one()
        assert n == 0, f"spacecraft {sc_id} was created with refused elements"

    return check


def _field_named(key: str) -> Callable[[ServeProcess, str, httpx.Response], None]:
    def check(server: ServeProcess, sc: str, r: httpx.Response) -> None:
        assert key in r.text, r.text

    return check


def _both(*checks: Callable[[ServeProcess, str, httpx.Response], None]) -> Any:
    def check(server: ServeProcess, sc: str, r: httpx.Response) -> None:
        for c in checks:
            c(server, sc, r)

    return check


PROBES: list[Probe] = []
for name, key, value in BAD_OMM_VALUES:
    omm = {**OMM, key: value}
    PROBES.append(
        Probe(
            f"put-omm-{name}",
            "orbit",
            _json({"omm": omm}),
            JSON,
            422,
            says=(key,),
            stored=0,
            method="PUT",
            path="/v1/spacecraft/{sc}/orbit",
            check=_no_orbit_stored,
        )
    )
    new_id = f"orbit-probe-omm-{name}"
    PROBES.append(
        Probe(
            f"post-omm-{name}",
            "orbit",
            _json({"id": new_id, "omm": omm}),
            JSON,
            422,
            says=(key,),
            stored=0,
            path="/v1/spacecraft",
            check=_not_created(new_id),
        )
    )
for name, text, words in BAD_TLES:
    PROBES.append(
        Probe(
            f"put-tle-{name}",
            "orbit",
            _json({"tle": text}),
            JSON,
            422,
            says=(words,),
            stored=0,
            method="PUT",
            path="/v1/spacecraft/{sc}/orbit",
            check=_no_orbit_stored,
        )
    )
    new_id = f"orbit-probe-tle-{name}"
    PROBES.append(
        Probe(
            f"post-tle-{name}",
            "orbit",
            _json({"id": new_id, "tle": text}),
            JSON,
            422,
            says=(words,),
            stored=0,
            path="/v1/spacecraft",
            check=_not_created(new_id),
        )
    )


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServeProcess]:
    with serve_process(tmp_path_factory.mktemp("probes-orbit")) as s:
        yield s


@pytest.mark.parametrize("probe", PROBES, ids=lambda p: p.name)
def test_orbit_probe(server: ServeProcess, probe: Probe) -> None:
    server.run(probe)


def test_the_real_elements_are_accepted(server: ServeProcess) -> None:
    """The unedited set goes through both routes: the probes refuse the edit, not the set."""
    sc = server.new_spacecraft()
    with server.client() as http:
        assert http.put(f"/v1/spacecraft/{sc}/orbit", json={"omm": OMM}).is_success
        assert http.put(f"/v1/spacecraft/{sc}/orbit", json={"tle": SWARM_A_TLE}).is_success
        r = http.post("/v1/spacecraft", json={"id": "orbit-probe-good", "omm": OMM})
        assert r.status_code == 201, r.text
