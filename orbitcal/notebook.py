"""What the notebook objects show of themselves: one-line reprs, pandas frames, xarray datasets.

``Telemetry``, ``Truth`` and ``CalibrationRun`` hold arrays of every sample; printed whole they fill
a notebook. Their ``__repr__`` is one line (size, span, what they carry, the headline figure), and
``to_frame()`` / ``to_xarray()`` give the samples as a pandas DataFrame or an xarray Dataset
indexed by UTC time. xarray is optional: ``to_xarray`` says how to install it when it is missing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

from orbitcal.arrays import FloatArray

if TYPE_CHECKING:
    import pandas as pd

# The objects are taken as ``Any`` (duck-typed: Telemetry, Truth, CalibrationRun): this module sits
# below the packages whose objects it shows, so that it imports none of them (no import cycle).
Telemetry: TypeAlias = Any
Truth: TypeAlias = Any
CalibrationRun: TypeAlias = Any

__all__ = [
    "frame_to_xarray",
    "run_frame",
    "run_repr",
    "span_text",
    "telemetry_repr",
    "time_index",
    "truth_frame",
    "truth_repr",
]


def span_text(t_utc_s: FloatArray) -> str:
    """``2160 samples, 2022-08-02T00:00:00Z … 2022-08-02T05:59:50Z`` (UTC, whole seconds)."""
    n = int(np.shape(t_utc_s)[0])
    if n == 0:
        return "0 samples"
    from orbitcal.timescales import utc_s_to_iso

    first, last = (s[:19] + "Z" for s in utc_s_to_iso([float(t_utc_s[0]), float(t_utc_s[-1])]))
    return f"{n} samples, {first} … {last}"


def telemetry_repr(tel: Telemetry) -> str:
    carried = ["b"]
    for name, arr in (
        ("q", tel.q_wxyz),
        ("r", tel.r_itrs_km),
        ("temperature", tel.temperature_c),
        ("mtq", tel.mtq_am2),
    ):
        if arr is not None:
            carried.append(name)
    carried.extend(sorted(tel.hk))
    return f"Telemetry({span_text(tel.t_utc_s)}; columns {', '.join(carried)})"


def truth_repr(truth: Truth) -> str:
    frames = ["body"] if truth.b_body_nt is not None else []
    frames += ["itrs", "nec"]
    return (
        f"Truth({truth.field_name}, {span_text(truth.t_utc_s)}; frames {', '.join(frames)}; "
        f"positions from {truth.position_source})"
    )


def run_repr(run: CalibrationRun) -> str:
    doc = run.document
    metrics = doc.get("metrics", {})
    key = "holdout_rms_nt"
    rms = metrics.get(key)
    rms_text = f"{rms:.3g} nT" if isinstance(rms, int | float) else "–"
    kind = "" if run.vector else " (scalar)"
    return (
        f"CalibrationRun({doc.get('method')}, spacecraft {doc.get('spacecraft')!r}, "
        f"{span_text(run.telemetry.t_utc_s)}; {int(run.train.sum())} fitted, "
        f"{int(run.holdout.sum())} held out; held-out RMS{kind} {rms_text})"
    )


def time_index(t_utc_s: FloatArray) -> pd.DatetimeIndex:
    """A tz-aware UTC ``DatetimeIndex`` named ``time`` (microseconds kept)."""
    import pandas as pd

    us = np.round(np.asarray(t_utc_s, dtype=float) * 1e6).astype("int64")
    return pd.DatetimeIndex(pd.to_datetime(us, unit="us", utc=True), name="time")


def _columns(prefix: str, arr: FloatArray | None, axes: str, unit: str) -> dict[str, FloatArray]:
    if arr is None:
        return {}
    return {f"{prefix}_{a}_{unit}": arr[:, k] for k, a in enumerate(axes)}


def truth_frame(truth: Truth) -> pd.DataFrame:
    """``b_body_{x,y,z}_nt``, ``b_itrs_{x,y,z}_nt``, ``b_nec_{n,e,c}_nt``, ``r_itrs_{x,y,z}_km``
    by UTC time."""
    import pandas as pd

    data = {
        **_columns("b_body", truth.b_body_nt, "xyz", "nt"),
        **_columns("b_itrs", truth.b_itrs_nt, "xyz", "nt"),
        **_columns("b_nec", truth.b_nec_nt, "nec", "nt"),
        **_columns("r_itrs", truth.r_itrs_km, "xyz", "km"),
    }
    return pd.DataFrame(data, index=time_index(truth.t_utc_s))


def run_frame(
    run: CalibrationRun, b_cal: FloatArray, res: FloatArray | None, scalar: FloatArray
) -> pd.DataFrame:
    """Per sample by UTC time: ``held_out`` (a row no fit saw), the raw and calibrated field
    ``b_cal``, the residual ``res``, body frame [nT] (``residual_{x,y,z}_nt`` only with
    attitude), and ``scalar_residual_nt`` (``|b_cal| − |B_ref|``), as
    :func:`orbitcal.pipeline.residuals` gives them."""
    import pandas as pd

    data: dict[str, Any] = {"held_out": np.asarray(run.holdout, dtype=bool)}
    data.update(_columns("b_raw", run.telemetry.b_raw_nt, "xyz", "nt"))
    data.update(_columns("b_cal", b_cal, "xyz", "nt"))
    if res is not None:
        data.update(_columns("residual", res, "xyz", "nt"))
    data["scalar_residual_nt"] = scalar
    return pd.DataFrame(data, index=time_index(run.telemetry.t_utc_s))


def frame_to_xarray(frame: pd.DataFrame, *, attrs: dict[str, Any] | None = None) -> Any:
    """An xarray Dataset of a time-indexed frame (UTC times as naive datetime64[ns]).

    Raises
    ------
    ImportError
        xarray is not installed (it is optional): the message says how to install it.
    """
    try:
        import xarray as xr
    except ImportError as exc:
        raise ImportError(
            "to_xarray() needs xarray, an optional dependency: pip install xarray "
            "(to_frame() gives the same data as a pandas DataFrame)"
        ) from exc
    frame = frame.copy()
    if isinstance(frame.index, type(time_index(np.zeros(0)))) and frame.index.tz is not None:
        frame.index = frame.index.tz_convert("UTC").tz_localize(None)
    ds = xr.Dataset.from_dataframe(frame)
    ds.attrs.update({"time_scale": "UTC", **(attrs or {})})
    return ds
