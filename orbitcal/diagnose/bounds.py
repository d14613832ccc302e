"""Physical ranges of the effect parameters (``docs/diagnosis_priors.md`` gives the sources).

Every joint fit of the diagnosis is a box-constrained least-squares problem: the 12 calibration
parameters are free (or held by the calibration prior), each effect parameter lies in the range
below. A candidate whose fit would need a parameter outside its range (a crustal model turned
upside down, a ring current changing by thousands of nT per hour) is fitted at the edge of the
range, and when only the unconstrained fit would have won, it is reported as ``implausible`` with
the parameter that had to leave its range.

The ranges are deliberately wide -- they exclude what no spacecraft or magnetosphere does, not
what is unusual -- so that a physical effect is never clipped. Names are matched by prefix on the
catalogue's parameter names (:mod:`orbitcal.diagnose.effects`), whose units are in the names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["PARAM_RANGES", "ParamRange", "consistency_reasons", "param_range"]


@dataclass(frozen=True)
class ParamRange:
    """Plausible range of one parameter.

    Attributes
    ----------
    lower, upper : float
        Bounds in the parameter's units (in its name).
    why : str
        One line: the physics or the missions the range comes from (sources in
        ``docs/diagnosis_priors.md``).
    prior_mean, prior_sd : float, optional
        A Gaussian prior inside the range, for parameters with a published value (a model's
        amplitude is 1) and for those a common attitude leaves ill-determined (a nonlinearity's
        cross-track terms in nadir): it decides the direction the data leave open (on a 30-min
        pass a scale factor and the ring current trade off) and hardly moves a well-determined
        fit.
    """

    lower: float
    upper: float
    why: str
    prior_mean: float | None = None
    prior_sd: float | None = None

    def contains(self, value: float, *, rel_tol: float = 1e-6) -> bool:
        """Whether ``value`` lies inside the range (a relative tolerance for solver round-off)."""
        pad = rel_tol * max(abs(self.lower), abs(self.upper), 1.0)
        return self.lower - pad <= value <= self.upper + pad

    def describe(self) -> str:
        """``[lower, upper]`` with the reason."""
        return f"[{self.lower:g}, {self.upper:g}] ({self.why})"


def _sym(x: float, why: str) -> ParamRange:
    return ParamRange(-x, x, why)


#: Ranges by parameter-name prefix (first match wins; order matters for shared prefixes).
PARAM_RANGES: tuple[tuple[str, ParamRange], ...] = (
    # temperature: fluxgate offset and sensitivity thermal coefficients
    ("offset_", _sym(10.0, "fluxgate offset thermal coefficient, <= 10 nT/degC")),
    (
        "scale_x_per_degc",
        _sym(25.0, "sensitivity thermal coefficient <= 500 ppm/degC (x 5e4 nT)"),
    ),
    (
        "scale_y_per_degc",
        _sym(25.0, "sensitivity thermal coefficient <= 500 ppm/degC (x 5e4 nT)"),
    ),
    (
        "scale_z_per_degc",
        _sym(25.0, "sensitivity thermal coefficient <= 500 ppm/degC (x 5e4 nT)"),
    ),
    # magnetorquer: dipole law 2 mu0 m / (4 pi d^3) at d >= 0.27 m
    ("coupling_", _sym(1.0e4, "dipole field of 1 A m^2 at >= 0.27 m from the sensor")),
    # time offset: a clock synchronised by ground contacts or GNSS
    ("dt_squared_s2", ParamRange(0.0, 25.0, "second order of the same shift: 0 <= dt^2 <= 25")),
    ("dt_s", _sym(5.0, "time-tag error of a synchronised on-board clock, <= 5 s")),
    # external field: ring current and its rate of change
    (
        "uniform_along_dipole_nt",
        ParamRange(-2000.0, 200.0, "magnetospheric field along the dipole: Dst >= -1760 nT"),
    ),
    (
        "uniform_trend_nt_per_day",
        _sym(7200.0, "ring-current rate of change <= 300 nT/h (extreme storms)"),
    ),
    (
        "uniform_recovering_nt",
        _sym(2000.0, "decaying storm-time ring-current field at the start: |Dst| <= 1760 nT"),
    ),
    (
        "rc_coefficient",
        ParamRange(0.3, 3.0, "field per nT of RC index, external + induced", 1.0, 0.5),
    ),
    (
        "rc_model_scale",
        ParamRange(0.2, 3.0, "RC-driven model amplitude, positive, near 1", 1.0, 0.5),
    ),
    # crustal field: a published model's amplitude
    (
        "crust_scale",
        ParamRange(0.3, 3.0, "amplitude of a published crustal model, near 1", 1.0, 0.5),
    ),
    # Sun-driven stray field (solar-array currents)
    ("sunlit_offset_", _sym(500.0, "stray field of solar-array currents, <= 500 nT")),
    ("sun_", _sym(500.0, "stray field of solar-array currents, <= 500 nT")),
    # sensor nonlinearity at 5e4 nT
    ("quadratic_", ParamRange(-500.0, 500.0, "nonlinearity <= 1 % of 5e4 nT", 0.0, 250.0)),
    ("cubic_", ParamRange(-500.0, 500.0, "nonlinearity <= 1 % of 5e4 nT", 0.0, 250.0)),
    # orbit error of an element set
    ("along_track_rate_km_per_day", _sym(50.0, "SGP4 along-track error growth <= 50 km/day")),
    ("along_track_km", _sym(100.0, "SGP4 along-track error <= 100 km")),
    ("along_track_", _sym(20.0, "once-per-rev along-track error <= 20 km")),
    ("radial_", _sym(20.0, "radial error of an element set <= 20 km")),
    ("cross_track_", _sym(20.0, "cross-track error of an element set <= 20 km")),
    # parameter drift
    ("bias_x_step", _sym(2000.0, "offset step <= 2000 nT")),
    ("bias_y_step", _sym(2000.0, "offset step <= 2000 nT")),
    ("bias_z_step", _sym(2000.0, "offset step <= 2000 nT")),
    ("bias_", _sym(100.0, "offset drift <= 100 nT/day")),
    ("scale_x_x5e+04_step", _sym(2500.0, "scale-factor step <= 5 % (x 5e4 nT)")),
    ("scale_y_x5e+04_step", _sym(2500.0, "scale-factor step <= 5 % (x 5e4 nT)")),
    ("scale_z_x5e+04_step", _sym(2500.0, "scale-factor step <= 5 % (x 5e4 nT)")),
    ("scale_", _sym(100.0, "scale-factor drift <= 2000 ppm/day (x 5e4 nT)")),
    # field-aligned currents
    ("east_", _sym(3000.0, "field-aligned-current perturbation at LEO <= 3000 nT")),
    # attitude error
    ("dtheta_", _sym(100.0, "attitude error <= 100 mrad (~6 deg)")),
)

_FREE = ParamRange(-math.inf, math.inf, "no physical range")


def param_range(name: str) -> ParamRange:
    """The plausible range of the parameter called ``name`` (unbounded when none matches)."""
    for prefix, rng in PARAM_RANGES:
        if name.startswith(prefix):
            return rng
    return _FREE


def consistency_reasons(names: list[str], values: list[float], sds: list[float]) -> list[str]:
    """Relations between the parameters of one effect that physics fixes, where violated.

    * ``time_offset``: the second-order coefficient of a time shift is ``dt^2`` itself; a fit
      whose ``dt_squared_s2`` differs from ``dt_s^2`` by more than three standard deviations
      (plus 0.1 s^2 and a factor 2) is using the second-order column for something else.
    """
    out: list[str] = []
    idx = {n: i for i, n in enumerate(names)}
    if "dt_s" in idx and "dt_squared_s2" in idx:
        dt, dt2 = values[idx["dt_s"]], values[idx["dt_squared_s2"]]
        sd2 = sds[idx["dt_squared_s2"]]
        sd1 = sds[idx["dt_s"]]
        # The second-order column is only approximately the second derivative (the part a
        # steady spin gives is absorbed by the 12 parameters): a factor 2 is tolerated.
        tol = 3.0 * math.hypot(sd2, 2.0 * abs(dt) * sd1) + 0.1 + dt * dt
        if math.isfinite(tol) and abs(dt2 - dt * dt) > tol:
            out.append(
                f"dt_squared_s2 = {dt2:.3g} s^2 while dt_s^2 = {dt * dt:.3g} s^2: the second-order "
                "term of a time shift must equal the square of the shift"
            )
    return out
