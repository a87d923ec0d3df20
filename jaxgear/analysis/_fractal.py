"""Fractal basin measures: basin entropy, boundary basin entropy, uncertainty exponent.

How unpredictable the final state is near the basin boundaries of a global result:

- :func:`basin_entropy` — the basin entropy ``S_b`` and the boundary basin entropy
  ``S_bb`` of a label array (Daza, Wagemakers, Georgeot, Guéry-Odelin & Sanjuán,
  "Basin entropy: a new tool to analyze uncertainty in dynamical systems", Sci. Rep. 6,
  31416, 2016), with their log 2 criterion: ``S_bb > ln 2`` is a sufficient condition for
  a fractal basin boundary;
- :func:`uncertain_fraction` — the share ``f(eps)`` of random initial states whose
  outcome changes when they move by ``eps`` (Grebogi, McDonald, Ott & Yorke, "Final
  state sensitivity: an obstruction to predictability", Phys. Lett. A 99, 415, 1983);
- :func:`uncertainty_exponent` — ``alpha`` of ``f(eps) ~ eps^alpha`` by a log-log least
  squares fit with its standard error; ``alpha = D - d`` (state dimension minus the box
  dimension of the boundary): 1 for a smooth boundary, below 1 for a fractal one;
- :func:`scaling_range` — that fit over the widest run of ``eps`` where the power law
  holds within the counting errors (not where ``f`` saturates), or no exponent at all.

Plain numpy: these read label arrays (any number of dimensions) or call a labelling
function; the expensive part, the labels, comes from the global analysis.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from .._checks import check_finite_array, check_int

__all__ = ["BasinEntropy", "basin_entropy", "UncertaintyExponent", "uncertainty_exponent", "uncertain_fraction",
           "ScalingRange", "scaling_range", "LOG2", "MAX_REDUCED_CHI2"]

LOG2 = float(np.log(2.0))
"""``ln 2``: a boundary basin entropy above it proves a fractal boundary (Daza et al. 2016)."""


class BasinEntropy(NamedTuple):
    """Result of :func:`basin_entropy` (all entropies in nats).

    Attributes:
        S_b: basin entropy, the mean over all boxes of the Gibbs entropy of the outcomes in
            a box, ``S_i = -sum_j p_ij ln p_ij``.
        S_bb: boundary basin entropy, the mean of ``S_i`` over the boxes holding more than
            one outcome (NaN when there are none).
        n_boxes: boxes of ``box^d`` cells in the grid (cells beyond a whole number of boxes
            along an axis are left out).
        n_boundary_boxes: boxes holding more than one outcome.
        n_outcomes: distinct outcomes (labels) that count.
        box: cells per box side.
    """

    S_b: float
    S_bb: float
    n_boxes: int
    n_boundary_boxes: int
    n_outcomes: int
    box: int

    @property
    def fractal(self) -> bool:
        """``S_bb > ln 2``: the log 2 criterion, a sufficient (not a necessary) condition for
        a fractal boundary (Daza et al. 2016). ``False`` does not prove a smooth one."""
        return bool(self.S_bb > LOG2)

    def __repr__(self) -> str:
        return (f"BasinEntropy(S_b={self.S_b:.4f}, S_bb={self.S_bb:.4f}, fractal={self.fractal}, "
                f"n_boxes={self.n_boxes}, n_boundary_boxes={self.n_boundary_boxes}, n_outcomes={self.n_outcomes}, "
                f"box={self.box})")


def basin_entropy(labels, box: int = 5, *, ignore: Sequence[int] = ()) -> BasinEntropy:
    """Basin entropy ``S_b`` and boundary basin entropy ``S_bb`` of a label array (Daza et al. 2016).

    The grid of ``labels`` (any number ``d`` of dimensions, one integer outcome per cell,
    e.g. :attr:`~jaxgear.GlobalResult.labels` reshaped to the grid) is covered by
    non-overlapping boxes of ``box^d`` cells. In box ``i`` with ``p_ij`` the share of its
    cells with outcome ``j``, ``S_i = -sum_j p_ij ln p_ij``; ``S_b`` is the mean of ``S_i``
    over all boxes and ``S_bb`` over the boxes that hold more than one outcome. ``S_bb >
    ln 2`` proves a fractal boundary (:attr:`BasinEntropy.fractal`). Daza et al. use
    ``box = 5`` on grids of a few hundred cells a side; ``S_b`` depends on the box
    and the grid, so compare values computed with the same ones.

    The reserved labels of a global result (``SINK = -1``: the orbit left the region;
    ``UNRESOLVED = -2``: not decided in time) are outcomes like any other by default:
    escaping is a final state (Daza et al. treat escape as one in open systems), and
    leaving the undecided cells out would hide exactly the cells near a boundary.
    ``ignore`` lists labels to leave out instead (each box's shares are then over its
    other cells; a box with none left does not count).

    Args:
        labels: integer array, ``d >= 1`` dimensions, each at least ``box`` cells long.
        box: cells per box side (>= 2).
        ignore: labels left out of the shares.
    Returns:
        a :class:`BasinEntropy`.
    """
    box = check_int(box, "box", 2)
    lab = np.asarray(labels)
    if lab.ndim == 0 or not (np.issubdtype(lab.dtype, np.integer) or np.issubdtype(lab.dtype, np.bool_)):
        raise ValueError(f"labels must be an integer array of at least one dimension, got dtype {lab.dtype} "
                         f"and shape {lab.shape}.")
    if min(lab.shape) < box:
        raise ValueError(f"box={box} is larger than the label grid {lab.shape}: every axis needs at least "
                         f"box cells.")
    d = lab.ndim
    nb = [n // box for n in lab.shape]
    lab = lab[tuple(slice(0, m * box) for m in nb)]
    # (nb_0, box, nb_1, box, ...) -> (boxes, cells per box)
    lab = lab.reshape([v for m in nb for v in (m, box)])
    lab = lab.transpose(list(range(0, 2 * d, 2)) + list(range(1, 2 * d, 2))).reshape(int(np.prod(nb)), box**d)
    keep = ~np.isin(lab, np.asarray(list(ignore), dtype=np.int64)) if len(ignore) else np.ones(lab.shape, bool)
    values, inv = np.unique(lab[keep], return_inverse=True)
    m = len(values)
    rows = np.nonzero(keep)[0]
    counts = np.bincount(rows * max(m, 1) + inv, minlength=lab.shape[0] * max(m, 1)).reshape(lab.shape[0], max(m, 1))
    total = counts.sum(axis=1)
    counted = total > 0
    p = counts[counted] / total[counted, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        S = -np.sum(np.where(p > 0, p * np.log(np.where(p > 0, p, 1.0)), 0.0), axis=1)
    boundary = np.count_nonzero(counts[counted] > 0, axis=1) > 1
    n_boxes = int(np.count_nonzero(counted))
    S_b = float(S.mean()) if n_boxes else float("nan")
    S_bb = float(S[boundary].mean()) if boundary.any() else float("nan")
    return BasinEntropy(S_b, S_bb, n_boxes, int(boundary.sum()), int(m), box)


class UncertaintyExponent(NamedTuple):
    """Result of :func:`uncertainty_exponent`.

    Attributes:
        alpha: the uncertainty exponent, slope of ``ln f`` against ``ln eps``.
        alpha_err: its standard error (from the fit; see :func:`uncertainty_exponent`).
        log_prefactor: the intercept ``ln c`` of ``f = c eps^alpha``, with ``log_prefactor_err``.
        eps, fraction: the data fitted, ``(m,)`` each.
        n_samples: samples behind each fraction ``(m,)`` (``None``: unweighted fit).
        reduced_chi2: ``chi^2 / (m - 2)`` of the weighted fit with the binomial errors
            (about 1 where the power law holds; NaN for the unweighted fit).

    ``state_dim - alpha`` is the box dimension of the boundary (:meth:`dimension`).
    """

    alpha: float
    alpha_err: float
    log_prefactor: float
    log_prefactor_err: float
    eps: np.ndarray
    fraction: np.ndarray
    n_samples: np.ndarray | None
    reduced_chi2: float = float("nan")

    def dimension(self, state_dim: int) -> float:
        """Box dimension of the basin boundary, ``state_dim - alpha`` (Grebogi et al. 1983;
        McDonald, Grebogi, Ott & Yorke, Physica D 17, 125, 1985)."""
        return int(state_dim) - self.alpha

    def __repr__(self) -> str:
        return f"UncertaintyExponent(alpha={self.alpha:.4f} +- {self.alpha_err:.4f}, points={len(self.eps)})"


def _fractions(eps, f_uncertain, n_samples):
    """``eps``, ``f_uncertain`` and ``n_samples`` (``None`` or broadcast to ``eps``) checked:
    one length, ``eps > 0``, ``f`` in ``[0, 1]``, integer sample counts >= 1."""
    x = check_finite_array(eps, "eps", ndim=1)
    f = check_finite_array(f_uncertain, "f_uncertain", ndim=1)
    if x.shape != f.shape:
        raise ValueError(f"eps and f_uncertain must have the same length, got {x.shape[0]} and {f.shape[0]}.")
    if np.any(x <= 0):
        raise ValueError(f"eps must be positive, got {x.tolist()}.")
    if np.any(f < 0) or np.any(f > 1):
        raise ValueError(f"f_uncertain must lie in [0, 1], got {f.tolist()}.")
    if n_samples is None:
        return x, f, None
    n = np.broadcast_to(np.asarray(n_samples), x.shape)
    if not np.issubdtype(n.dtype, np.integer) or np.any(n < 1):
        raise ValueError(f"n_samples must be None or integers >= 1, got {n_samples!r}.")
    return x, f, n


def uncertainty_exponent(eps, f_uncertain, n_samples=None) -> UncertaintyExponent:
    """The uncertainty exponent ``alpha`` of ``f(eps) ~ c eps^alpha`` (Grebogi et al. 1983).

    A straight-line least-squares fit of ``ln f`` against ``ln eps``. Without
    ``n_samples`` the fit is unweighted and the standard errors come from the residuals
    (``m - 2`` degrees of freedom: ``m >= 3`` points needed). With ``n_samples`` (the
    number of sampled states behind each fraction, a scalar or ``(m,)``) each point is
    weighted by its binomial error, ``var(ln f) = (1 - f) / (n f)``, and the standard
    errors are those of the weighted fit, scaled up by ``sqrt(chi^2 / (m - 2))`` when that
    exceeds 1 (a fit worse than the counting errors allow: the power law does not hold
    exactly over the range). Use ``eps`` over a decade or more.

    Args:
        eps: perturbation sizes ``(m,)``, positive.
        f_uncertain: uncertain fractions ``(m,)`` in ``(0, 1]`` (a zero has no logarithm:
            use more samples or larger ``eps``).
        n_samples: ``None``, or samples per fraction (int or ``(m,)`` ints >= 1).
    Returns:
        an :class:`UncertaintyExponent`.
    """
    x, f, n = _fractions(eps, f_uncertain, n_samples)
    if len(x) < 3:
        raise ValueError(f"eps must hold at least 3 perturbation sizes for a fit with an error, got {len(x)}.")
    if np.any(f <= 0):
        raise ValueError(f"f_uncertain must lie in (0, 1] (a zero fraction has no logarithm: sample more states "
                         f"or use larger eps), got {f.tolist()}.")
    lx, ly = np.log(x), np.log(f)
    A = np.stack([np.ones_like(lx), lx], axis=1)
    m = len(x)
    if n_samples is None:
        coef, *_ = np.linalg.lstsq(A, ly, rcond=None)
        r = ly - A @ coef
        s2 = float(r @ r) / (m - 2)
        cov = s2 * np.linalg.inv(A.T @ A)
        n, chi2 = None, float("nan")
    else:
        var = (1.0 - f) / (n * f)
        w = 1.0 / np.maximum(var, 1.0 / (n * n))  # f = 1 has no binomial spread: one sample's worth
        Aw = A * w[:, None]
        cov = np.linalg.inv(A.T @ Aw)
        coef = cov @ (Aw.T @ ly)
        r = ly - A @ coef
        chi2 = float(np.sum(w * r * r)) / (m - 2)
        cov = cov * max(1.0, chi2)
        n = n.copy()
    return UncertaintyExponent(float(coef[1]), float(np.sqrt(cov[1, 1])), float(coef[0]), float(np.sqrt(cov[0, 0])),
                               x, f, n, chi2)


MAX_REDUCED_CHI2 = 3.0
"""The largest reduced ``chi^2`` of a power-law fit that :func:`scaling_range` accepts
(about the 95 % point of ``chi^2 / nu`` for ``nu = 2`` degrees of freedom, 99 % for 6)."""


class ScalingRange(NamedTuple):
    """Result of :func:`scaling_range`.

    Attributes:
        alpha, alpha_err: the uncertainty exponent over the range and its standard error
            (NaN: no range).
        eps_min, eps_max: the smallest and the largest ``eps`` of the range (NaN: none).
        reduced_chi2: ``chi^2 / (points - 2)`` of the fit over the range (NaN: none).
        used: ``(m,)`` bool, the points of the range (in the order given).
        reason: ``None`` when a range was found, else why none was
            (``"no scaling range: ..."``).
        fit: the :class:`UncertaintyExponent` over the range (``None``: none).
    """

    alpha: float
    alpha_err: float
    eps_min: float
    eps_max: float
    reduced_chi2: float
    used: np.ndarray
    reason: str | None
    fit: UncertaintyExponent | None

    def __repr__(self) -> str:
        if self.fit is None:
            return f"ScalingRange({self.reason})"
        return (f"ScalingRange(alpha={self.alpha:.4f} +- {self.alpha_err:.4f}, eps={self.eps_min:.3g}..{self.eps_max:.3g}, "
                f"reduced_chi2={self.reduced_chi2:.2f}, points={int(self.used.sum())})")


def scaling_range(eps, f_uncertain, n_samples, *, min_points: int = 4, min_decades: float = 3.0,
                  max_chi2: float = MAX_REDUCED_CHI2) -> ScalingRange:
    """The uncertainty exponent over the scaling range of ``f(eps)`` (Grebogi, McDonald, Ott
    & Yorke 1983).

    ``f ~ eps^alpha`` holds only for moves small against the basins' structure; at larger
    ``eps`` the uncertain fraction saturates (and at smaller ones it may drop to zero
    samples). The range is the widest run of consecutive ``eps`` (sorted) with at least
    ``min_points`` points over at least ``min_decades`` decades, every fraction above zero,
    where the weighted fit of :func:`uncertainty_exponent` (binomial errors from
    ``n_samples``) is consistent, ``chi^2 / (points - 2) <= max_chi2``, and ``f`` rises,
    ``alpha > 3`` standard errors (a flat ``f`` is saturation, not scaling). The widest
    run has the most decades, then the most points, then the smallest ``chi^2``. Where
    none qualifies, ``alpha`` is NaN and ``reason`` says why. A bend of ``f`` smaller than
    its counting errors cannot be told from the power law and may end up in the range.

    Args:
        eps: perturbation sizes ``(m,)``, positive.
        f_uncertain: uncertain fractions ``(m,)`` in ``[0, 1]``.
        n_samples: samples per fraction (int or ``(m,)`` ints >= 1).
        min_points, min_decades, max_chi2: what a scaling range needs (see above).
    Returns:
        a :class:`ScalingRange`.
    """
    if n_samples is None:
        raise ValueError("n_samples must be given: the scaling range is judged by the counting errors.")
    x, f, n = _fractions(eps, f_uncertain, n_samples)
    min_points = check_int(min_points, "min_points", 3)
    order = np.argsort(x, kind="stable")
    xs, fs, ns = x[order], f[order], n[order]
    m = len(xs)
    best, best_key, candidates, consistent = None, None, 0, 0
    for i in range(m):
        for j in range(i + min_points, m + 1):  # the run xs[i:j]
            if np.any(fs[i:j] <= 0):
                break  # a zero fraction ends every run through it
            decades = float(np.log10(xs[j - 1] / xs[i]))
            if decades < min_decades - 1e-9:
                continue
            candidates += 1
            u = uncertainty_exponent(xs[i:j], fs[i:j], n_samples=ns[i:j])
            if not u.reduced_chi2 <= max_chi2:
                continue
            consistent += 1
            if not u.alpha > 3.0 * u.alpha_err:
                continue
            key = (round(decades, 9), j - i, -u.reduced_chi2)
            if best_key is None or key > best_key:
                best, best_key = (i, j, u), key
    if best is None:
        if candidates == 0:
            why = f"fewer than {min_points} nonzero fractions in a row over {min_decades:g} decades"
        elif consistent == 0:
            why = (f"no run of {min_points} or more fractions over {min_decades:g} decades fits a power law "
                   f"(reduced chi^2 above {max_chi2:g})")
        else:
            why = "f(eps) does not rise where a power law fits (alpha within 3 errors of 0: saturated)"
        return ScalingRange(float("nan"), float("nan"), float("nan"), float("nan"), float("nan"),
                            np.zeros(m, bool), f"no scaling range: {why}", None)
    i, j, u = best
    used = np.zeros(m, bool)
    used[order[i:j]] = True
    return ScalingRange(u.alpha, u.alpha_err, float(xs[i]), float(xs[j - 1]), u.reduced_chi2, used, None, u)


def uncertain_fraction(label_fn: Callable[[np.ndarray], np.ndarray], low, high, eps, *, n_samples: int = 2000,
                       seed: int = 0) -> np.ndarray:
    """Share ``f(eps)`` of random initial states whose outcome depends on a perturbation of size ``eps``.

    Grebogi, McDonald, Ott & Yorke (1983): a state ``x`` is *uncertain* at ``eps`` when
    ``x - eps u`` or ``x + eps u`` has another label than ``x``; ``u`` is a random unit
    vector (one per state; Grebogi et al. moved along one coordinate, an isotropic
    direction measures the same scaling). ``n_samples`` states are drawn uniformly in the
    box ``[low, high]`` (the same states for every ``eps``). Feed the result to
    :func:`uncertainty_exponent` with ``n_samples``.

    Args:
        label_fn: ``label_fn(points (m, dim)) -> labels (m,)`` integers (e.g. the final
            attractor of each state from a direct integration); called once per ``eps``
            (with the ``2 n_samples`` perturbed states, the first time also with the
            ``n_samples`` states themselves); it must accept states slightly outside the box.
        low, high: corners of the box, ``(dim,)`` each.
        eps: perturbation sizes ``(k,)`` (state units; the same in every coordinate, so
            scale the coordinates first when their units differ).
        n_samples: sampled states (>= 1).
        seed: seed of the random states and directions.
    Returns:
        ``f (k,)``, the uncertain share at each ``eps``.
    """
    lo = check_finite_array(low, "low", ndim=1)
    hi = check_finite_array(high, "high", ndim=1)
    if lo.shape != hi.shape or np.any(hi <= lo):
        raise ValueError(f"low and high must be corners of a box of one dimension with low < high, got {lo.tolist()} "
                         f"and {hi.tolist()}.")
    e = check_finite_array(eps, "eps", ndim=1)
    if np.any(e <= 0):
        raise ValueError(f"eps must be positive, got {e.tolist()}.")
    n = check_int(n_samples, "n_samples", 1)
    rng = np.random.default_rng(check_int(seed, "seed", 0))
    dim = lo.shape[0]
    x = lo + (hi - lo) * rng.random((n, dim))
    u = rng.standard_normal((n, dim))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    base = None
    out = np.empty(len(e))
    for i, ep in enumerate(e):
        pts = np.concatenate([x, x - ep * u, x + ep * u]) if base is None else np.concatenate([x - ep * u, x + ep * u])
        lab = np.asarray(label_fn(pts)).reshape(-1)
        if lab.shape[0] != pts.shape[0]:
            raise ValueError(f"label_fn returned {lab.shape[0]} labels for {pts.shape[0]} points; it must return one "
                             "label per point.")
        if base is None:
            base, lab = lab[:n], lab[n:]
        out[i] = np.mean((lab[:n] != base) | (lab[n:] != base))
    return out
