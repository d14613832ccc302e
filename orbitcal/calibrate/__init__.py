"""Magnetometer calibrators behind one interface, and a registry by method name.

| method | kind | source |
|---|---|---|
| ``linear`` | 12-parameter vector least squares (closed form) | Wang et al. 2020 eq. 1 |
| ``linear-hk`` | the same plus housekeeping regressors | – |
| ``lmbp`` | the paper's 3-H-3 BP network trained by LM, raw inputs | Wang et al. 2020 |
| ``lmbp-hk`` | on-orbit network: housekeeping inputs and a linear path | this project |
| ``twostep`` | attitude-free scalar calibration | Alonso & Shuster 2002 |
| ``flann`` | attitude-free, upper-triangular ``C`` + bias | Wu & Huang (seed 001) |
| ``online`` | one-sample ellipsoid estimator, ``η → chol → G, X_0`` | Chen (seed 002) |

Vector methods need the reference field in the body frame (attitude); scalar methods need only its
magnitude.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from orbitcal.calibrate.base import AffineCalibration, Calibration, FitData
from orbitcal.calibrate.errors import (
    CalibrationError,
    DocumentError,
    MissingAttitudeError,
    PoorCoverageError,
    TooFewSamplesError,
    UndeterminedFitError,
    UnknownMethodError,
)

if TYPE_CHECKING:  # imported on first use (torch takes ~1 s): see __getattr__
    import torch

    from orbitcal.calibrate.lmbp import LMBPCalibration

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "AffineCalibration",
    "Calibration",
    "CalibrationError",
    "DocumentError",
    "FitData",
    "LMBPCalibration",
    "MethodSpec",
    "MissingAttitudeError",
    "PoorCoverageError",
    "TooFewSamplesError",
    "UndeterminedFitError",
    "UnknownMethodError",
    "calibration_class",
    "fit_method",
]

ProgressCallback = Callable[[int, float], None]


def _load(ref: str) -> Any:
    """``"module:attribute"`` → the attribute, importing the module on first use."""
    module, _, attribute = ref.partition(":")
    return getattr(importlib.import_module(module), attribute)


@dataclass(frozen=True)
class MethodSpec:
    """A registered calibrator: how to fit it and which class loads its documents.

    The registry names its implementations by ``"module:attribute"`` and imports them on first use,
    so listing the methods (``orbitcal calibrate --help``) does not import torch.
    """

    name: str
    cls_ref: str
    vector: bool
    description: str
    fit: Callable[..., Calibration]

    @property
    def cls(self) -> type[Calibration]:
        """The class that loads this method's documents."""
        cls: type[Calibration] = _load(self.cls_ref)
        return cls


def _fit_lmbp(use_hk: bool) -> Callable[..., Calibration]:
    def fit(
        data: FitData,
        *,
        generator: torch.Generator,
        callback: ProgressCallback | None = None,
        warm_start: Calibration | None = None,
        n_hidden: int = 3,
        restarts: int | None = None,
        max_epochs: int = 200,
    ) -> Calibration:
        from orbitcal.calibrate.lmbp import STOPPING, LMBPCalibration, fit_lmbp

        return fit_lmbp(
            data,
            n_hidden=n_hidden,
            use_hk=use_hk,
            restarts=restarts if restarts is not None else (1 if use_hk else 3),
            generator=generator,
            options=replace(STOPPING, max_epochs=max_epochs),
            warm_start=warm_start if isinstance(warm_start, LMBPCalibration) else None,
            callback=callback,
        )

    return fit


def _simple(ref: str, **kwargs: Any) -> Callable[..., Calibration]:
    def fit(data: FitData, **_: Any) -> Calibration:
        calibration: Calibration = _load(ref)(data, **kwargs)
        return calibration

    return fit


_AFFINE = "orbitcal.calibrate.base:AffineCalibration"
_LMBP = "orbitcal.calibrate.lmbp:LMBPCalibration"

METHODS: dict[str, MethodSpec] = {
    spec.name: spec
    for spec in (
        MethodSpec(
            "linear",
            _AFFINE,
            True,
            "12-parameter vector least squares",
            _simple("orbitcal.calibrate.linear:fit_linear"),
        ),
        MethodSpec(
            "linear-hk",
            _AFFINE,
            True,
            "12-parameter vector least squares + housekeeping regressors",
            _simple("orbitcal.calibrate.linear:fit_linear", use_hk=True),
        ),
        MethodSpec(
            "lmbp",
            _LMBP,
            True,
            "Wang et al. 2020: 3-H-3 BP network trained by Levenberg-Marquardt",
            _fit_lmbp(False),
        ),
        MethodSpec(
            "lmbp-hk",
            _LMBP,
            True,
            "LM-BP network with housekeeping inputs and a linear path",
            _fit_lmbp(True),
        ),
        MethodSpec(
            "twostep",
            _AFFINE,
            False,
            "TWOSTEP attitude-free scalar calibration (Alonso & Shuster 2002)",
            _simple("orbitcal.calibrate.scalar:fit_twostep"),
        ),
        MethodSpec(
            "flann",
            _AFFINE,
            False,
            "FLANN scalar calibration, upper-triangular C + bias (Wu & Huang)",
            _simple("orbitcal.calibrate.scalar:fit_flann"),
        ),
        MethodSpec(
            "online",
            _AFFINE,
            False,
            "one-sample ellipsoid estimator (Chen, patent)",
            _simple("orbitcal.calibrate.online:fit_online"),
        ),
    )
}

DEFAULT_METHOD = "lmbp-hk"


def _spec(name: str) -> MethodSpec:
    try:
        return METHODS[name]
    except KeyError:
        raise UnknownMethodError(name, sorted(METHODS)) from None


def calibration_class(name: str) -> type[Calibration]:
    """The class that loads documents of method ``name``."""
    try:
        return _spec(name).cls
    except UnknownMethodError as exc:
        raise DocumentError(str(exc)) from None


def fit_method(
    name: str,
    data: FitData,
    *,
    generator: torch.Generator,
    callback: ProgressCallback | None = None,
    **options: Any,
) -> Calibration:
    """Fit calibrator ``name`` on ``data``.

    Raises
    ------
    UnknownMethodError, MissingAttitudeError, TooFewSamplesError, PoorCoverageError
    """
    spec = _spec(name)
    if spec.vector and data.b_ref_body_nt is None:
        raise MissingAttitudeError(name)
    return spec.fit(data, generator=generator, callback=callback, **options)


def __getattr__(name: str) -> Any:
    """``LMBPCalibration`` is imported on first use (it needs torch)."""
    if name == "LMBPCalibration":
        return _load(_LMBP)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
