"""The contract's table in the library: columns, bounds, :class:`Telemetry`, :class:`ReadResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
import numpy.typing as npt
import pandas as pd

from orbitcal.arrays import FloatArray
from orbitcal.errors import UnreadableInputError

__all__ = [
    "B_ABSURD_NT",
    "HK_PREFIX",
    "OPTIONAL_GROUPS",
    "QUAT_NORM_TOL",
    "REQUIRED_COLUMNS",
    "R_MAX_KM",
    "R_MIN_KM",
    "T_MAX_S",
    "T_MIN_S",
    "ReadResult",
    "RowError",
    "Telemetry",
    "TelemetryError",
    "TelemetryFormat",
    "format_from_path",
    "iso_z",
]

TelemetryFormat = Literal["csv", "ndjson", "json", "parquet"]

#: Columns every table must carry (CONTRACT section 1).
REQUIRED_COLUMNS: tuple[str, ...] = ("time", "b_x", "b_y", "b_z")
#: Optional column groups: all columns of a group or none.
OPTIONAL_GROUPS: dict[str, tuple[str, ...]] = {
    "quaternion": ("q_w", "q_x", "q_y", "q_z"),
    "position": ("r_x", "r_y", "r_z"),
    "temperature": ("temperature",),
    "magnetorquer": ("mtq_x", "mtq_y", "mtq_z"),
}
#: A field magnitude above this is not a magnetometer reading [nT] (Earth's surface field < 7e4 nT).
B_ABSURD_NT = 1e6
#: Largest accepted deviation of |q| from 1 (CONTRACT section 1).
QUAT_NORM_TOL = 1e-3
#: Accepted geocentric distance of a position [km]: above the Earth's surface, below 10^6 km.
R_MIN_KM = 6300.0
R_MAX_KM = 1e6
#: Accepted sample times: 1900-01-01 … 2200-01-01 [POSIX s].
T_MIN_S = -2_208_988_800.0
T_MAX_S = 7_258_118_400.0
HK_PREFIX = "hk_"


_EXTENSIONS: dict[str, TelemetryFormat] = {
    ".csv": "csv",
    ".parquet": "parquet",
    ".pq": "parquet",
    ".ndjson": "ndjson",
    ".jsonl": "ndjson",
    ".json": "json",
}
_KNOWN_COLUMNS = frozenset(REQUIRED_COLUMNS).union(*OPTIONAL_GROUPS.values())


class TelemetryError(UnreadableInputError):
    """The table as a whole cannot be read (missing column, bad format, unknown time scale).

    Fix the file or the option named in the message; row-level problems never raise, they are
    returned as :class:`RowError` entries. HTTP 400 (a malformed upload), exit code 2.
    """


class RowError(NamedTuple):
    """One rejected data row: 0-based row number in the upload's order and the reason."""

    row: int
    reason: str


@dataclass(frozen=True, eq=False)
class Telemetry:
    """A validated telemetry table (columnar, sorted by time, unique times).

    Attributes
    ----------
    t_utc_s : ndarray, shape (N,)
        Sample times, POSIX seconds of UTC [s].
    b_raw_nt : ndarray, shape (N, 3)
        Raw magnetometer output in sensor axes [nT].
    q_wxyz : ndarray, shape (N, 4), or None
        Body orientation in the attitude frame (GCRS by default), scalar first:
        ``v_body = Rotation.from_quat([x, y, z, w]).inv().apply(v_frame)``.
    r_itrs_km : ndarray, shape (N, 3), or None
        Position in ITRS [km].
    temperature_c : ndarray, shape (N,), or None
        Sensor temperature [°C].
    mtq_am2 : ndarray, shape (N, 3), or None
        Magnetorquer dipole commands, body axes [A·m²].
    hk : dict of str to ndarray, shape (N,)
        Other housekeeping channels keyed by their full column name (``"hk_<name>"``); numeric
        channels are float64, others object arrays of str.
    """

    t_utc_s: FloatArray
    b_raw_nt: FloatArray
    q_wxyz: FloatArray | None = None
    r_itrs_km: FloatArray | None = None
    temperature_c: FloatArray | None = None
    mtq_am2: FloatArray | None = None
    hk: dict[str, npt.NDArray[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = np.shape(self.t_utc_s)[0] if np.ndim(self.t_utc_s) == 1 else -1
        if n < 0:
            raise ValueError("t_utc_s must have shape (N,)")
        shapes: dict[str, tuple[npt.NDArray[Any] | None, tuple[int, ...]]] = {
            "b_raw_nt": (self.b_raw_nt, (n, 3)),
            "q_wxyz": (self.q_wxyz, (n, 4)),
            "r_itrs_km": (self.r_itrs_km, (n, 3)),
            "temperature_c": (self.temperature_c, (n,)),
            "mtq_am2": (self.mtq_am2, (n, 3)),
        }
        for name, (arr, shape) in shapes.items():
            if arr is not None and np.shape(arr) != shape:
                raise ValueError(f"{name} has shape {np.shape(arr)}, expected {shape}")
        for name, arr in self.hk.items():
            if not name.startswith(HK_PREFIX):
                raise ValueError(f"housekeeping channel {name!r} must be named 'hk_<name>'")
            if np.shape(arr) != (n,):
                raise ValueError(f"{name} has shape {np.shape(arr)}, expected {(n,)}")

    def __len__(self) -> int:
        return int(self.t_utc_s.shape[0])

    def select(self, mask_or_index: npt.ArrayLike | slice) -> Telemetry:
        """The rows picked by a boolean mask, an integer index array or a slice (a new table)."""
        idx: Any = mask_or_index if isinstance(mask_or_index, slice) else np.asarray(mask_or_index)

        def pick(a: npt.NDArray[Any] | None) -> Any:
            return None if a is None else a[idx]

        return Telemetry(
            t_utc_s=self.t_utc_s[idx],
            b_raw_nt=self.b_raw_nt[idx],
            q_wxyz=pick(self.q_wxyz),
            r_itrs_km=pick(self.r_itrs_km),
            temperature_c=pick(self.temperature_c),
            mtq_am2=pick(self.mtq_am2),
            hk={k: v[idx] for k, v in self.hk.items()},
        )

    def sort_by_time(self) -> Telemetry:
        """The rows in ascending time (stable); ``self`` when already sorted."""
        if len(self) < 2 or bool(np.all(np.diff(self.t_utc_s) >= 0)):
            return self
        return self.select(np.argsort(self.t_utc_s, kind="stable"))

    def regressors(self) -> tuple[FloatArray, list[str]]:
        """Housekeeping regressors for the calibrators and the diagnosis.

        Returns
        -------
        x_hk : ndarray, shape (N, k)
            Columns in the order of ``names``: temperature [°C], ``mtq_x, mtq_y, mtq_z`` [A·m²],
            then every numeric ``hk_*`` channel (sorted by name) in its own unit.
        names : list of str
            Column names as in the table (``"temperature"``, ``"mtq_x"``, …, ``"hk_<name>"``).
        """
        cols: list[FloatArray] = []
        names: list[str] = []
        if self.temperature_c is not None:
            cols.append(np.asarray(self.temperature_c, dtype=np.float64))
            names.append("temperature")
        if self.mtq_am2 is not None:
            for j, axis in enumerate("xyz"):
                cols.append(np.asarray(self.mtq_am2[:, j], dtype=np.float64))
                names.append(f"mtq_{axis}")
        for name in sorted(self.hk):
            arr = self.hk[name]
            if arr.dtype.kind in "iufb":
                cols.append(arr.astype(np.float64))
                names.append(name)
        x_hk = np.column_stack(cols) if cols else np.empty((len(self), 0))
        return x_hk, names

    def to_frame(self) -> pd.DataFrame:
        """The samples by UTC time (a tz-aware ``DatetimeIndex`` named ``time``, as
        ``CalibrationRun.to_frame()`` and ``Truth.to_frame()``), the contract's other columns
        beside it; :func:`orbitcal.read_table` takes it back. For the contract's table with
        ``time`` as an ISO-8601 column (what the writers write): :meth:`to_table_frame`."""
        from orbitcal.notebook import time_index

        frame = self.to_table_frame().drop(columns="time")
        frame.index = time_index(self.t_utc_s)
        return frame

    def to_table_frame(self) -> pd.DataFrame:
        """The table with the contract's columns (``time`` as ISO-8601 UTC with ``Z``) on a
        row-number index: what the writers write."""
        data: dict[str, Any] = {"time": iso_z(self.t_utc_s)}
        for j, c in enumerate(("b_x", "b_y", "b_z")):
            data[c] = self.b_raw_nt[:, j]
        if self.q_wxyz is not None:
            for j, c in enumerate(OPTIONAL_GROUPS["quaternion"]):
                data[c] = self.q_wxyz[:, j]
        if self.r_itrs_km is not None:
            for j, c in enumerate(OPTIONAL_GROUPS["position"]):
                data[c] = self.r_itrs_km[:, j]
        if self.temperature_c is not None:
            data["temperature"] = self.temperature_c
        if self.mtq_am2 is not None:
            for j, c in enumerate(OPTIONAL_GROUPS["magnetorquer"]):
                data[c] = self.mtq_am2[:, j]
        for name in sorted(self.hk):
            data[name] = self.hk[name]
        return pd.DataFrame(data)

    def to_xarray(self) -> Any:
        """The table as an xarray Dataset indexed by UTC time (needs the optional xarray)."""
        from orbitcal.notebook import frame_to_xarray

        return frame_to_xarray(self.to_frame())

    def __repr__(self) -> str:
        from orbitcal.notebook import telemetry_repr

        return telemetry_repr(self)


@dataclass(frozen=True)
class ReadResult:
    """What a reader returns: the valid rows (sorted by time) and the rejected ones."""

    telemetry: Telemetry
    rejected: list[RowError]


def format_from_path(path: str | Path) -> TelemetryFormat:
    """The table format named by a file's extension (.csv, .parquet, .ndjson, .json)."""
    suffix = Path(path).suffix.lower()
    try:
        return _EXTENSIONS[suffix]
    except KeyError:
        raise TelemetryError(
            f"{path}: unknown telemetry extension {suffix!r}; use .csv, .parquet, .ndjson or .json"
        ) from None


def iso_z(t_utc_s: npt.ArrayLike) -> npt.NDArray[np.str_]:
    """POSIX seconds of UTC → ISO-8601 ``YYYY-MM-DDTHH:MM:SS.ffffffZ`` (vectorised, µs)."""
    t = np.asarray(t_utc_s, dtype=np.float64)
    whole = np.floor(t)
    us = whole.astype(np.int64) * 1_000_000 + np.round((t - whole) * 1e6).astype(np.int64)
    text = np.datetime_as_string(us.astype("datetime64[us]"), unit="us")
    return np.char.add(text, "Z")
