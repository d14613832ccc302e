"""The notebook surface of orbitcal: six functions re-exported by ``import orbitcal``.

======================  =================================================================
``read_table``           a telemetry table from a file (CSV, Parquet, NDJSON, JSON) or a DataFrame
``load_orbit``           an :class:`~orbitcal.orbit.Orbit` from a TLE or OMM file, text or dict
``reference_field``      the reference field along the orbit, NEC / ITRS / body frame [nT]
``calibrate_table``      fit a calibration on the earlier samples, score it on the later ones
``apply_calibration``    the calibrated field of a table through a calibration document
``diagnose_table``       which unmodelled effect explains what the calibration leaves
======================  =================================================================

Each wraps the library's own pipeline (the same code as the ``orbitcal`` commands), with
keyword-only options and seeds passed in. Heavy packages (torch, scipy, pandas) are imported when a
function runs, so ``import orbitcal`` stays light. The tutorial ``docs/tutorial.md`` walks through
them; ``tests/test_tutorial.py`` runs it.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy.typing as npt
    import pandas as pd

    from orbitcal.diagnose.result import Report
    from orbitcal.orbit import Orbit
    from orbitcal.pipeline import CalibrationRun
    from orbitcal.telemetry import Telemetry
    from orbitcal.truth import Truth

__all__ = [
    "apply_calibration",
    "calibrate_table",
    "diagnose_table",
    "load_orbit",
    "read_table",
    "reference_field",
]


def read_table(source: str | Path | pd.DataFrame, *, time_scale: str = "UTC") -> Telemetry:
    """A validated telemetry table (CONTRACT section 1) from a file or a pandas DataFrame.

    Parameters
    ----------
    source : str, Path or pandas.DataFrame
        A ``.csv``, ``.parquet``, ``.ndjson`` or ``.json`` file, or a DataFrame with the contract's
        columns (``time``, ``b_x, b_y, b_z`` [nT], optional ``q_w…q_z``, ``r_x…r_z`` [km], …).
    time_scale : {"UTC", "TAI", "GPS"}, keyword-only
        The scale of the table's times.

    Returns
    -------
    Telemetry
        The valid rows. Rejected rows are reported in one :class:`UserWarning` (count and the
        first row's reason).

    Raises
    ------
    orbitcal.telemetry.TelemetryError
        The table cannot be read, or no row is valid.
    """
    from orbitcal.telemetry import TelemetryError, from_frame, read_telemetry

    if isinstance(source, str | Path):
        result = read_telemetry(source, time_scale=time_scale)
    else:
        result = from_frame(_time_as_column(source), time_scale=time_scale)
    if result.rejected:
        first = result.rejected[0]
        warnings.warn(
            f"{len(result.rejected)} rows rejected (first: row {first.row}: {first.reason}); "
            f"the {len(result.telemetry)} valid rows are used",
            UserWarning,
            stacklevel=2,
        )
    if len(result.telemetry) == 0:
        raise TelemetryError("no valid rows in the table")
    return result.telemetry


def _time_as_column(df: pd.DataFrame) -> pd.DataFrame:
    """A frame whose times are its ``DatetimeIndex`` gets them as the contract's ``time`` column
    (a tz-aware index is converted to UTC; a naive one is refused: its scale is unknown)."""
    import numpy as np
    import pandas as pd

    from orbitcal.telemetry import TelemetryError

    if "time" in df.columns:
        return df
    if isinstance(df.index, pd.DatetimeIndex):
        if df.index.tz is None:
            raise TelemetryError(
                "the DataFrame's DatetimeIndex has no time zone: localize it "
                "(df.index = df.index.tz_localize('UTC')) or give a 'time' column"
            )
        epoch = pd.Timestamp(0, tz="UTC")
        seconds = (df.index.tz_convert("UTC") - epoch).total_seconds()
        return df.reset_index(drop=True).assign(time=np.asarray(seconds, dtype=float))
    raise TelemetryError(
        "missing column 'time': a DataFrame carries the sample times as a 'time' column (ISO-8601 "
        "with Z, or Unix seconds) or as a tz-aware DatetimeIndex"
        + (f" (its index is a {type(df.index).__name__})" if len(df.index) else "")
    )


def load_orbit(
    source: str | Path | Mapping[str, Any],
    *,
    norad_id: int | None = None,
    near_utc_s: float | tuple[float, float] | None = None,
) -> Orbit:
    """One spacecraft's SGP4 elements from a TLE or OMM file, TLE/OMM text, or an OMM dict.

    Parameters
    ----------
    source : str, Path or mapping
        A path to a TLE file (one or many sets) or an OMM file (XML, JSON, CSV); the text of one;
        or one OMM record as a dict (CelesTrak JSON keys).
    norad_id : int, keyword-only
        The spacecraft, when the source holds several.
    near_utc_s : float or (float, float), keyword-only
        The data's time or span, POSIX seconds of UTC [s]: of several sets the one nearest in
        epoch is taken (default: the latest).

    Returns
    -------
    Orbit

    Raises
    ------
    orbitcal.orbit.OrbitError
        Malformed or unphysical elements (naming the field), or an ambiguous spacecraft.
    """
    from orbitcal.orbit import Orbit, read_orbits, select_orbit

    if isinstance(source, Mapping):
        return Orbit.from_omm(source)
    text = str(source)
    path = Path(text)
    if isinstance(source, Path) or ("\n" not in text and path.is_file()):
        text = path.read_text()
    orbits = read_orbits(text, path=str(source)[:80])
    return select_orbit(orbits, norad_id=norad_id, at_utc_s=near_utc_s)


def reference_field(
    telemetry: Telemetry,
    *,
    orbit: Orbit | None = None,
    field: str = "IGRF-14",
    attitude_frame: str = "GCRS",
) -> Truth:
    """The reference field at every sample, each at its own time and position.

    Parameters
    ----------
    telemetry : Telemetry
    orbit : Orbit, keyword-only
        Needed when the table has no positions (``r_x, r_y, r_z``).
    field : str, keyword-only
        Model name(s) joined by ``+`` (default IGRF-14; e.g. ``"CHAOS-8.1+LCS-1+RC"``).
    attitude_frame : {"GCRS", "ITRS"}, keyword-only
        Frame of the table's quaternions.

    Returns
    -------
    orbitcal.truth.Truth
        ``b_nec_nt``, ``b_itrs_nt`` and (with attitude) ``b_body_nt`` [nT], shape (N, 3).
    """
    from orbitcal.truth import truth_for_telemetry

    return truth_for_telemetry(telemetry, orbit=orbit, attitude_frame=attitude_frame, field=field)


def calibrate_table(
    telemetry: Telemetry,
    *,
    orbit: Orbit | None = None,
    method: str = "lmbp-hk",
    field: str = "IGRF-14",
    attitude_frame: str = "GCRS",
    holdout_fraction: float = 0.25,
    seed: int = 0,
    spacecraft: str | None = None,
    **options: Any,
) -> CalibrationRun:
    """Fit a calibration on the earlier samples and score it on the later ones.

    Parameters
    ----------
    telemetry : Telemetry
    orbit : Orbit, keyword-only
        Needed when the table has no positions.
    method : str, keyword-only
        ``linear``, ``linear-hk``, ``lmbp``, ``lmbp-hk`` (default), ``twostep``, ``flann``,
        ``online`` (:data:`orbitcal.calibrate.METHODS`).
    field, attitude_frame : str, keyword-only
        As in :func:`reference_field`.
    holdout_fraction : float, keyword-only
        Share of the latest samples held out for the metrics (default
        :data:`~orbitcal.calibrate.holdout.HOLDOUT_FRACTION`, as on every surface; written
        out so that loading this module imports no numpy, and held equal to it by a test).
    seed : int, keyword-only
        Seeds the fit's random start.
    spacecraft : str, keyword-only
        The document's ``spacecraft`` (default: the orbit's object name, else ``NORAD <id>``, else
        ``"unnamed"``; as ``orbitcal calibrate --spacecraft``).
    **options
        Passed to the calibrator (``n_hidden``, ``restarts``, ``max_epochs``).

    Returns
    -------
    orbitcal.pipeline.CalibrationRun
        ``.document`` is the CONTRACT section-4 document (``document["metrics"]``), ``.calibration``
        the fitted object, ``.holdout_scores`` the held-out RMS values.
    """
    import numpy as np

    from orbitcal.pipeline import calibrate

    if spacecraft is None:
        name = str(getattr(orbit, "name", "") or "").strip()
        norad = getattr(orbit, "norad_id", None)
        spacecraft = name or (f"NORAD {norad}" if norad is not None else "unnamed")
    return calibrate(
        telemetry,
        orbit=orbit,
        spacecraft=spacecraft,
        method=method,
        field=field,
        attitude_frame=attitude_frame,
        holdout_fraction=holdout_fraction,
        rng=np.random.default_rng(seed),
        **options,
    )


def apply_calibration(
    calibration: Mapping[str, Any] | str | Path | CalibrationRun, telemetry: Telemetry
) -> npt.NDArray[Any]:
    """The calibrated field of every row [nT, body frame], shape (N, 3).

    Parameters
    ----------
    calibration : dict, path or CalibrationRun
        A section-4 document (dict or JSON file) or the result of :func:`calibrate_table`.
    telemetry : Telemetry
        Housekeeping columns the calibration uses must be present.
    """
    from orbitcal.pipeline import CalibrationRun, apply_document
    from orbitcal.plausibility import check_table, table_radius_km

    if isinstance(calibration, CalibrationRun):
        document: dict[str, Any] = calibration.document
    elif isinstance(calibration, str | Path):
        document = json.loads(Path(calibration).read_text())
    else:
        document = dict(calibration)
    # no orbit here: the dipole range at the table's positions, else surface to GEO
    check_table(telemetry.b_raw_nt, r_km=table_radius_km(telemetry))
    return apply_document(document, telemetry)


def diagnose_table(
    telemetry: Telemetry,
    *,
    orbit: Orbit | None = None,
    field: str = "IGRF-14",
    attitude_frame: str = "GCRS",
    calibration: Mapping[str, Any] | None = None,
    seed: int = 0,
) -> Report:
    """Which unmodelled effect explains the calibrated residual (CONTRACT section-5 report).

    A thin wrapper of :func:`orbitcal.diagnose.diagnose` for notebooks: the typed, read-only
    :class:`~orbitcal.diagnose.Report` (``report["verdict"]`` as a dict's; ``to_json()`` the
    document, ``to_frame()`` the candidates, ``to_frame("time")`` the residual by UTC time; a
    notebook shows its first screen).
    The whole :class:`~orbitcal.diagnose.Diagnosis` (with the attribution and the arrays) and
    every option (:class:`~orbitcal.diagnose.DiagnosisOptions`) are there.

    Parameters
    ----------
    telemetry : Telemetry
        With attitude quaternions.
    orbit, field, attitude_frame : keyword-only
        As in :func:`reference_field`.
    calibration : dict, keyword-only
        The calibration in service (a section-4 document) as a prior on the 12 parameters.
    seed : int, keyword-only
        Seeds the learned model.

    Returns
    -------
    orbitcal.diagnose.Report
        ``verdict``, ranked ``effects`` with their held-out shrink, ``baseline`` and ``final``.
    """
    from orbitcal.diagnose.api import diagnose
    from orbitcal.diagnose.options import DiagnosisOptions

    options = DiagnosisOptions(field=field, attitude_frame=attitude_frame, seed=seed)
    diagnosis = diagnose(telemetry, orbit=orbit, options=options, prior=calibration)
    return diagnosis.report
