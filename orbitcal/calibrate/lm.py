"""A generic Levenberg–Marquardt least-squares optimiser in PyTorch (float64).

Minimises ``E(w) = ½ Σ r_i(w)²`` (Wang et al. 2020, eq. 2) for any small model given as a residual
function of a flat parameter vector. Each epoch forms the exact Jacobian once — from the model's own
analytic ``residuals_and_jacobian`` when it has one, otherwise by forward-mode ``torch.func.jacfwd``
(exact, and cheaper than reverse mode when parameters ≪ residuals) — and then solves the damped
normal equations (Wang et al. 2020, eq. 14, with Marquardt's diagonal scaling instead of ``μI``)

    (JᵀJ + μ·diag(D)) δ = −Jᵀr,   D = diag(JᵀJ) of this epoch        (Marquardt 1963)

by Cholesky, retrying with a larger ``μ`` (without a new Jacobian) until the step lowers ``E``.
``μ`` follows Nielsen's rule (Nielsen 1999, IMM-REP-1999-05; Madsen, Nielsen & Tingleff 2004,
"Methods for non-linear least squares problems", eq. 3.16 and Algorithm 3.16): on an accepted step
with gain ratio ``ρ``, ``μ ← μ·max(1/3, 1 − (2ρ − 1)³)`` and ``ν ← 2``; on a rejected one
``μ ← μ·ν``, ``ν ← 2ν``; the start is ``μ₀ = τ = 1e-6`` (their recommendation for a start
believed close to the solution).

Why these defaults (measured on the 3-H-3 network of ``benchmarks/lm.py``): the network's noise
floor lies along a flat, curved valley (tanh units driven towards their linear range) that only
nearly-Gauss–Newton steps cross quickly. Nielsen's rule lowers ``μ`` by at most 3× per epoch and
barely at all while ``ρ`` stays 0.6–0.85, as it does there, so every extra decade of ``μ₀`` or of
damping costs epochs: Moré's running maximum of ``diag(JᵀJ)`` (kept as ``scaling="more"``) holds
on to the large curvatures of the first epochs, and with it and ``τ = 1e-3`` the 3-3-3 network
needed 18–23 epochs to 1.02× the floor (seeds 1–3, 10^3 and 10^4 samples); with this epoch's
diagonal and ``τ = 1e-6`` it needs 12–19. Marquardt's ×10 rule (``update="marquardt"``), which
lowers ``μ`` on every accepted step whatever ``ρ``, needs 8–11 with ``scaling="levenberg"``.

References
----------
Wang, Y.K., Sheng, T., He, L., Cheng, Z.Y. (2020), J. Computer and Communications 8, 31-41.
Marquardt, D.W. (1963), SIAM J. Appl. Math. 11(2), 431-441.
Moré, J.J. (1978), "The Levenberg-Marquardt algorithm: implementation and theory", LNM 630.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

import torch

__all__ = [
    "LMOptions",
    "LMResult",
    "LeastSquaresProblem",
    "StopReason",
    "levenberg_marquardt",
    "torch_threads",
]

StopReason = Literal["gradient", "step", "loss", "target", "max_epochs", "damping", "monitor"]


@contextmanager
def torch_threads(n: int | None) -> Iterator[None]:
    """Run the block with ``n`` torch intra-op threads, then restore the previous count.

    ``None`` leaves the count alone. A small fit's operations take microseconds to milliseconds;
    with two threads on a shared two-core machine each one waits for the busier core (NOTES: 5 ms
    became 3.8 s), and the split of sums between threads makes weights differ from run to run.
    The setting is process-wide while the block runs, so it is set where a fit runs, not globally.
    """
    if n is None:
        yield
        return
    previous = torch.get_num_threads()
    if previous == n:
        yield
        return
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


ResidualFn = Callable[[torch.Tensor], torch.Tensor]
ResidualJacobianFn = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]]


@runtime_checkable
class LeastSquaresProblem(Protocol):
    """A model with a residual function.

    Optional methods, found at run time: ``residuals_and_jacobian(w) -> (r, J)`` (an analytic
    Jacobian) and ``normal_equations(w) -> (r, JᵀJ, Jᵀr)`` (the same, assembled from a structured
    Jacobian without forming its zero blocks).
    """

    def residuals(self, params: torch.Tensor) -> torch.Tensor:
        """Residual vector ``r(w)``, shape ``(m,)``, float64."""
        ...


@dataclass(frozen=True)
class LMOptions:
    """Stopping rules and damping of :func:`levenberg_marquardt`.

    Parameters
    ----------
    max_epochs
        Maximum number of epochs (Jacobian evaluations).
    gtol
        Stop when every column of ``J`` is nearly orthogonal to ``r``:
        ``|(Jᵀr)_j| ≤ gtol · ‖J_j‖ · ‖r‖`` for all ``j`` (MINPACK's scale-free first-order test:
        the cosine of the angle between ``r`` and each Jacobian column).
    xtol
        Stop when ``‖δ‖ ≤ xtol · (‖w‖ + xtol)``.
    ftol
        Stop when the accepted steps of the last ``ftol_epochs`` epochs together lowered ``E`` by
        less than ``ftol`` times ``E`` as it was before them, or when the epoch's least-damped
        step is predicted to lower it by less than ``ftol · E`` and does not lower it.
    ftol_epochs
        Window of the relative-decrease test (1: the last epoch alone). A window of a few epochs
        lets LM cross a flat valley, where single steps gain little, without stopping there.
    target_mse
        Stop as soon as ``mean(r²) ≤ target_mse`` (e.g. the paper's 1e-3); ``None`` to disable.
    mu0
        Initial relative damping ``μ`` (dimensionless: it multiplies ``diag(D)``); Nielsen's ``τ``.
    scaling
        ``"marquardt"``: damp with ``μ·diag(D)``, ``D = diag(JᵀJ)`` of the current epoch
        (Marquardt 1963); ``"more"``: ``D`` the running max of ``diag(JᵀJ)`` over the epochs
        (Moré 1978, MINPACK); ``"levenberg"``: ``μ·max(D)·I`` (Levenberg 1944; Nielsen 1999 uses
        this).
    update
        ``"nielsen"``: the gain-ratio rule above; ``"marquardt"``: Marquardt's (1963) ``μ/10`` on
        an accepted step and ``10μ`` on a rejected one, which returns to Gauss–Newton faster when
        steps succeed with a mediocre gain ratio (fewer epochs on the 3-3-3 network).
    max_rejections
        Retries with a larger ``μ`` in one epoch before giving up ("damping").
    """

    max_epochs: int = 200
    gtol: float = 1e-10
    xtol: float = 1e-10
    ftol: float = 1e-12
    ftol_epochs: int = 1
    target_mse: float | None = None
    mu0: float = 1e-6
    max_rejections: int = 30
    scaling: Literal["marquardt", "more", "levenberg"] = "marquardt"
    update: Literal["nielsen", "marquardt"] = "nielsen"


@dataclass
class LMResult:
    """Outcome of :func:`levenberg_marquardt`.

    Attributes
    ----------
    params
        Final parameter vector, float64 ``(n,)``.
    epochs
        Number of epochs run (one Jacobian each).
    loss
        Final ``E = ½ Σ r²`` [residual unit²].
    mse
        Final ``mean(r²)`` [residual unit²].
    stop_reason
        Why it stopped: ``"gradient"``, ``"step"``, ``"loss"`` (relative decrease below ``ftol``),
        ``"target"`` (``target_mse`` reached), ``"max_epochs"``, ``"monitor"`` (the caller's
        ``monitor`` said so) or ``"damping"`` (no step lowered
        the loss even at maximum damping: a numerical minimum). A rejected least-damped step whose
        predicted decrease is itself below ``ftol · E`` also stops with ``"loss"``.
    mse_history
        ``mean(r²)`` before the first epoch and after each one.
    n_residuals
        Number of residuals ``m``.
    """

    params: torch.Tensor
    epochs: int
    loss: float
    mse: float
    stop_reason: StopReason
    mse_history: list[float] = field(default_factory=list)
    n_residuals: int = 0


def _jacobian_fn(problem: LeastSquaresProblem | ResidualFn) -> ResidualJacobianFn:
    analytic = getattr(problem, "residuals_and_jacobian", None)
    if callable(analytic):
        return analytic  # type: ignore[no-any-return]
    fn: ResidualFn = problem.residuals if isinstance(problem, LeastSquaresProblem) else problem

    def via_jacfwd(w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        def both(p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            out = fn(p)
            return out, out

        jac, r = torch.func.jacfwd(both, has_aux=True)(w)
        return r, jac

    return via_jacfwd


NormalEqFn = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor, torch.Tensor]]


def _normal_equations_fn(problem: LeastSquaresProblem | ResidualFn) -> NormalEqFn:
    structured = getattr(problem, "normal_equations", None)
    if callable(structured):
        return structured  # type: ignore[no-any-return]
    res_jac = _jacobian_fn(problem)

    def from_jacobian(w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        r, J = res_jac(w)
        return r, J.T @ J, J.T @ r

    return from_jacobian


def levenberg_marquardt(
    problem: LeastSquaresProblem | ResidualFn,
    params0: torch.Tensor,
    *,
    options: LMOptions | None = None,
    callback: Callable[[int, float], None] | None = None,
    monitor: Callable[[int, torch.Tensor, float], bool] | None = None,
) -> LMResult:
    """Minimise ``½‖r(w)‖²`` by Levenberg–Marquardt from ``params0``.

    Parameters
    ----------
    problem
        Either an object with ``residuals(w) -> r`` (and optionally an analytic
        ``residuals_and_jacobian(w) -> (r, J)``) or a plain residual function.
    params0
        Starting parameters, ``(n,)``; converted to float64.
    options
        Stopping rules and damping; defaults to :class:`LMOptions`.
    callback
        Called as ``callback(epoch, mse)`` after each epoch (progress bars live in the caller).
    monitor
        Called as ``monitor(epoch, params, mse)`` after each accepted epoch; ``True`` stops the fit
        with ``stop_reason="monitor"`` (e.g. a validation test deciding early).

    Returns
    -------
    LMResult
    """
    opts = options or LMOptions()
    w = params0.detach().to(torch.float64).clone()
    fn: ResidualFn = problem.residuals if isinstance(problem, LeastSquaresProblem) else problem
    normal_eq = _normal_equations_fn(problem)

    r, JtJ, g = normal_eq(w)
    m = r.numel()
    loss = 0.5 * float(r @ r)
    history = [2.0 * loss / m]
    n = w.numel()
    diag_max = torch.zeros(n, dtype=torch.float64)
    damping = _Damping(opts.mu0)
    stop: StopReason = "max_epochs"
    epochs = 0
    if opts.target_mse is not None and history[0] <= opts.target_mse:
        return LMResult(w, 0, loss, history[0], "target", history, m)
    losses = [loss]  # E before the first epoch and after each accepted one
    window = max(1, opts.ftol_epochs)

    while epochs < opts.max_epochs:
        diag = torch.diagonal(JtJ)
        # MINPACK's gtol: |cos| between r and every Jacobian column (‖r‖ = √(2E))
        if bool(torch.all(g.abs() <= opts.gtol * torch.sqrt(diag.clamp_min(0.0) * (2.0 * loss)))):
            stop = "gradient"
            break
        scale, diag_max = _damping_scale(diag, diag_max, opts.scaling)
        epochs += 1
        step = _damped_step(fn, w, loss, JtJ, g, scale, damping, opts)
        if not isinstance(step, _Step):
            if step == "loss":
                history.append(history[-1])  # this epoch left the parameters unchanged
            stop = step
            break
        small_step = float(step.delta.norm()) <= opts.xtol * (float(w.norm()) + opts.xtol)
        w = step.w
        loss = step.loss
        losses.append(loss)
        small_drop = len(losses) > window and (
            losses[-1 - window] - loss <= opts.ftol * losses[-1 - window]
        )
        mse = 2.0 * loss / m
        history.append(mse)
        if callback is not None:
            callback(epochs, mse)
        if monitor is not None and monitor(epochs, w, mse):
            stop = "monitor"
            break
        if opts.target_mse is not None and mse <= opts.target_mse:
            stop = "target"
            break
        if small_step:
            stop = "step"
            break
        if small_drop:
            stop = "loss"
            break
        if epochs >= opts.max_epochs:
            break  # no new Jacobian that no step would use
        r, JtJ, g = normal_eq(w)
    return LMResult(w, epochs, loss, 2.0 * loss / m, stop, history, m)


@dataclass
class _Damping:
    """The damping ``mu`` and its growth factor ``nu`` (Nielsen), carried between epochs."""

    mu: float
    nu: float = 2.0


@dataclass(frozen=True)
class _Step:
    """An accepted step: its increment, the new parameters and their loss ``E``."""

    delta: torch.Tensor
    w: torch.Tensor
    loss: float


def _damping_scale(
    diag: torch.Tensor, diag_max: torch.Tensor, scaling: str
) -> tuple[torch.Tensor, torch.Tensor]:
    """The diagonal ``D`` the damping multiplies (``JᵀJ + μ·D``) and the running maximum of the
    curvature ``diag(JᵀJ)`` (kept by the Moré and Levenberg scalings)."""
    if scaling == "marquardt":
        d_max = float(diag.max())
        return torch.clamp(diag, min=1e-12 * d_max + 1e-300), diag_max
    diag_max = torch.maximum(diag_max, diag)
    d_max = float(diag_max.max())
    if scaling == "more":
        return torch.clamp(diag_max, min=1e-12 * d_max + 1e-300), diag_max
    # Levenberg: μ·I, μ relative to the largest curvature seen
    return torch.full_like(diag_max, d_max), diag_max


def _damped_step(
    fn: ResidualFn,
    w: torch.Tensor,
    loss: float,
    JtJ: torch.Tensor,
    g: torch.Tensor,
    scale: torch.Tensor,
    damping: _Damping,
    opts: LMOptions,
) -> _Step | StopReason:
    """One epoch's step: the damping raised until a step lowers the loss as the linear model
    predicts (the step), or ``"loss"`` (the least-damped step predicts no meaningful decrease
    and gets none: converged) or ``"damping"`` (``max_rejections`` steps rejected). Updates
    ``damping``."""
    for attempt in range(opts.max_rejections):
        A = JtJ.clone()
        A.diagonal().add_(scale, alpha=damping.mu)
        L, info = torch.linalg.cholesky_ex(A)
        if int(info) != 0:
            damping.mu *= damping.nu
            damping.nu *= 2.0
            continue
        delta = -torch.cholesky_solve(g.unsqueeze(1), L).squeeze(1)
        w_new = w + delta
        r_new = fn(w_new)
        loss_new = 0.5 * float(r_new @ r_new)
        # Predicted decrease of the linear model: ½ δᵀ(μ·D·δ − g)  (Madsen et al., eq. 3.14)
        predicted = 0.5 * float(delta @ (damping.mu * scale * delta - g))
        actual = loss - loss_new
        if actual > 0.0 and predicted > 0.0 and math.isfinite(loss_new):
            if opts.update == "nielsen":
                rho = actual / predicted
                damping.mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                damping.nu = 2.0
            else:  # Marquardt (1963): divide by 10 on success
                damping.mu = max(damping.mu / 10.0, 1e-12)
            return _Step(delta, w_new, loss_new)
        if attempt == 0 and math.isfinite(predicted) and predicted <= opts.ftol * loss:
            # the least-damped step predicts no meaningful decrease and gets none: converged
            # to rounding (MINPACK's relative-reduction test, Moré 1978)
            return "loss"
        if opts.update == "nielsen":
            damping.mu *= damping.nu
            damping.nu *= 2.0
        else:
            damping.mu *= 10.0
    return "damping"
