"""GRACE-FO Level-1B (RL04 ASCII) → the contract's telemetry table.

Products (GRACE-FO Level-1 Data Product User Handbook, JPL D-56935, and the files' own headers):

=======  ========================================================  ======================
product  what the table takes from it                              cadence
=======  ========================================================  ======================
MAG1B    ``MfvX/Y/Z_RAW`` [µT, SRF] → ``b_x, b_y, b_z`` [nT];      2 Hz
         six magnetorquer currents [mA] → ``hk_torque…_ma``
GNV1B    ``xpos…`` [m, ITRF, ``coord_ref`` E] → ``r_*`` [km]      1 Hz
SCA1B    ``quatangle, quati/j/kcoeff`` → ``q_w, q_x, q_y, q_z``    1 Hz
IHK1B    temperatures (``sensortype`` T) → ``hk_ihk1b_t<id>_degc``  60 s (optional)
=======  ========================================================  ======================

**Time.** Every product counts seconds past 2000-01-01 12:00:00 **GPS** (MAG1B and IHK1B add a
fractional part). They are converted to UTC through the leap-second table
(:func:`orbitcal.timescales.gps_to_utc`; GPS − UTC = 18 s in 2023). MAG1B's header declares its
``time_frac`` in nanoseconds, but its values are microseconds (``83329`` for ``.083329`` s, the
header's own ``start_time_epoch_secs``); the unit is therefore checked against
``start_time_epoch_secs`` and the one that agrees is used (the summary says so).

**Attitude.** SCA1B quaternions (scalar first) rotate the inertial frame into the satellite
reference frame: ``v_SRF = R(q)ᵀ v_inertial`` with ``R(q)`` the active rotation matrix of
``q``. That is the contract's convention (``v_body = Rotation.from_quat([x, y, z, w]).inv()
.apply(v_frame)``, i.e. ``R(q)ᵀ v_frame``), so the quaternion is carried over component for
component, scalar first; the test on the real files checks the sign (the other convention
leaves thousands of nT). The handbook names the inertial frame ICRF/J2000; the table declares
**GCRS**, whose axes are the ICRS axes. Between ICRS and the J2000 mean equator and equinox the
frame bias is ≈ 0.02″ (1e-7 rad): ≤ 0.005 nT on a 50,000 nT field, far below the magnetometer's
resolution, so no bias rotation is applied.

**Join.** MAG1B samples are kept only inside the spans of GNV1B and SCA1B (and of every
temperature channel taken): positions by cubic Hermite interpolation with GNV1B's velocities,
quaternions by slerp, temperatures linearly, all from the two bracketing product samples;
samples before or after a product's span, or in a gap longer than the allowed step
(:class:`GraceFOOptions`), are dropped and counted by reason. Neighbouring days' files, when
given, bridge midnight.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.ingest.errors import IngestError
from orbitcal.ingest.join import Bracket, bracket, hermite_positions, linear, slerp
from orbitcal.ingest.l1b_ascii import L1BFile, flag_bits
from orbitcal.ingest.summary import Gap, IngestSummary
from orbitcal.telemetry import Telemetry
from orbitcal.timescales import gps_to_utc, utc_s_to_iso

__all__ = [
    "GPS_EPOCH_J2000_NOON_S",
    "MAG1B_CURRENTS",
    "GraceFOOptions",
    "GraceFOSource",
    "gps_j2000_to_utc_s",
]

#: 2000-01-01T12:00:00 as a POSIX-style reading [s]: the products' time origin, read in GPS.
GPS_EPOCH_J2000_NOON_S = 946_728_000.0

#: MAG1B magnetorquer currents [mA] → table column names.
MAG1B_CURRENTS: dict[str, str] = {
    "torque1A": "hk_torque1a_ma",
    "torque2A": "hk_torque2a_ma",
    "torque3A": "hk_torque3a_ma",
    "torque1B": "hk_torque1b_ma",
    "torque2B": "hk_torque2b_ma",
    "torque3B": "hk_torque3b_ma",
}

_REQUIRED = ("MAG1B", "GNV1B", "SCA1B")
_NEIGHBOUR_RECORDS = 3
_MAG_STEP_S = 0.5
_QUAT_NORM_TOL = 1e-3
_MAG_FIELD = ("MfvX_RAW", "MfvY_RAW", "MfvZ_RAW")
_REPEAT_KEY = "field equal to the previous record's (kept)"


@dataclass(frozen=True)
class GraceFOOptions:
    """How GRACE-FO files are joined.

    Attributes
    ----------
    chunk_rows : int
        MAG1B records per chunk (memory is bounded by this, not by the number of days).
    max_gap_gnv_s, max_gap_sca_s : float
        Longest interval between two GNV1B (SCA1B) samples that is interpolated across [s];
        MAG1B samples in a longer one are dropped. Nominal steps are 1 s.
    max_gap_ihk_s : float
        The same for each IHK1B temperature channel (nominal step 60 s).
    temperatures : bool
        Take IHK1B temperatures (when IHK1B files are given) as ``hk_ihk1b_t<id>_degc`` columns.
    min_temperature_cover : float
        A temperature channel is taken when its span covers at least this fraction of the first
        day's GNV1B ∩ SCA1B span (a short file's channels that start after the magnetometer
        data ends are left out and named in the summary).
    temperature_sensor : str or None
        IHK1B sensor id (e.g. ``"21"``) whose temperature fills the table's ``temperature``
        column (the sensor's own, for the ``temperature`` effect); None leaves it out.
    time_frac_unit : str or None
        ``"microseconds"`` or ``"nanoseconds"`` forces the unit of MAG1B's ``time_frac``; None
        (the default) takes the unit that agrees with the header's ``start_time_epoch_secs``.
    every_s : float or None
        Thin MAG1B to its first record in each ``every_s``-second bin of GPS time (e.g. 10 for
        0.1 Hz, a month in a table a calibration can hold); None keeps every record (2 Hz).
    """

    chunk_rows: int = 50_000
    max_gap_gnv_s: float = 10.0
    max_gap_sca_s: float = 5.0
    max_gap_ihk_s: float = 150.0
    temperatures: bool = True
    min_temperature_cover: float = 0.95
    temperature_sensor: str | None = None
    time_frac_unit: str | None = None
    every_s: float | None = None


def gps_j2000_to_utc_s(t_gps_j2000_s: npt.ArrayLike) -> FloatArray:
    """Seconds past 2000-01-01 12:00:00 GPS → POSIX seconds of UTC (leap-second table)."""
    return gps_to_utc(np.asarray(t_gps_j2000_s, dtype=np.float64) + GPS_EPOCH_J2000_NOON_S)


@dataclass
class _Aux:
    """One product's samples around one day (neighbours' edge records included)."""

    t_s: FloatArray
    values: dict[str, FloatArray]


@dataclass
class _MagState:
    """What MAG1B's checks carry from one chunk (and one day) to the next."""

    previous: float = -np.inf
    last_bin: float = -np.inf
    last_b: FloatArray | None = None
    n_in_file: int = 0


@dataclass
class _Day:
    date: str
    files: dict[str, L1BFile]


def _collect(paths: Sequence[str | Path]) -> list[L1BFile]:
    files: list[L1BFile] = []
    for p in paths:
        path = Path(p)
        if path.is_dir():
            found = sorted(
                q for q in path.iterdir() if L1BFile.parse_name(q) is not None and q.is_file()
            )
            if not found:
                raise IngestError(path, "no GRACE-FO Level-1B files (PROD_YYYY-MM-DD_S_04.txt)")
            files.extend(L1BFile.open(q) for q in found)
        else:
            files.append(L1BFile.open(path))
    return files


def _days(files: list[L1BFile], where: str) -> tuple[list[_Day], dict[str, _Day], str]:
    sats = sorted({f.satellite for f in files})
    if len(sats) != 1:
        raise IngestError(where, f"files of several satellites ({', '.join(sats)}): ingest one")
    by_date: dict[str, _Day] = {}
    for f in files:
        day = by_date.setdefault(f.date, _Day(f.date, {}))
        if f.product in day.files:
            raise IngestError(f.path, f"a second {f.product} file for {f.date}")
        day.files[f.product] = f
    wanted = [d for d in sorted(by_date) if "MAG1B" in by_date[d].files]
    if not wanted:
        raise IngestError(where, "no MAG1B file among the inputs (the magnetometer product)")
    for d in wanted:
        missing = [p for p in _REQUIRED if p not in by_date[d].files]
        if missing:
            raise IngestError(
                by_date[d].files["MAG1B"].path,
                f"no {' and no '.join(missing)} file for {d} {sats[0]} beside MAG1B "
                "(MAG1B, GNV1B and SCA1B of the same day are needed)",
                field=missing[0],
            )
    return [by_date[d] for d in wanted], by_date, sats[0]


def _check_ids(f: L1BFile, ids: npt.NDArray[Any], first_line: int) -> None:
    bad = np.flatnonzero(ids != f.satellite)
    if bad.size:
        raise IngestError(
            f.path,
            f"GRACEFO_id {ids[bad[0]]!r} in a file named for satellite {f.satellite}",
            line=first_line + int(bad[0]),
            field="GRACEFO_id",
        )


def _increasing(f: L1BFile, t: FloatArray, first_line: int, previous: float) -> None:
    d = np.diff(np.concatenate([[previous], t]))
    bad = np.flatnonzero(~(d > 0))
    if bad.size:
        raise IngestError(
            f.path,
            f"time {t[bad[0]]!r} is not after the previous record's",
            line=first_line + int(bad[0]),
            field=f.variables[0].name,
        )


def _count_bits(summary: IngestSummary, product: str, flags: npt.NDArray[np.int64]) -> None:
    summary.count_flags(product, {k: int(np.count_nonzero(flags & (1 << k))) for k in range(8)})


def _report_gaps(summary: IngestSummary, product: str, t_s: FloatArray, max_step_s: float) -> None:
    if t_s.size < 2:
        return
    d = np.diff(t_s)
    for i in np.flatnonzero(d > max_step_s):
        start, end = utc_s_to_iso(gps_j2000_to_utc_s([t_s[i], t_s[i + 1]]))
        summary.add_gap(Gap(product, start[:23] + "Z", end[:23] + "Z", float(d[i])))


def _read_gnv(f: L1BFile, summary: IngestSummary | None, limit: int | None = None) -> _Aux:
    names = ["gps_time", "xpos", "ypos", "zpos", "xvel", "yvel", "zvel", "qualflg"]
    for n in ("xpos", "ypos", "zpos"):
        f.variable(n, units=("m",))
    for n in ("xvel", "yvel", "zvel"):
        f.variable(n, units=("m/s",))
    f.variable("gps_time", units=("second", "seconds"))
    parts: list[dict[str, npt.NDArray[Any]]] = []
    previous = -np.inf
    rows = limit if limit is not None else 200_000
    for chunk in f.chunks(names, text=["GRACEFO_id", "coord_ref"], chunk_rows=rows):
        c = chunk.columns
        _check_ids(f, c["GRACEFO_id"], chunk.first_line)
        not_e = np.flatnonzero(c["coord_ref"] != "E")
        if not_e.size:
            raise IngestError(
                f.path,
                f"coord_ref {c['coord_ref'][not_e[0]]!r}: positions are not Earth-fixed (E)",
                line=chunk.first_line + int(not_e[0]),
                field="coord_ref",
            )
        t = c["gps_time"].astype(np.float64)
        _increasing(f, t, chunk.first_line, previous)
        previous = float(t[-1])
        parts.append(c)
        if limit is not None:
            break
    cat = {n: np.concatenate([p[n] for p in parts]) if parts else np.empty(0) for n in names}
    t = cat["gps_time"].astype(np.float64)
    if summary is not None:
        summary.records["GNV1B"] += int(t.size)
        _count_bits(summary, "GNV1B", flag_bits(cat["qualflg"]))
    r = np.column_stack([cat[n] for n in ("xpos", "ypos", "zpos")]).astype(np.float64) / 1000.0
    v = np.column_stack([cat[n] for n in ("xvel", "yvel", "zvel")]).astype(np.float64) / 1000.0
    return _Aux(t, {"r_km": r, "v_km_s": v})


def _read_sca(f: L1BFile, summary: IngestSummary | None, limit: int | None = None) -> _Aux:
    names = ["gps_time", "quatangle", "quaticoeff", "quatjcoeff", "quatkcoeff", "qualflg"]
    f.variable("gps_time", units=("second", "seconds"))
    parts: list[dict[str, npt.NDArray[Any]]] = []
    previous = -np.inf
    rows = limit if limit is not None else 200_000
    for chunk in f.chunks(names, text=["GRACEFO_id"], chunk_rows=rows):
        c = chunk.columns
        _check_ids(f, c["GRACEFO_id"], chunk.first_line)
        t = c["gps_time"].astype(np.float64)
        _increasing(f, t, chunk.first_line, previous)
        previous = float(t[-1])
        parts.append(c)
        if limit is not None:
            break
    cat = {n: np.concatenate([p[n] for p in parts]) if parts else np.empty(0) for n in names}
    t = cat["gps_time"].astype(np.float64)
    q = np.column_stack(
        [cat[n] for n in ("quatangle", "quaticoeff", "quatjcoeff", "quatkcoeff")]
    ).astype(np.float64)
    unit = np.abs(np.linalg.norm(q, axis=1) - 1.0) <= _QUAT_NORM_TOL
    if summary is not None:
        summary.records["SCA1B"] += int(t.size)
        _count_bits(summary, "SCA1B", flag_bits(cat["qualflg"]))
        if not unit.all():
            summary.note(
                f"{f.path.name}: {int((~unit).sum())} quaternions not of unit norm, left out"
            )
    return _Aux(t[unit], {"q_wxyz": q[unit]})


def _read_ihk_temperatures(f: L1BFile, summary: IngestSummary) -> dict[str, _Aux]:
    names = ["time_intg", "time_frac", "sensorvalue"]
    f.variable("time_frac", units=("microseconds",))
    by_sensor: dict[str, list[tuple[FloatArray, FloatArray]]] = {}
    for chunk in f.chunks(names, text=["GRACEFO_id", "sensortype", "sensorname"]):
        c = chunk.columns
        _check_ids(f, c["GRACEFO_id"], chunk.first_line)
        summary.records["IHK1B"] += len(chunk)
        t = c["time_intg"].astype(np.float64) + c["time_frac"].astype(np.float64) * 1e-6
        is_t = c["sensortype"] == "T"
        for sensor in np.unique(c["sensorname"][is_t]):
            m = is_t & (c["sensorname"] == sensor)
            by_sensor.setdefault(str(sensor), []).append(
                (t[m], c["sensorvalue"][m].astype(np.float64))
            )
    out: dict[str, _Aux] = {}
    for sensor, parts in by_sensor.items():
        t = np.concatenate([p[0] for p in parts])
        y = np.concatenate([p[1] for p in parts])
        order = np.argsort(t, kind="stable")
        t, y = t[order], y[order]
        keep = np.concatenate([[True], np.diff(t) > 0])
        out[sensor] = _Aux(t[keep], {"temperature_c": y[keep]})
    return out


def _with_neighbours(aux: _Aux, before: _Aux | None, after: _Aux | None) -> _Aux:
    pieces = [p for p in (before, aux, after) if p is not None]
    t = np.concatenate([p.t_s for p in pieces])
    vals = {k: np.concatenate([p.values[k] for p in pieces]) for k in aux.values}
    order = np.argsort(t, kind="stable")
    t, vals = t[order], {k: v[order] for k, v in vals.items()}
    keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, bool)
    return _Aux(t[keep], {k: v[keep] for k, v in vals.items()})


def _tail(aux: _Aux, n: int) -> _Aux:
    return _Aux(aux.t_s[-n:], {k: v[-n:] for k, v in aux.values.items()})


def _frac_scale_s(
    f: L1BFile, intg: float, frac: float, summary: IngestSummary, forced: str | None
) -> float:
    """Seconds per unit of MAG1B's ``time_frac``, checked against ``start_time_epoch_secs``."""
    declared = (f.units_by_name.get("time_frac") or "").lower()
    scales = {"nanoseconds": 1e-9, "microseconds": 1e-6}
    if forced is not None:
        if forced not in scales:
            raise IngestError(
                f.path,
                f"time_frac_unit {forced!r}: use nanoseconds or microseconds",
                field="time_frac",
            )
        return scales[forced]
    if declared not in scales:
        raise IngestError(
            f.path,
            f"time_frac in {declared!r}, expected nanoseconds or microseconds",
            field="time_frac",
        )
    start = f.attributes.get("start_time_epoch_secs")
    if not isinstance(start, int | float):
        return scales[declared]
    fits = {u: abs(intg + frac * s - float(start)) < 2e-6 for u, s in scales.items()}
    if fits[declared]:
        return scales[declared]
    other = next(u for u in scales if u != declared)
    if fits[other]:
        summary.note(
            f"MAG1B time_frac is declared in {declared} but holds {other} "
            f"(start_time_epoch_secs {start}): read as {other}"
        )
        return scales[other]
    raise IngestError(
        f.path,
        f"the first record's time ({intg:.0f} s + {frac:.0f}) matches the header's "
        f"start_time_epoch_secs {start} in neither nanoseconds nor microseconds",
        line=f.header_lines + 1,
        field="time_frac",
    )


@dataclass
class GraceFOSource:
    """The table of a set of GRACE-FO Level-1B files, produced chunk by chunk.

    Build it with :meth:`open`; iterate :meth:`chunks` once; :attr:`summary` is complete when
    the iteration ends.
    """

    days: list[_Day]
    all_days: dict[str, _Day]
    options: GraceFOOptions
    summary: IngestSummary
    temperature_sensors: list[str] = field(default_factory=list)
    _frac_s: float | None = None

    @classmethod
    def open(
        cls, paths: Sequence[str | Path], options: GraceFOOptions | None = None
    ) -> GraceFOSource:
        """Read the headers of ``paths`` (files or directories) and check the set is complete."""
        if not paths:
            raise IngestError("-", "no input files")
        opts = options or GraceFOOptions()
        files = _collect(paths)
        days, all_days, sat = _days(files, str(paths[0]))
        summary = IngestSummary(mission="GRACE-FO", spacecraft=f"GRACE {sat}")
        summary.files = [str(f.path) for d in days for f in d.files.values()]
        src = cls(days, all_days, opts, summary)
        src.summary.columns = src.columns()
        return src

    def columns(self) -> list[str]:
        base = ["time", "b_x", "b_y", "b_z", "q_w", "q_x", "q_y", "q_z", "r_x", "r_y", "r_z"]
        if self.options.temperature_sensor is not None:
            base.append("temperature")
        hk = sorted([*MAG1B_CURRENTS.values(), *(_t_name(s) for s in self.temperature_sensors)])
        return base + hk

    def _neighbour(self, date: str, product: str, *, last: bool) -> _Aux | None:
        day = self.all_days.get(date)
        f = None if day is None else day.files.get(product)
        if f is None:
            return None
        reader = _read_gnv if product == "GNV1B" else _read_sca
        if last:
            return _tail(reader(f, None), _NEIGHBOUR_RECORDS)
        return reader(f, None, limit=_NEIGHBOUR_RECORDS)

    def chunks(self) -> Iterator[Telemetry]:
        """The table, one MAG1B chunk at a time (rows in time order, UTC)."""
        prev_tail: dict[str, _Aux] = {}
        prev_tail_date: str | None = None
        last_b: FloatArray | None = None
        for k, day in enumerate(self.days):
            prev_date = _shift_date(day.date, -1)
            next_date = _shift_date(day.date, +1)
            gnv = _read_gnv(day.files["GNV1B"], self.summary)
            sca = _read_sca(day.files["SCA1B"], self.summary)
            _report_gaps(self.summary, "GNV1B", gnv.t_s, self.options.max_gap_gnv_s)
            _report_gaps(self.summary, "SCA1B", sca.t_s, self.options.max_gap_sca_s)
            before = {
                p: prev_tail[p]
                if prev_tail_date == prev_date
                else self._neighbour(prev_date, p, last=True)
                for p in ("GNV1B", "SCA1B")
            }
            after = {p: self._neighbour(next_date, p, last=False) for p in ("GNV1B", "SCA1B")}
            prev_tail = {
                "GNV1B": _tail(gnv, _NEIGHBOUR_RECORDS),
                "SCA1B": _tail(sca, _NEIGHBOUR_RECORDS),
            }
            prev_tail_date = day.date
            gnv = _with_neighbours(gnv, before["GNV1B"], after["GNV1B"])
            sca = _with_neighbours(sca, before["SCA1B"], after["SCA1B"])
            temps = self._temperatures(day, gnv, sca, first=(k == 0))
            for tel in self._mag_chunks(day.files["MAG1B"], gnv, sca, temps, last_b):
                if len(tel):
                    last_b = tel.b_raw_nt[-1]
                    yield tel

    def _temperatures(self, day: _Day, gnv: _Aux, sca: _Aux, *, first: bool) -> dict[str, _Aux]:
        ihk = day.files.get("IHK1B")
        if ihk is None or not (self.options.temperatures or self.options.temperature_sensor):
            if first and self.options.temperature_sensor is not None:
                raise IngestError(
                    day.files["MAG1B"].path,
                    f"temperature sensor {self.options.temperature_sensor} asked for but no "
                    f"IHK1B file for {day.date}",
                    field="IHK1B",
                )
            return {}
        channels = _read_ihk_temperatures(ihk, self.summary)
        if first:
            lo = max(gnv.t_s[0], sca.t_s[0]) if gnv.t_s.size and sca.t_s.size else 0.0
            hi = min(gnv.t_s[-1], sca.t_s[-1]) if gnv.t_s.size and sca.t_s.size else 0.0
            span = max(hi - lo, 1e-9)
            chosen: list[str] = []
            left: list[str] = []
            for s, aux in sorted(channels.items()):
                cover = (
                    (min(hi, aux.t_s[-1]) - max(lo, aux.t_s[0])) / span if aux.t_s.size > 1 else 0.0
                )
                (chosen if cover >= self.options.min_temperature_cover else left).append(s)
            want = self.options.temperature_sensor
            if want is not None and want not in chosen:
                raise IngestError(
                    ihk.path,
                    f"IHK1B temperature sensor {want!r} does not cover the day's span "
                    f"(sensors that do: {', '.join(chosen) or 'none'})",
                    field="sensorname",
                )
            self.temperature_sensors = chosen if self.options.temperatures else []
            if left:
                self.summary.note(
                    "IHK1B temperature channels not covering the data span, left out: "
                    + ", ".join(left)
                )
            self.summary.columns = self.columns()
        needed = set(self.temperature_sensors)
        if self.options.temperature_sensor is not None:
            needed.add(self.options.temperature_sensor)
        return {
            s: channels.get(s, _Aux(np.empty(0), {"temperature_c": np.empty(0)})) for s in needed
        }

    def _mag_chunks(
        self,
        f: L1BFile,
        gnv: _Aux,
        sca: _Aux,
        temps: dict[str, _Aux],
        last_b: FloatArray | None,
    ) -> Iterator[Telemetry]:
        opts = self.options
        f.variable("time_intg", units=("seconds", "second"))
        for n in ("MfvX_RAW", "MfvY_RAW", "MfvZ_RAW"):
            f.variable(n, units=("microTesla",))
        for n in MAG1B_CURRENTS:
            f.variable(n, units=("mA",))
        if opts.every_s is not None and not opts.every_s > 0:
            raise IngestError(
                f.path, f"every_s must be positive, got {opts.every_s}", field="every_s"
            )
        names = ["time_intg", "time_frac", *_MAG_FIELD, *MAG1B_CURRENTS, "qualflg"]
        state = _MagState(last_b=last_b)
        for chunk in f.chunks(names, text=["GRACEFO_id", "time_ref"], chunk_rows=opts.chunk_rows):
            c = chunk.columns
            _check_ids(f, c["GRACEFO_id"], chunk.first_line)
            state.n_in_file += len(chunk)
            self.summary.records["MAG1B"] += len(chunk)
            _count_bits(self.summary, "MAG1B", flag_bits(c["qualflg"]))
            intg = c["time_intg"].astype(np.float64)
            frac = c["time_frac"].astype(np.float64)
            if self._frac_s is None:
                self._frac_s = _frac_scale_s(
                    f, float(intg[0]), float(frac[0]), self.summary, opts.time_frac_unit
                )
            t = intg + frac * self._frac_s
            b_nt = np.column_stack([c[k] for k in _MAG_FIELD]).astype(np.float64) * 1000.0
            keep = self._mag_keep(c, t, b_nt, state)
            tel = self._join(c, t, b_nt, keep, gnv, sca, temps)
            if tel is not None:
                yield tel
        if f.num_records is not None and state.n_in_file != f.num_records:
            self.summary.note(
                f"{f.path.name} holds {state.n_in_file} of the {f.num_records} records "
                "its header announces"
            )

    def _mag_keep(
        self, c: dict[str, npt.NDArray[Any]], t: FloatArray, b_nt: FloatArray, state: _MagState
    ) -> BoolArray:
        """MAG1B's own checks on a chunk: GPS time tags, order, thinning; gaps and repeats."""
        every = self.options.every_s
        keep: BoolArray = np.ones(t.shape[0], dtype=np.bool_)
        self._drop(keep, np.asarray(c["time_ref"] != "G", dtype=np.bool_), "MAG1B time_ref not GPS")
        order: BoolArray = np.asarray(np.diff(np.concatenate([[state.previous], t])) > 0)
        self._drop(keep, ~order, "MAG1B time not after the previous record")
        if every is not None:
            bins = np.floor(t / every)
            first_in_bin = np.diff(np.concatenate([[state.last_bin], bins])) > 0
            state.last_bin = float(bins[-1])
            self._drop(keep, ~first_in_bin, f"thinned to one record per {every:g} s")
        seq = np.concatenate([[state.previous], t]) if np.isfinite(state.previous) else t
        _report_gaps(self.summary, "MAG1B", seq, 3 * _MAG_STEP_S)
        state.previous = float(max(state.previous, t.max()))
        first_b = state.last_b if state.last_b is not None else np.full(3, np.nan)
        prev_b = np.vstack([first_b, b_nt[:-1]])
        repeats = int(np.count_nonzero(np.all(b_nt == prev_b, axis=1)))
        if repeats:
            self.summary.count_flags("MAG1B", {})
            self.summary.flags["MAG1B"][_REPEAT_KEY] += repeats
        state.last_b = b_nt[-1]
        return keep

    def _join(
        self,
        c: dict[str, npt.NDArray[Any]],
        t: FloatArray,
        b_nt: FloatArray,
        keep: BoolArray,
        gnv: _Aux,
        sca: _Aux,
        temps: dict[str, _Aux],
    ) -> Telemetry | None:
        """The chunk's kept samples inside every product's span, joined; None when none is."""
        opts = self.options
        g = bracket(t, gnv.t_s, max_gap_s=opts.max_gap_gnv_s)
        s = bracket(t, sca.t_s, max_gap_s=opts.max_gap_sca_s)
        self._drop_outside(keep, g, "GNV1B")
        self._drop_outside(keep, s, "SCA1B")
        tb: dict[str, Bracket] = {}
        for sensor, aux in temps.items():
            tb[sensor] = bracket(t, aux.t_s, max_gap_s=opts.max_gap_ihk_s)
            self._drop_outside(keep, tb[sensor], f"IHK1B T{sensor}")
        if not keep.any():
            return None
        idx = np.flatnonzero(keep)
        hk: dict[str, npt.NDArray[Any]] = {
            col: c[name][idx].astype(np.float64) for name, col in MAG1B_CURRENTS.items()
        }
        for sensor in self.temperature_sensors:
            hk[_t_name(sensor)] = linear(
                temps[sensor].values["temperature_c"], tb[sensor].take(idx)
            )
        temperature = None
        if opts.temperature_sensor is not None:
            sensor = opts.temperature_sensor
            temperature = linear(temps[sensor].values["temperature_c"], tb[sensor].take(idx))
        t_utc = gps_j2000_to_utc_s(t[idx])
        tel = Telemetry(
            t_utc_s=t_utc,
            b_raw_nt=b_nt[idx],
            q_wxyz=slerp(sca.values["q_wxyz"], s.take(idx)),
            r_itrs_km=hermite_positions(gnv.values["r_km"], gnv.values["v_km_s"], g.take(idx)),
            temperature_c=temperature,
            hk=hk,
        )
        self.summary.rows += len(tel)
        first, last = utc_s_to_iso([t_utc[0], t_utc[-1]])
        if self.summary.first_utc is None:
            self.summary.first_utc = first
        self.summary.last_utc = last
        return tel

    def _drop(self, keep: BoolArray, mask: BoolArray, reason: str) -> None:
        newly = mask & keep
        if newly.any():
            self.summary.dropped[reason] += int(newly.sum())
            keep &= ~mask

    def _drop_outside(self, keep: BoolArray, b: Bracket, product: str) -> None:
        self._drop(keep, b.before, f"before {product} span")
        self._drop(keep, b.after, f"after {product} span")
        self._drop(keep, b.in_gap, f"in {product} gap")


def _t_name(sensor: str) -> str:
    return f"hk_ihk1b_t{sensor}_degc"


def _shift_date(date: str, days: int) -> str:
    d = np.datetime64(date, "D") + np.timedelta64(days, "D")
    return str(d)
