"""Swarm magnetic data → the contract's telemetry table (attitude frame GCRS, UTC).

Inputs, by extension:

* ``.cdf`` — an ESA ``SW_OPER_MAGx_LR_1B`` product or a VirES export in CDF (read with
  ``cdflib``): ``Timestamp`` (CDF_EPOCH, UTC), ``Latitude``/``Longitude`` (geocentric, deg),
  ``Radius`` (m), and either ``B_VFM`` (nT, instrument frame) with ``q_NEC_CRF`` (scalar last)
  or ``B_NEC`` (nT, North–East–Centre);
* ``.csv`` — a VirES export in CSV (ISO times with ``Z``, vectors written ``{a;b;c}``);
* ``.nc``/``.nc4`` — a VirES/SwarmPAL NetCDF-4 file (group ``SW_OPER_MAGx_LR_1B``, ``Timestamp`` in
  seconds since the epoch its ``units`` attribute names), read with ``h5py``.

**Frames.** With ``B_VFM`` the table's body frame is the instrument's: the rotation from NEC into
it is ``Rotation.from_quat(q_NEC_CRF)`` — checked on the VirES GRACE-A rows, where
``Rotation.from_quat(q_NEC_CRF).inv().apply(B_FGM) == B_NEC_raw`` to 1e-11 nT — and the table's
quaternion is the rotation GCRS → ITRS → NEC → instrument, written in the contract's convention.
The fixed VFM→CRF rotation (the product's Euler angles live in a separate auxiliary file) is not in
the file; it is a constant rotation that the calibration matrix ``M`` absorbs. With ``B_NEC`` only
(already calibrated data, no attitude in the file) the body frame *is* the local NEC frame at each
sample and the quaternion is GCRS → ITRS → NEC: a calibration of such a table should come out close
to the identity, which makes it a check of the pipeline on real field values.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.ingest.errors import IngestError
from orbitcal.ingest.summary import IngestSummary
from orbitcal.telemetry import Telemetry

__all__ = ["SwarmOptions", "nec_to_gcrs_quaternions", "read_swarm"]

_FIELDS = ("B_VFM", "B_NEC")


@dataclass(frozen=True)
class SwarmOptions:
    """How a Swarm file is read.

    Attributes
    ----------
    field : str or None
        ``"B_VFM"`` (instrument frame, needs ``q_NEC_CRF``) or ``"B_NEC"``; None takes ``B_VFM``
        when the file has it with ``q_NEC_CRF``, else ``B_NEC``.
    """

    field: str | None = None


@dataclass
class _Columns:
    t_utc_s: FloatArray
    lat_deg: FloatArray
    lon_deg: FloatArray
    radius_m: FloatArray
    vectors: dict[str, FloatArray]
    q_nec_crf_xyzw: FloatArray | None
    spacecraft: str
    flags: dict[str, npt.NDArray[np.int64]]


def nec_to_gcrs_quaternions(t_utc_s: FloatArray, r_itrs_km: FloatArray) -> FloatArray:
    """Quaternions (contract convention) of a body whose axes are the local NEC frame, in GCRS.

    ``v_body = R(q)ᵀ v_gcrs`` gives the NEC components: ``R(q)ᵀ = N(r) · G(t)`` with ``N`` the
    ITRS → NEC basis and ``G`` the GCRS → ITRS matrix. Shape (N, 4), scalar first.
    """
    from orbitcal import frames
    from orbitcal.attitude import matrix_to_quat_wxyz

    m = np.einsum(
        "nij,njk->nik", frames.nec_basis_itrs(r_itrs_km), frames.gcrs_to_itrs_matrix(t_utc_s)
    )
    return np.asarray(matrix_to_quat_wxyz(m), dtype=np.float64)


def _crf_quaternions(
    t_utc_s: FloatArray, r_itrs_km: FloatArray, q_nec_crf_xyzw: FloatArray
) -> FloatArray:
    from scipy.spatial.transform import Rotation

    from orbitcal import frames
    from orbitcal.attitude import matrix_to_quat_wxyz

    nec_to_inst = Rotation.from_quat(q_nec_crf_xyzw).as_matrix()
    m = np.einsum(
        "nij,njk,nkl->nil",
        nec_to_inst,
        frames.nec_basis_itrs(r_itrs_km),
        frames.gcrs_to_itrs_matrix(t_utc_s),
    )
    return np.asarray(matrix_to_quat_wxyz(m), dtype=np.float64)


def read_swarm(path: str | Path, options: SwarmOptions) -> tuple[Telemetry, IngestSummary]:
    """Read one Swarm file (``.cdf``, ``.csv``, ``.nc``/``.nc4``); see the module docstring."""
    p = Path(path)
    if not p.is_file():
        raise IngestError(p, "no such file")
    suffix = p.suffix.lower()
    if suffix == ".cdf":
        cols = _read_cdf(p)
        kind = "CDF"
    elif suffix == ".csv":
        cols = _read_csv(p)
        kind = "VirES CSV"
    elif suffix in (".nc", ".nc4", ".h5"):
        cols = _read_netcdf(p)
        kind = "NetCDF-4"
    else:
        raise IngestError(p, f"unknown extension {suffix!r}: expected .cdf, .csv, .nc or .nc4")
    summary = IngestSummary(mission="Swarm", spacecraft=f"Swarm {cols.spacecraft}".strip())
    summary.files = [str(p)]
    return _table(p, cols, options, summary, kind), summary


def _choose_field(p: Path, cols: _Columns, options: SwarmOptions) -> str:
    want = options.field
    if want is not None and want not in _FIELDS:
        raise IngestError(p, f"field must be one of {', '.join(_FIELDS)}", field="field")
    if want is None:
        want = "B_VFM" if "B_VFM" in cols.vectors and cols.q_nec_crf_xyzw is not None else "B_NEC"
    if want not in cols.vectors:
        raise IngestError(p, f"the file has no {want} variable", field=want)
    if want == "B_VFM" and cols.q_nec_crf_xyzw is None:
        raise IngestError(
            p, "B_VFM is in the instrument frame: q_NEC_CRF is needed", field="q_NEC_CRF"
        )
    return want


def _table(
    p: Path, cols: _Columns, options: SwarmOptions, summary: IngestSummary, kind: str
) -> Telemetry:
    from orbitcal import frames

    name = _choose_field(p, cols, options)
    b = cols.vectors[name]
    summary.records[name] += int(b.shape[0])
    r_km = cols.radius_m / 1000.0
    r_itrs = frames.spherical_to_itrs(r_km, 90.0 - cols.lat_deg, cols.lon_deg)
    ok = (
        np.isfinite(cols.t_utc_s)
        & np.all(np.isfinite(b), axis=1)
        & np.all(np.isfinite(r_itrs), axis=1)
    )
    ok &= np.all(np.abs(b) < 1e6, axis=1)  # Swarm fill values
    q_src = cols.q_nec_crf_xyzw
    if name == "B_VFM" and q_src is not None:
        ok &= np.all(np.isfinite(q_src), axis=1) & (
            np.abs(np.linalg.norm(q_src, axis=1) - 1) < 1e-3
        )
    if (~ok).any():
        summary.dropped[f"non-finite or fill value in {name}, position or quaternion"] += int(
            (~ok).sum()
        )
    order = np.argsort(cols.t_utc_s[ok], kind="stable")
    idx = np.flatnonzero(ok)[order]
    t = cols.t_utc_s[idx]
    dup = np.concatenate([[False], np.diff(t) <= 0])
    if dup.any():
        summary.dropped["time equal to the previous sample's"] += int(dup.sum())
        idx, t = idx[~dup], t[~dup]
    if not idx.size:
        raise IngestError(p, "no valid samples in the file", field=name)
    r = r_itrs[idx]
    if name == "B_VFM":
        assert q_src is not None
        q = _crf_quaternions(t, r, q_src[idx])
        summary.note(
            "body frame: the VFM instrument frame (q_NEC_CRF); the VFM→CRF Euler rotation "
            "is left to the calibration"
        )
    else:
        q = nec_to_gcrs_quaternions(t, r)
        summary.note("body frame: the local NEC frame (B_NEC carries no instrument attitude)")
    for flag, values in cols.flags.items():
        summary.count_flags(
            flag, {k: int(np.count_nonzero(values[idx] & (1 << k))) for k in range(16)}
        )
    summary.note(f"read as {kind}")
    from orbitcal.timescales import utc_s_to_iso

    tel = Telemetry(t_utc_s=t, b_raw_nt=np.ascontiguousarray(b[idx]), q_wxyz=q, r_itrs_km=r)
    summary.rows = len(tel)
    first, last = utc_s_to_iso([t[0], t[-1]])
    summary.first_utc, summary.last_utc = first, last
    summary.columns = (
        list(tel.to_table_frame().columns)
        if len(tel) < 2
        else ["time", "b_x", "b_y", "b_z", "q_w", "q_x", "q_y", "q_z", "r_x", "r_y", "r_z"]
    )
    return tel


def _need(p: Path, have: dict[str, Any], name: str) -> Any:
    if name not in have:
        raise IngestError(
            p, f"the file has no {name} variable ({', '.join(sorted(have))})", field=name
        )
    return have[name]


def _vec3(p: Path, values: Any, name: str) -> FloatArray:
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise IngestError(p, f"{name} has shape {a.shape}, expected (N, 3)", field=name)
    return a


def _columns(p: Path, data: dict[str, Any], t_utc_s: FloatArray, spacecraft: str) -> _Columns:
    n = t_utc_s.shape[0]
    vectors = {k: _vec3(p, data[k], k) for k in _FIELDS if k in data}
    if not vectors:
        raise IngestError(p, "the file has neither B_VFM nor B_NEC", field="B_NEC")
    q = None
    if "q_NEC_CRF" in data:
        q = np.asarray(data["q_NEC_CRF"], dtype=np.float64)
        if q.shape != (n, 4):
            raise IngestError(
                p, f"q_NEC_CRF has shape {q.shape}, expected ({n}, 4)", field="q_NEC_CRF"
            )
    scalars = {}
    for k in ("Latitude", "Longitude", "Radius"):
        a = np.asarray(_need(p, data, k), dtype=np.float64).reshape(-1)
        if a.shape[0] != n:
            raise IngestError(p, f"{k} has {a.shape[0]} values for {n} times", field=k)
        scalars[k] = a
    for k, v in vectors.items():
        if v.shape[0] != n:
            raise IngestError(p, f"{k} has {v.shape[0]} rows for {n} times", field=k)
    flags: dict[str, npt.NDArray[np.int64]] = {
        k: np.asarray(data[k]).astype(np.int64).reshape(-1)
        for k in ("Flags_B", "Flags_q", "Flags_Platform")
        if k in data and np.asarray(data[k]).shape[:1] == (n,)
    }
    return _Columns(
        t_utc_s,
        scalars["Latitude"],
        scalars["Longitude"],
        scalars["Radius"],
        vectors,
        q,
        spacecraft,
        flags,
    )


#: What the variables of one CDF may decode to [bytes]: a day of 50 Hz Swarm MAGx_HR is ~0.5 GB.
#: CDF variables may be compressed (GZIP, RLE), so a small file can declare far more.
MAX_CDF_DECODED_BYTES = 2 * 2**30


def _check_cdf_expansion(p: Path, cdf: Any, names: list[str]) -> None:
    """Refuse a CDF whose variables, as declared, decode beyond ``MAX_CDF_DECODED_BYTES``."""
    total = 0
    for n in names:
        info = cdf.varinq(n)
        records = max(int(info.Last_Rec) + 1, 0)
        per_record = int(info.Num_Elements) * 16  # 16 bytes: the widest CDF type (EPOCH16)
        for size in info.Dim_Sizes or []:
            per_record *= max(int(size), 1)
        total += records * per_record
        if total > MAX_CDF_DECODED_BYTES:
            raise IngestError(
                p,
                f"its variables declare {total:,} bytes or more once decoded (variable {n}: "
                f"{records:,} records), over the limit MAX_CDF_DECODED_BYTES = "
                f"{MAX_CDF_DECODED_BYTES:,}",
                field=n,
            )


def _read_cdf(p: Path) -> _Columns:
    import cdflib
    from cdflib.epochs import CDFepoch

    try:
        cdf = cdflib.CDF(str(p))
        names = list(cdf.cdf_info().zVariables) + list(cdf.cdf_info().rVariables)
        _check_cdf_expansion(p, cdf, names)
        data = {n: cdf.varget(n) for n in names}
    except (OSError, ValueError, KeyError, IndexError, TypeError) as exc:
        raise IngestError(p, f"not a readable CDF file ({exc})") from exc
    except Exception as exc:  # cdflib raises bare Exceptions on damaged files
        raise IngestError(p, f"not a readable CDF file ({type(exc).__name__}: {exc})") from exc
    epochs = np.asarray(_need(p, data, "Timestamp")).reshape(-1)
    if epochs.dtype.kind not in "fiu" and epochs.dtype.kind != "c":
        raise IngestError(p, "Timestamp is not a CDF epoch", field="Timestamp")
    t = np.asarray(CDFepoch.unixtime(epochs), dtype=np.float64).reshape(-1)
    sc = data.get("Spacecraft")
    spacecraft = str(np.asarray(sc).reshape(-1)[0]) if sc is not None and np.size(sc) else ""
    return _columns(p, data, t, spacecraft)


def _read_csv(p: Path) -> _Columns:
    from orbitcal.timescales import parse_time_values

    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise IngestError(p, f"not UTF-8 text ({exc.reason})") from exc
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise IngestError(p, "empty file")
    head = rows[0]
    body = rows[1:]
    data: dict[str, Any] = {}
    for j, name in enumerate(head):
        values: list[Any] = []
        for i, row in enumerate(body):
            if len(row) != len(head):
                raise IngestError(
                    p,
                    f"{len(row)} fields where the header has {len(head)}: a truncated file?",
                    line=i + 2,
                )
            values.append(row[j])
        if name in ("Timestamp", "Spacecraft"):
            data[name] = values
            continue
        if values and values[0].startswith("{"):
            data[name] = _csv_vectors(p, name, values)
        else:
            try:
                data[name] = np.array([float(v) for v in values])
            except ValueError:
                bad = next(i for i, v in enumerate(values) if not _is_float(v))
                raise IngestError(
                    p, f"{values[bad]!r} is not a number", line=bad + 2, field=name
                ) from None
    stamps = _need(p, data, "Timestamp")
    t, errors = parse_time_values(np.asarray(stamps, dtype=object))
    if errors:
        bad_row, reason = errors[0]
        raise IngestError(p, f"unreadable Timestamp: {reason}", line=bad_row + 2, field="Timestamp")
    sc = data.get("Spacecraft") or [""]
    return _columns(p, data, np.asarray(t, dtype=np.float64), str(sc[0]))


def _is_float(v: str) -> bool:
    try:
        float(v)
    except ValueError:
        return False
    return True


def _csv_vectors(p: Path, name: str, values: list[str]) -> FloatArray:
    out = np.empty((len(values), 3))
    for i, v in enumerate(values):
        parts = v.strip().lstrip("{").rstrip("}").split(";")
        try:
            if len(parts) != 3:
                raise ValueError
            out[i] = [float(x) for x in parts]
        except ValueError:
            raise IngestError(
                p, f"{v!r} is not a vector {{x;y;z}}", line=i + 2, field=name
            ) from None
    return out


def _read_netcdf(p: Path) -> _Columns:
    import h5py

    try:
        fh = h5py.File(p, "r")
    except OSError as exc:
        raise IngestError(p, f"not a readable NetCDF-4/HDF5 file ({exc})") from exc
    with fh:
        groups = [k for k in fh if k.startswith("SW_") and "MAG" in k]
        if not groups:
            raise IngestError(
                p, "no SW_…MAG… group (a VirES/SwarmPAL Swarm magnetic file)", field="group"
            )
        g = fh[groups[0]]
        data = {k: g[k][()] for k in g if isinstance(g[k], h5py.Dataset)}
        ts = _need(p, data, "Timestamp")
        units = g["Timestamp"].attrs.get("units", b"")
        units = units.decode() if isinstance(units, bytes) else str(units)
    prefix = "seconds since "
    if not units.startswith(prefix):
        raise IngestError(
            p, f"Timestamp units {units!r}: expected 'seconds since …'", field="Timestamp"
        )
    epoch = np.datetime64(units[len(prefix) :].strip().replace(" ", "T"), "us")
    t = np.asarray(ts, dtype=np.float64) + epoch.astype("datetime64[us]").astype(np.int64) / 1e6
    sc = data.get("Spacecraft")
    spacecraft = ""
    if sc is not None and np.size(sc):
        first = np.asarray(sc).reshape(-1)[0]
        spacecraft = first.decode() if isinstance(first, bytes) else str(first)
    return _columns(p, data, t, spacecraft)
