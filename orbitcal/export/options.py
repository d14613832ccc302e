"""Options and results of :func:`orbitcal.export.export` (one typed object each)."""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from orbitcal.export.errors import ExportError
from orbitcal.export.names import NAME, check_name, default_hk_name

__all__ = [
    "DEFAULT_CAL_NAMES",
    "DEFAULT_RAW_NAMES",
    "FORMATS",
    "YAMCS_INPUTS",
    "ExportError",
    "ExportOptions",
    "ExportResult",
    "HeldOutLoss",
    "YamcsTarget",
    "parse_hk_names",
    "parse_names",
]

#: CONTRACT section 7.
FORMATS = ("json", "xtce", "yamcs-push", "yamcs-instance", "cosmos", "c-header", "polynomial")
#: How the raw and housekeeping inputs reach a Yamcs algorithm (``--yamcs-inputs``): ``local``
#: parameters defined in the file (settable over REST: replay, commissioning), ``telemetered``
#: ones defined in the file (fed by a parameter link or stream by name), or ``qualified``
#: references to parameters the mission's own MDB defines (every name ``/SYSTEM/NAME``).
YAMCS_INPUTS = ("local", "telemetered", "qualified")
DEFAULT_RAW_NAMES = ("MAG_X_RAW", "MAG_Y_RAW", "MAG_Z_RAW")
DEFAULT_CAL_NAMES = ("MAG_X_CAL", "MAG_Y_CAL", "MAG_Z_CAL")


def _check_name(name: str, option: str) -> str:
    return check_name(name, option)  # the one identifier policy: orbitcal/export/names.py


def parse_names(
    text: str | None, default: tuple[str, str, str], option: str
) -> tuple[str, str, str]:
    """``"X,Y,Z"`` → three checked names (``default`` when ``None``)."""
    if text is None:
        return default
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3 or not all(parts):
        raise ExportError(f"{option} takes three names X,Y,Z; got {text!r}", field=option)
    a, b, c = (_check_name(p, option) for p in parts)
    if len({a, b, c}) != 3:
        raise ExportError(f"{option}: the three names must differ; got {text!r}", field=option)
    return a, b, c


def parse_hk_names(text: str | None, option: str = "--hk-names") -> dict[str, str]:
    """``"temperature=TEMP_MAG,mtq_x=MTQ_X"`` → ``{column: mission parameter name}``."""
    out: dict[str, str] = {}
    if not text:
        return out
    for item in text.split(","):
        column, sep, name = item.partition("=")
        if not sep or not column.strip() or not name.strip():
            raise ExportError(
                f"{option} takes COLUMN=NAME pairs separated by commas; got {item!r}",
                field=option,
            )
        out[column.strip()] = _check_name(name.strip(), option)
    return out


@dataclass(frozen=True)
class YamcsTarget:
    """A running Yamcs: base URL (``http://host:8090``), instance, processor, credentials."""

    url: str
    instance: str
    processor: str = "realtime"
    username: str | None = None
    password: str | None = None
    timeout_s: float = 10.0


@dataclass(frozen=True)
class HeldOutLoss:
    """Held-out RMS [nT] (CONTRACT ``rms_nt``: over samples and the three components) of the
    full calibration and of the reduced forms the exports carry, on the same samples."""

    n_samples: int
    full_rms_nt: float
    affine_rms_nt: float
    diagonal_rms_nt: float
    affine_max_abs_diff_nt: float
    diagonal_max_abs_diff_nt: float
    source: str

    def to_json(self) -> dict[str, Any]:
        return {
            "n_samples": self.n_samples,
            "full_rms_nt": self.full_rms_nt,
            "affine_rms_nt": self.affine_rms_nt,
            "diagonal_rms_nt": self.diagonal_rms_nt,
            "affine_max_abs_diff_nt": self.affine_max_abs_diff_nt,
            "diagonal_max_abs_diff_nt": self.diagonal_max_abs_diff_nt,
            "source": self.source,
        }


@dataclass(frozen=True)
class ExportOptions:
    """How to export.

    Attributes
    ----------
    format
        One of :data:`FORMATS`.
    raw_names, cal_names
        Mission parameter names of the raw [nT] and calibrated [nT] axes (CONTRACT section 7).
    hk_names
        Mission parameter names of the housekeeping inputs, by table column (``temperature``,
        ``mtq_x``, ``hk_<name>``); a column left out keeps its name upper-cased, made a name by
        :func:`orbitcal.export.names.default_hk_name`.
    space_system
        Name of the XTCE SpaceSystem / prefix of the coefficient parameters and variables.
    loss
        Held-out RMS of the reduced forms, written into the files that carry less than the
        whole model (:func:`orbitcal.export.held_out_loss`); ``None``: not measured.
    yamcs
        Where ``yamcs-push`` sends the coefficients.
    cosmos_target, cosmos_packet
        Default values of the plugin variables naming the packet that gets the DERIVED items.
    yamcs_inputs
        ``xtce``/``yamcs-instance``: how the inputs reach Yamcs, one of :data:`YAMCS_INPUTS`
        (a qualified name refers to the mission's parameter in every mode).
    yamcs_instance
        ``yamcs-instance``: the name of the Yamcs instance written.
    """

    format: str = "json"
    raw_names: tuple[str, str, str] = DEFAULT_RAW_NAMES
    cal_names: tuple[str, str, str] = DEFAULT_CAL_NAMES
    hk_names: dict[str, str] = field(default_factory=dict)
    space_system: str = "MAGCAL"
    loss: HeldOutLoss | None = None
    yamcs: YamcsTarget | None = None
    cosmos_target: str = "INST"
    cosmos_packet: str = "MAG"
    yamcs_inputs: str = "local"
    yamcs_instance: str = "magcal"

    def __post_init__(self) -> None:
        if self.format not in FORMATS:
            raise ExportError(
                f"unknown export format {self.format!r}; known: {', '.join(FORMATS)}",
                field="format",
            )
        _check_name(self.space_system, "space_system")
        if "/" in self.space_system:
            raise ExportError("space_system must be a plain name", field="space_system")
        for option in ("cosmos_target", "cosmos_packet"):
            check_name(getattr(self, option), option, qualified=False)
        for n in (*self.raw_names, *self.cal_names, *self.hk_names.values()):
            _check_name(n, "names")
        self._check_yamcs()
        clash = set(self.raw_names) & set(self.cal_names)
        if clash:
            raise ExportError(
                f"raw and calibrated names must differ; both name {', '.join(sorted(clash))}",
                field="cal_names",
            )

    def _check_yamcs(self) -> None:
        if self.yamcs_inputs not in YAMCS_INPUTS:
            raise ExportError(
                f"--yamcs-inputs: unknown {self.yamcs_inputs!r}; known: {', '.join(YAMCS_INPUTS)}",
                field="yamcs_inputs",
            )
        if NAME.fullmatch(self.yamcs_instance) is None:
            raise ExportError(
                f"Yamcs instance {self.yamcs_instance!r} must be a plain name (letters, digits, "
                "'_' or '-')",
                field="yamcs_instance",
            )
        if self.yamcs_inputs == "qualified":
            plain = [n for n in (*self.raw_names, *self.hk_names.values()) if not n.startswith("/")]
            if plain:
                raise ExportError(
                    "--yamcs-inputs qualified: every raw and housekeeping name must be the "
                    f"mission's qualified /SYSTEM/NAME; not: {', '.join(plain)}",
                    field="yamcs_inputs",
                )

    def hk_parameter(self, column: str) -> str:
        """The mission name of housekeeping column ``column``."""
        return self.hk_names.get(column) or default_hk_name(column)


@dataclass(frozen=True)
class ExportResult:
    """An export: one file (``content``) or a folder of files (``files``), or the report of a
    push (``report``), with the product metadata it names."""

    format: str
    media_type: str
    info: dict[str, Any]
    content: bytes | None = None
    files: dict[str, bytes] | None = None
    report: dict[str, Any] | None = None
    filename: str = "calibration"

    def zip_bytes(self) -> bytes:
        """The folder as a zip archive (deterministic: fixed dates, sorted names)."""
        assert self.files is not None
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(self.files):
                info = zipfile.ZipInfo(name, date_time=(2000, 1, 1, 0, 0, 0))
                info.external_attr = 0o644 << 16
                zf.writestr(info, self.files[name])
        return buf.getvalue()

    def body(self) -> bytes:
        """What an HTTP answer carries: the file, the zip of the folder, or the JSON report."""
        if self.content is not None:
            return self.content
        if self.files is not None:
            return self.zip_bytes()
        import json

        return (json.dumps(self.report, indent=2) + "\n").encode()

    def write(self, path: str | Path) -> list[Path]:
        """Write to ``path``: a file; for a folder export a directory, or a zip when ``path``
        ends in ``.zip``. Returns the paths written."""
        p = Path(path)
        if self.files is None or p.suffix.lower() == ".zip":
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(self.body())
            return [p]
        written = []
        for name, data in sorted(self.files.items()):
            target = p / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
            written.append(target)
        return written
