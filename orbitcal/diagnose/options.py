"""The diagnosis's options, in one typed place: every default of every door lives here.

:class:`AttributionOptions` are the held-out attribution's settings (time blocks, chunks of the
significance test, level, gain, steps); :class:`DiagnosisOptions` add what the front door decides
(reference field, attitude frame, the crustal and external models offered, the learned model, the
prior's widths, the seed and the BLAS threads). The CLI, the service, the notebook API and the
benchmark build one of these and hand it to :func:`orbitcal.diagnose.diagnose`; no door keeps a
default of its own.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from orbitcal.diagnose.prior import DEFAULT_SIGMA_MATRIX, DEFAULT_SIGMA_OFFSET_NT

__all__ = [
    "DEFAULT_CRUST_MODEL",
    "DEFAULT_WORKERS",
    "ENGINES",
    "HOLDOUT_BLOCKS",
    "N_BLOCKS",
    "AttributionOptions",
    "DiagnosisOptions",
    "ModelOptions",
]

#: The verdict-makers: ``"rules"`` the held-out attribution and its review, ``"model"`` the
#: model core (:mod:`orbitcal.diagnose.model`).
ENGINES = ("rules", "model")

#: Equal-duration time blocks of a diagnosis, and how many of the latest are held out.
N_BLOCKS = 10
HOLDOUT_BLOCKS = 3

#: Threads of a selection step (:attr:`AttributionOptions.workers`): the candidates' fits are
#: independent. Much of a fit holds the interpreter (small products), so two threads gain a
#: little: the torquer day at 1 Hz of ``benchmarks/diagnose_timing.py`` took 6.8 s of wall time
#: against 7.3 s with one (8.2 s of CPU against 7.6), the same report to the bit. With two or
#: more, the model core also runs on a thread of its own beside the rules engine
#: (``orbitcal.diagnose.api._model_core_started``).
DEFAULT_WORKERS = 2

#: Crustal model used as the crustal_field candidate (Olsen et al. 2017).
DEFAULT_CRUST_MODEL = "LCS-1"


@dataclass(frozen=True)
class AttributionOptions:
    """Settings of the held-out attribution (:func:`orbitcal.diagnose.attribution.attribute`).

    Attributes
    ----------
    n_blocks, holdout_blocks : int
        Equal-duration time blocks; the last ``holdout_blocks`` are held out.
    n_chunks : int
        Consecutive chunks of the held-out span for the significance test.
    n_chunks_local : int
        Chunks for an effect confined to less than half of the held-out span (e.g. auroral
        crossings), so that each chunk still spans a whole part of a crossing.
    alpha : float
        Family-wise significance level per selection step (Bonferroni over candidates).
    min_gain : float
        Minimum relative drop of the held-out RMS for an effect to be named [-].
    max_steps : int
        At most this many effects are selected. An effect with a regional test (auroral
        currents) found in the calibration's residual takes one place; found only in what the
        selected effects leave, it comes as one more.
    tie_tolerance : float
        Candidates whose held-out RMS is within this fraction of the best are ranked by the BIC
        of their training fit instead [-].
    robust : bool
        Huber-reweighted fits.
    split_tests : bool
        Also run the split-fit tests (sunlit/eclipse, attitude regimes, time blocks).
    workers : int
        Threads that fit the candidates of a selection step side by side (at most the machine's
        cores; 1: one after the other). Each candidate's fit is computed alone in its thread,
        with one BLAS thread, so the result does not depend on it. With two or more, the model
        core runs on a thread of its own beside the rules engine (same result).
    """

    n_blocks: int = N_BLOCKS
    holdout_blocks: int = HOLDOUT_BLOCKS
    n_chunks: int = 32
    n_chunks_local: int = 16
    alpha: float = 0.05
    min_gain: float = 0.03
    max_steps: int = 3
    tie_tolerance: float = 0.01
    robust: bool = True
    split_tests: bool = True
    workers: int = DEFAULT_WORKERS


@dataclass(frozen=True)
class ModelOptions:
    """The model core's settings (:mod:`orbitcal.diagnose.model`, ``docs/design.md``): all of
    them, fixed before any validation world was drawn.

    Attributes
    ----------
    engine : {"rules", "model"}
        Which engine makes the verdict. The report's ``probability``, ``verdict_probability``
        and ``confirmation`` come from the model core under both.
    expected_effects : float
        Prior expected number of effects present; each of the catalogue's K effects is present
        with probability ``expected_effects / K``.
    max_effects : int
        Largest model enumerated (every model of at most this many effects).
    noise_max_order : int
        Largest autoregressive order of the per-axis noise model.
    prior_sd_fraction : float
        Prior standard deviation of a parameter without a stated Gaussian prior, as a fraction
        of its range's half-width.
    selection_probability : float
        Inclusion probability from which an effect is in the chosen model (0.5: the median
        probability model) and is named.
    confirmation_level : float
        Level of the one-sided confirmation test on the final block.
    """

    engine: str = "rules"
    expected_effects: float = 1.0
    max_effects: int = 3
    noise_max_order: int = 4
    prior_sd_fraction: float = 1.0 / 3.0
    selection_probability: float = 0.5
    confirmation_level: float = 0.05

    def __post_init__(self) -> None:
        if self.engine not in ENGINES:
            raise ValueError(f"engine {self.engine!r}: one of {', '.join(ENGINES)}")


@dataclass(frozen=True)
class DiagnosisOptions:
    """Everything a diagnosis is asked with, besides the telemetry, the orbit and the prior.

    Attributes
    ----------
    field : str
        Reference field (``orbitcal.field`` name).
    attitude_frame : {"GCRS", "ITRS"}
        The frame of the table's quaternions.
    crust_model : str or None
        Crustal model offered to the crustal_field candidate; None to skip it (then the learned
        model, if on, stands for it).
    external_model : bool
        Offer the RC-driven magnetospheric field to the external_field candidate.
    learned : bool
        Fit the seed-003 learned field model (the crustal candidate without a crustal model,
        else a summary of what the final model leaves).
    prior_sigma_matrix, prior_sigma_offset_nt : float
        Widths of the prior made from a calibration document [-], [nT]
        (:func:`orbitcal.diagnose.prior.prior_from_document`).
    seed : int
        Seeds the learned model when no generator is given.
    one_blas_thread : bool
        Run with one BLAS thread (many small products: more threads only spin,
        :mod:`orbitcal.blas`).
    attribution : AttributionOptions
        The held-out attribution's settings.
    model : ModelOptions
        The model core's settings, and which engine makes the verdict.
    """

    field: str = "IGRF-14"
    attitude_frame: str = "GCRS"
    crust_model: str | None = DEFAULT_CRUST_MODEL
    external_model: bool = True
    learned: bool = True
    prior_sigma_matrix: float = DEFAULT_SIGMA_MATRIX
    prior_sigma_offset_nt: float = DEFAULT_SIGMA_OFFSET_NT
    seed: int = 0
    one_blas_thread: bool = True
    attribution: AttributionOptions = dataclasses.field(default_factory=AttributionOptions)
    model: ModelOptions = dataclasses.field(default_factory=ModelOptions)
