"""Lyapunov exponents of the stroboscopic map and the type of an attractor.

The stroboscopic map ``P: x(t0) -> x(t0 + T)`` of a forced system (paper eq. 6; model
document §6) turns every bounded steady motion into an attractor of a map: a P-k orbit
is a k-cycle, a quasi-periodic motion an invariant closed curve (a torus of the flow),
a chaotic motion a strange attractor. Their leading Lyapunov exponents tell them apart.

- :func:`lyapunov_spectrum` — the ``k`` largest exponents of ``P`` by the QR method of
  Benettin, Galgani, Giorgilli & Strelcyn (Meccanica 15, 9 and 21, 1980) and Shimada &
  Nagashima (Prog. Theor. Phys. 61, 1605, 1979): ``k`` orthonormal tangent vectors are
  pushed through the tangent map ``DP`` (``jax.jvp`` through the integrator's steps, so
  the kink-aware integrator's exact treatment of the backlash kinks is part of it) and
  re-orthonormalised by a QR decomposition every period; the exponents are the averages
  of ``ln |R_ii|``. Per forcing period and per unit time, with an error from the spread
  over independent stretches, and the Kaplan-Yorke dimension (Kaplan & Yorke, Lecture
  Notes in Math. 730, 204, 1979).
- :func:`classify_attractor` — periodic, quasi-periodic or chaotic, from the exponents
  and their errors.
"""

from __future__ import annotations

import enum

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._checks import check_bool, check_int, check_number, with_changes
from ._status import Status
from ._system import ForcedSystem, check_state_shape, check_system
from .integrate import AbstractIntegrator, resolve_integrator

__all__ = ["AttractorType", "LyapunovSpectrum", "LyapunovOptions", "lyapunov_spectrum", "classify_attractor", "type_reason", "kaplan_yorke",
           "ensemble_spectrum",
           "birkhoff_weights", "DEFAULT_ZERO_TOL"]

DEFAULT_ZERO_TOL = 1e-6
"""Exponents (per forcing period) within this of zero count as zero in
:func:`classify_attractor` even when their statistical error is smaller (round-off and
the integrator's own error put a floor under any estimate)."""

ZERO_FRACTION = 1e-4
"""Exponents within this fraction of the spectrum's largest magnitude count as zero in
:func:`classify_attractor`: a finite-time estimate of a torus's zero exponent keeps a bias
of order 1/(periods) that averaging over lanes on the same phase does not remove (the
near-resonant torus of the tests averages to 1e-6 +- 3e-7 beside a second exponent of
-0.39), and a largest exponent 10^4 times smaller than the contraction would need 10^4
e-foldings of that contraction to show."""


class AttractorType(enum.IntEnum):
    """Type of a bounded steady motion (an attractor of the stroboscopic map).

    ``UNKNOWN`` (-1): the trajectory blew up or the exponents are not finite;
    ``PERIODIC`` (0): a P-k orbit (a fixed point of ``P^k``; a stable one has a negative
    largest exponent); ``QUASI_PERIODIC`` (1): bounded, not periodic, largest exponent
    zero within its error and the next one negative beyond its error (an attracting
    invariant closed curve of ``P``: a torus of the flow); ``CHAOTIC`` (2): largest
    exponent positive beyond its error; ``UNDETERMINED`` (3): bounded, not periodic, the
    largest exponent zero within its error but the test for a closed curve fails (the
    second exponent is zero within its error too: a torus of higher dimension, or a
    slowly mixing set): not decided, never guessed (:func:`type_reason` says why).
    """

    UNKNOWN = -1
    PERIODIC = 0
    QUASI_PERIODIC = 1
    CHAOTIC = 2
    UNDETERMINED = 3

    @property
    def label(self) -> str:
        """``"periodic"``, ``"quasi-periodic"``, ``"chaotic"``, ``"undetermined"`` or ``"unknown"``."""
        return self.name.lower().replace("_", "-")


def attractor_label(period: int, kind) -> str:
    """The label of an attractor of ``period`` k (> 0: ``"P-k"``) and type ``kind`` (an
    :class:`AttractorType`): for period 0 ``"chaotic"``, ``"quasi-periodic"`` or
    ``"undetermined"``, and ``"aperiodic"`` where the type is unknown (or says periodic:
    a cycle longer than the periods searched)."""
    if int(period) > 0:
        return f"P-{int(period)}"
    return {int(AttractorType.CHAOTIC): "chaotic", int(AttractorType.QUASI_PERIODIC): "quasi-periodic",
            int(AttractorType.UNDETERMINED): "undetermined"}.get(int(kind), "aperiodic")


class LyapunovSpectrum(eqx.Module):
    """The leading Lyapunov exponents of the stroboscopic map from one or many initial states.

    Arrays have the batch shape ``(...)`` of the initial states in front.

    Attributes:
        exponents: ``(..., k)`` the ``k`` largest exponents of ``P`` per forcing period
            (dimensionless: the mean logarithmic stretching per iterate), in the order of
            the QR method: decreasing up to their errors (the two equal exponents of a
            complex pair of multipliers can come out in either order).
        per_time: ``(..., k)`` the same per unit time: ``exponents / T`` (``T`` the forcing
            period in the system's time unit; ``1/tau`` for the gear models).
        errors: ``(..., k)`` standard errors of ``exponents``: the standard deviation of
            the estimates of the ``stretches`` consecutive stretches divided by
            ``sqrt(stretches)``, per forcing period.
        errors_per_time: ``(..., k)`` the same per unit time (``errors / T``).
        stretch_exponents: ``(..., stretches, k)`` the estimate of each stretch.
        kaplan_yorke: ``(...)`` the Kaplan-Yorke (Lyapunov) dimension of the attractor of
            ``P`` from these exponents (:func:`kaplan_yorke`; add 1 for the flow); NaN when
            the ``k`` exponents computed do not determine it.
        final_state: ``(..., dim)`` the state after the last period.
        status: ``(...)`` int, a :class:`~jaxgear.Status`: ``CONVERGED``, or ``DIVERGED``
            when the trajectory or its tangent vectors became non-finite (its exponents
            are then NaN).
        periods: iterates of ``P`` averaged over (``stretches`` times the stretch length).
        transient: iterates of ``P`` run first and not averaged over.
        weighted: whether each stretch is a weighted Birkhoff average (see
            :func:`lyapunov_spectrum`).
    """

    exponents: Float[Array, "*batch k"]
    per_time: Float[Array, "*batch k"]
    errors: Float[Array, "*batch k"]
    errors_per_time: Float[Array, "*batch k"]
    stretch_exponents: Float[Array, "*batch stretches k"]
    kaplan_yorke: Float[Array, "*batch"]
    final_state: Float[Array, "*batch dim"]
    status: Int[Array, "*batch"]
    periods: int = eqx.field(static=True)
    transient: int = eqx.field(static=True)
    weighted: bool = eqx.field(static=True)


class LyapunovOptions(eqx.Module):
    """Options of :func:`lyapunov_spectrum` (immutable; checked at construction).

    Attributes:
        n_exponents: ``k``, the number of exponents (``1 <= k <= dim`` of the system).
        periods: iterates of ``P`` averaged over, a multiple of ``stretches``.
        transient: iterates run first (state only) to reach the attractor.
        stretches: number of stretches (>= 2) for the error estimate.
        weighted: weighted Birkhoff averages within each stretch (:func:`birkhoff_weights`).
        chunk_size: initial states integrated together in one compiled call (memory is
            bounded by it; the result does not depend on it).
    """

    n_exponents: int = eqx.field(static=True, default=2)
    periods: int = eqx.field(static=True, default=2000)
    transient: int = eqx.field(static=True, default=200)
    stretches: int = eqx.field(static=True, default=10)
    weighted: bool = eqx.field(static=True, default=True)
    chunk_size: int = eqx.field(static=True, default=1024)

    def __check_init__(self):
        check_int(self.n_exponents, "n_exponents", 1)
        stretches = check_int(self.stretches, "stretches", 2)
        periods = check_int(self.periods, "periods", stretches)
        if periods % stretches:
            raise ValueError(f"periods={periods} must be a multiple of stretches={stretches} "
                             "(each stretch averages the same number of iterates).")
        check_int(self.transient, "transient", 0)
        check_bool(self.weighted, "weighted")
        check_int(self.chunk_size, "chunk_size", 1)


def birkhoff_weights(n: int) -> np.ndarray:
    """Weights ``w_m``, ``m = 0..n-1``, of a weighted Birkhoff average, summing to 1:
    ``w(s) = exp(-1 / (s (1 - s)))`` at ``s = (m + 1/2) / n``.

    Das & Yorke, "Super convergence of ergodic averages for quasiperiodic orbits",
    Nonlinearity 31, 491 (2018); Das, Saiki, Sander & Yorke, Discrete Contin. Dyn. Syst.
    S 12, 2019. For a quantity along a quasi-periodic orbit (or a periodic one) that is a
    smooth function of the phase, the weighted average converges faster than any power
    of ``n``; the plain average converges as ``1/n`` (the finite-time exponents of a
    complex pair of multipliers, or of an invariant circle, oscillate about their limit
    with an amplitude ``~ 1/n``). For a chaotic orbit both converge as ``1/sqrt(n)``.
    """
    n = check_int(n, "n", 1)
    s = (np.arange(n, dtype=np.float64) + 0.5) / n
    w = np.exp(-1.0 / (s * (1.0 - s)))
    return w / w.sum()


def kaplan_yorke(exponents: Float[ArrayLike, "*batch k"]) -> Float[Array, "*batch"]:
    """Kaplan-Yorke dimension ``D = j + (lambda_1 + ... + lambda_j) / |lambda_{j+1}|``.

    ``exponents (..., k)`` in decreasing order; ``j`` is the largest index whose partial
    sum ``lambda_1 + ... + lambda_j`` is non-negative (Kaplan & Yorke 1979; Frederickson,
    Kaplan, Yorke & Yorke, J. Differ. Equations 49, 185, 1983). ``D = 0`` when
    ``lambda_1 < 0`` (a stable periodic orbit is a set of points of ``P``). NaN when
    ``j = k`` (every partial sum of the ``k`` exponents is non-negative: more exponents
    are needed) or an exponent is not finite. The dimension of the attractor of the
    stroboscopic map; the flow's is one more.
    """
    return _kaplan_yorke(jnp.asarray(exponents, jnp.float64))


@jax.jit
def _kaplan_yorke(lam):
    k = lam.shape[-1]
    partial = jnp.cumsum(lam, axis=-1)
    j = jnp.sum(jnp.cumprod(partial >= 0.0, axis=-1), axis=-1)  # leading run of non-negative sums
    idx = jnp.clip(j, 1, k) - 1
    s_j = jnp.take_along_axis(partial, idx[..., None], axis=-1)[..., 0]
    nxt = jnp.take_along_axis(lam, jnp.clip(j, 0, k - 1)[..., None], axis=-1)[..., 0]
    d = jnp.where(j == 0, 0.0, j.astype(jnp.float64) + s_j / jnp.abs(nxt))
    ok = jnp.all(jnp.isfinite(lam), axis=-1) & (j < k)
    return jnp.where(ok, d, jnp.nan)


def _tangent_period(system, params, integrator, t0, Y, V):
    """One period of the state ``Y (dim, L)`` and its tangent vectors ``V (k, dim, L)``:
    ``P(Y)`` and ``DP(Y) V`` by ``jax.jvp`` through ``integrator.advance`` (the state is
    computed once: it does not depend on the tangent being mapped)."""
    def f(Z):
        return integrator.advance(system, params, Z, t0, 1)

    return jax.vmap(lambda v: jax.jvp(f, (Y,), (v,)), out_axes=(None, 0))(V)


@eqx.filter_jit
def _lyapunov_kernel(system, params, Y, t0, k, transient, stretches, weights, integrator):
    """The exponents of ``L`` lanes ``Y (dim, L)``: ``(stretches, L, k)`` stretch estimates
    and the final states. Tangent vectors start as the first ``k`` unit vectors; each
    period ``Q R = DP(x) Q`` and ``ln |R_ii|`` is accumulated with the stretch's weight."""
    dim, L = Y.shape
    if transient:
        Y = integrator.advance(system, params, Y, t0, transient)
    V = jnp.broadcast_to(jnp.eye(dim, k, dtype=Y.dtype).T[:, :, None], (k, dim, L))

    def one_period(carry, w):
        Y, V, acc = carry
        Y1, W = _tangent_period(system, params, integrator, t0, Y, V)
        A = jnp.transpose(W, (2, 1, 0))  # (L, dim, k)
        Q, R = jnp.linalg.qr(A)
        logs = jnp.log(jnp.abs(jnp.diagonal(R, axis1=-2, axis2=-1)))  # (L, k)
        return (Y1, jnp.transpose(Q, (2, 1, 0)), acc + w * logs), None

    def one_stretch(carry, _):
        Y, V = carry
        (Y, V, acc), _ = jax.lax.scan(one_period, (Y, V, jnp.zeros((L, k), Y.dtype)), weights)
        return (Y, V), acc

    (Y, V), est = jax.lax.scan(one_stretch, (Y, V), None, length=stretches)
    return est, Y


def lyapunov_spectrum(system: ForcedSystem, params, x0: Float[ArrayLike, "*batch dim"], *, t0: float = 0.0,
                      integrator: AbstractIntegrator | None = None, options: LyapunovOptions | None = None,
                      **changes) -> LyapunovSpectrum:
    """The ``n_exponents`` largest Lyapunov exponents of the stroboscopic map from ``x0``.

    ``P: x(t0) -> x(t0 + T)`` is the one-period map of the forced system (paper eq. 6;
    model document §6). After ``transient`` iterates from ``x0`` (not averaged), ``k =
    n_exponents`` orthonormal tangent vectors ``Q_n`` are mapped by the tangent map and
    re-orthonormalised every period, ``Q_{n+1} R_{n+1} = DP(x_n) Q_n`` (QR, Benettin et al.
    1980; Shimada & Nagashima 1979; as ChaosTools' ``lyapunovspectrum``), and
    ``lambda_i = <ln |R_{n+1, ii}|>`` over ``periods`` iterates. ``DP`` is ``jax.jvp``
    through the integrator's steps: with :class:`~jaxgear.KinkAwareRK4` (the default)
    its steps stop on the backlash surfaces, so the tangent dynamics includes the
    saltation there (the identity for the gear models' kinks, model document §8; the
    full saltation matrix for a ``field_jumps`` system). The forcing is ``T``-periodic, so
    every period starts at ``t0``.

    The ``periods`` iterates are cut into ``stretches`` consecutive stretches of equal
    length; each stretch gives an estimate (the tangent vectors run on from one stretch
    to the next), ``exponents`` is their mean and ``errors`` its standard error. With
    ``weighted=True`` (default) each stretch's average is a weighted Birkhoff average
    (:func:`birkhoff_weights`, Das & Yorke 2018): the exponents of periodic and
    quasi-periodic attractors then converge to round-off within a few hundred periods
    (the plain average converges as ``1/periods``), those of chaotic ones as the plain
    average does (``1/sqrt(periods)``, with about twice the error: for long runs on a
    chaotic attractor the plain average is the more efficient). With ``weighted=False``
    each stretch is the plain finite-time exponent.

    For a P-k orbit the exponents are ``ln |mu_i| / k`` of its Floquet multipliers ``mu_i``
    (sorted by modulus); a complex pair gives two equal exponents.

    Args:
        system: any :class:`~jaxgear.ForcedSystem`.
        params: its parameter pytree (one set, not batched).
        x0: initial states ``(..., dim)`` at time ``t0``.
        t0: phase of the stroboscopic section (system time unit).
        integrator: default :func:`~jaxgear.integrate.default_integrator`.
        options: :class:`LyapunovOptions` (``n_exponents`` ``k``, ``periods``,
            ``transient``, ``stretches``, ``weighted``, ``chunk_size``); ``None``: the defaults.
        **changes: fields of ``options`` to change, e.g. ``n_exponents=4, periods=500``.
    Returns:
        a :class:`LyapunovSpectrum` with the batch shape of ``x0``.
    """
    opts = with_changes(options, LyapunovOptions, changes)
    check_state_shape(system, x0)
    k = check_int(opts.n_exponents, "n_exponents", 1, system.dim)
    periods, stretches, transient, chunk_size = opts.periods, opts.stretches, opts.transient, opts.chunk_size
    t0 = check_number(t0, "t0")
    integrator = resolve_integrator(integrator)
    x0 = jnp.asarray(x0, jnp.float64)
    lead = x0.shape[:-1]
    check_system(system, params, x0)
    X = x0.reshape(-1, system.dim)
    n = X.shape[0]
    length = periods // stretches
    w = birkhoff_weights(length) if opts.weighted else np.full(length, 1.0 / length)
    weights = jnp.asarray(w, jnp.float64)
    T = jnp.asarray(system.period(params), jnp.float64)
    ests, finals = [], []
    for start in range(0, n, chunk_size):
        Xc = X[start:start + chunk_size]
        est, Yf = _lyapunov_kernel(system, params, Xc.T, jnp.asarray(t0, jnp.float64), k, transient, stretches,
                                   weights, integrator)
        ests.append(jnp.transpose(est, (1, 0, 2)))  # (L, stretches, k)
        finals.append(Yf.T)
    est = jnp.concatenate(ests, axis=0)
    final = jnp.concatenate(finals, axis=0)
    ok = jnp.all(jnp.isfinite(est), axis=(1, 2)) & jnp.all(jnp.isfinite(final), axis=1)
    est = jnp.where(ok[:, None, None], est, jnp.nan)
    lam = jnp.mean(est, axis=1)
    err = jnp.std(est, axis=1, ddof=1) / np.sqrt(stretches)
    status = jnp.where(ok, int(Status.CONVERGED), int(Status.DIVERGED)).astype(jnp.int32)
    return LyapunovSpectrum(
        exponents=lam.reshape(*lead, k), per_time=(lam / T).reshape(*lead, k), errors=err.reshape(*lead, k),
        errors_per_time=(err / T).reshape(*lead, k),
        stretch_exponents=est.reshape(*lead, stretches, k), kaplan_yorke=kaplan_yorke(lam).reshape(lead),
        final_state=final.reshape(*lead, system.dim), status=status.reshape(lead), periods=periods,
        transient=transient, weighted=opts.weighted)


def ensemble_spectrum(spectrum: LyapunovSpectrum, groups: ArrayLike) -> LyapunovSpectrum:
    """The spectra of many starts on the same attractors pooled, one per attractor: lane
    ``j`` of ``spectrum`` (batch ``(n,)``) lies on attractor ``groups[j]`` (``0..G-1``).

    The exponents of a group are the mean over its converged lanes; their error is the
    spread between those independent lanes, ``std / sqrt(lanes)`` (a group of one lane
    keeps that lane's error from its stretches). ``stretch_exponents`` holds the group's
    mean per stretch, ``final_state`` its first converged lane's; a group without a
    converged lane is ``DIVERGED`` with NaN exponents. Returns a spectrum of batch ``(G,)``."""
    groups = np.asarray(groups, np.int64)
    G = int(groups.max(initial=-1)) + 1
    ok = (np.asarray(spectrum.status) == int(Status.CONVERGED)) & np.all(np.isfinite(spectrum.exponents), axis=-1)
    members = [np.flatnonzero((groups == g) & ok) for g in range(G)]

    def pooled(values, errors=None):
        values = np.asarray(values)
        mean = np.full((G,) + values.shape[1:], np.nan)
        err = np.full_like(mean, np.nan)
        for g, lanes in enumerate(members):
            if lanes.size:
                mean[g] = values[lanes].mean(axis=0)
                if errors is not None:
                    err[g] = (values[lanes].std(axis=0, ddof=1) / np.sqrt(lanes.size) if lanes.size > 1
                              else np.asarray(errors)[lanes[0]])
        return mean, err

    lam, err = pooled(spectrum.exponents, spectrum.errors)
    per_time, err_time = pooled(spectrum.per_time, spectrum.errors_per_time)
    final = np.full((G, np.asarray(spectrum.final_state).shape[-1]), np.nan)
    for g, lanes in enumerate(members):
        if lanes.size:
            final[g] = np.asarray(spectrum.final_state)[lanes[0]]
    status = np.array([int(Status.CONVERGED) if lanes.size else int(Status.DIVERGED) for lanes in members], np.int32)
    return LyapunovSpectrum(
        exponents=jnp.asarray(lam), per_time=jnp.asarray(per_time), errors=jnp.asarray(err),
        errors_per_time=jnp.asarray(err_time), stretch_exponents=jnp.asarray(pooled(spectrum.stretch_exponents)[0]),
        kaplan_yorke=kaplan_yorke(jnp.asarray(lam)), final_state=jnp.asarray(final), status=jnp.asarray(status),
        periods=spectrum.periods, transient=spectrum.transient, weighted=spectrum.weighted)


def _zero_floor(exponents, zero_tol):
    """What counts as zero beside a spectrum: ``zero_tol`` or :data:`ZERO_FRACTION` of its
    largest magnitude, whichever is larger (one per spectrum of a batch)."""
    scale = np.max(np.abs(np.nan_to_num(np.asarray(exponents, float))), axis=-1)
    return np.maximum(zero_tol, ZERO_FRACTION * scale)


def classify_attractor(spectrum: LyapunovSpectrum, period: int | ArrayLike | None = None, *,
                       n_sigma: float = 3.0, zero_tol: float = DEFAULT_ZERO_TOL):
    """The type of the attractor a :class:`LyapunovSpectrum` was computed on.

    - ``PERIODIC`` when ``period`` (the k of a P-k orbit found on the attractor, e.g. by
      the cell map or by shooting) is given, or when the largest exponent is negative
      beyond its error (a stable periodic orbit whose period was not determined);
    - ``CHAOTIC`` when the largest exponent is positive beyond its error:
      ``lambda_1 > max(n_sigma * error_1, floor)``;
    - ``QUASI_PERIODIC`` when it is zero within its error,
      ``|lambda_1| <= max(n_sigma * error_1, floor)`` (the trajectory stayed bounded:
      its status is ``CONVERGED``), no period is given, and the attractor is a closed
      curve of the map: the second exponent is negative beyond its error,
      ``lambda_2 < -max(n_sigma * error_2, floor)`` (a spectrum of one exponent has no
      second: the first test alone decides);
    - ``UNDETERMINED`` when the first exponent is zero within its error and the second
      is too (not a closed curve: not decided; :func:`type_reason` says so);
    - ``UNKNOWN`` when the trajectory diverged.

    Exponents per forcing period; ``floor`` is what counts as zero: the larger of
    ``zero_tol`` (per forcing period, :data:`DEFAULT_ZERO_TOL`) and :data:`ZERO_FRACTION`
    of the spectrum's largest magnitude. For a single spectrum (no batch axes)
    returns an :class:`AttractorType`; for a batch, an int array of their values, with
    ``period`` ``None`` or an int array (values ``<= 0`` mean "no period found").
    """
    n_sigma = check_number(n_sigma, "n_sigma", 0.0)
    zero_tol = check_number(zero_tol, "zero_tol", 0.0)
    if not isinstance(spectrum, LyapunovSpectrum):
        raise ValueError(f"spectrum must be a LyapunovSpectrum (from lyapunov_spectrum), got {type(spectrum).__name__}.")
    lam1 = np.asarray(spectrum.exponents)[..., 0]
    err1 = np.asarray(spectrum.errors)[..., 0]
    status = np.asarray(spectrum.status)
    if period is None:
        has_period = np.zeros(lam1.shape, bool)
    else:
        p = np.asarray(period)
        if not np.issubdtype(p.dtype, np.integer):
            raise ValueError(f"period={period!r} must be an int (the k of a P-k orbit) or None.")
        has_period = np.broadcast_to(p > 0, lam1.shape)
    exps, errs = np.asarray(spectrum.exponents), np.asarray(spectrum.errors)
    floor = _zero_floor(exps, zero_tol)
    tol = np.maximum(n_sigma * err1, floor)
    good = (status == int(Status.CONVERGED)) & np.isfinite(lam1) & np.isfinite(err1)
    if exps.shape[-1] >= 2:  # a closed curve: contracting across it
        curve = exps[..., 1] < -np.maximum(n_sigma * errs[..., 1], floor)
    else:
        curve = np.ones(lam1.shape, bool)
    zero = np.where(curve, int(AttractorType.QUASI_PERIODIC), int(AttractorType.UNDETERMINED))
    code = np.where(lam1 > tol, int(AttractorType.CHAOTIC), np.where(lam1 < -tol, int(AttractorType.PERIODIC), zero))
    code = np.where(has_period, int(AttractorType.PERIODIC), code)
    code = np.where(good, code, int(AttractorType.UNKNOWN)).astype(np.int32)
    if code.ndim == 0:
        return AttractorType(int(code))
    return code


def type_reason(kind, exponents, errors, period: int = 0, *, n_sigma: float = 3.0,
                zero_tol: float = DEFAULT_ZERO_TOL) -> str:
    """One sentence saying why an attractor has the type ``kind`` (an
    :class:`AttractorType`) that :func:`classify_attractor` gave it from its leading
    ``exponents`` and their ``errors`` (per forcing period) and its ``period`` (> 0: a
    P-k cycle), with the numbers the test compared."""
    kind = AttractorType(int(kind))
    lam, err = np.atleast_1d(np.asarray(exponents, float)), np.atleast_1d(np.asarray(errors, float))
    if kind is AttractorType.PERIODIC and period > 0:
        return f"a P-{int(period)} cycle (a fixed point of P^{int(period)})"
    if kind is AttractorType.UNKNOWN or not len(lam):
        return "not measured, or the trajectory blew up"
    one = f"lambda_1 = {lam[0]:+.4g} +- {err[0]:.2g}"
    bound = max(n_sigma * err[0], float(_zero_floor(lam, zero_tol)))
    if kind is AttractorType.CHAOTIC:
        return f"{one}: positive beyond {n_sigma:g} errors ({bound:.2g})"
    if kind is AttractorType.PERIODIC:
        return f"{one}: negative beyond {n_sigma:g} errors, no period found (a cycle of a longer period)"
    two = f"lambda_2 = {lam[1]:+.4g} +- {err[1]:.2g}" if len(lam) > 1 else ""
    if kind is AttractorType.QUASI_PERIODIC:
        return f"{one}: zero within {n_sigma:g} errors" + (f"; {two}: negative beyond them (a closed curve)"
                                                            if two else "")
    return (f"{one} and {two}: both zero within {n_sigma:g} errors (not a closed curve of the map: a torus of "
            "higher dimension or a slowly mixing set), not decided")
