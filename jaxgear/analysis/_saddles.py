"""The mean lifetime of a long chaotic transient: the escape rate of a chaotic saddle.

Past a crisis a chaotic attractor can become a chaotic saddle: states wander on it like on
an attractor, then leave it for another attractor; the share still on it decays as
``exp(-kappa t)`` and ``1 / kappa`` is the transient's mean lifetime (Lai & Tél, *Transient
Chaos*, Springer 2011, ch. 1-2). The lane pool tells a saddle from an attractor (its
verification, :func:`~jaxgear.analysis._cloud.leaving_share`) and keeps its cloud; this
module measures ``kappa`` from that cloud, so that a long transient is reported with its
lifetime instead of being mistaken for slow convergence or an attractor.

``SADDLE_STARTS`` points of the cloud are continued in ``SADDLE_STAGES`` equal stages of
the verification's length; after each stage a point has left when its last ``2 M``
points lie on a cycle, it escaped, or they all lie in boxes of a known attractor of boxes.
Leaving is seen some periods after it happens (the approach to the cycle), a delay that
does not depend on when, so the rate is estimated from the points still on the saddle
after the first ``SADDLE_BURN_IN`` stages: with ``D`` departures seen in later stages and
``E`` whole later stages survived in all, the per-stage escape probability is ``p = D / (D + E)`` (the censored geometric
law's maximum likelihood), ``kappa = -ln(1 - p) / stage`` and its standard error from
``var(p) = p^2 (1 - p) / D``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._boxes import FinePartition, cell_keys
from ._cloud import continue_states, escaped, flat_cloud, settled_lanes
from ._result import ChaoticSaddle

__all__ = ["SADDLE_STARTS", "SADDLE_STAGES", "saddle_lifetimes", "escape_rate", "mean_lifetime"]

SADDLE_STARTS = 1024
"""Points of a saddle's cloud continued to measure its escape rate."""
SADDLE_STAGES = 32
"""Equal stages of the continuation."""
SADDLE_BURN_IN = 4
"""The first stages, an eighth of the continuation: the delay with which leaving is seen
(the approach to a cycle) and the cloud's points that were not on the saddle (a
candidate's copies that had settled); the rate is measured on the points left after them."""


@eqx.filter_jit
def _stage(system, params, integrator, partition: FinePartition, known_keys, Y, left, periods: int,
           max_period: int, bound):
    """The states ``Y (dim, K)`` continued ``periods`` periods, and ``left (K,)`` updated:
    on a cycle, escaped, or every one of the last ``2 M`` points in a known attractor's
    boxes (``known_keys``, sorted)."""
    pts = continue_states(system, params, integrator, Y, periods=periods, keep=2 * max_period)
    keys = cell_keys(partition, flat_cloud(pts))
    pos = jnp.clip(jnp.searchsorted(known_keys, keys), 0, known_keys.shape[0] - 1)
    inside = jnp.all(((known_keys[pos] == keys) & (keys >= 0)).reshape(pts.shape[0], -1), axis=0)
    now = settled_lanes(pts, partition.width, max_period) | escaped(pts[0], bound) | inside
    return pts[0], left | now


SADDLE_SPREAD = 1e-6
"""Starts are cloud points moved by this times ``1 + |x|`` in random directions: points of
one candidate's trajectory (the cloud's copies and periods interleave) would leave
together; on the saddle the moves grow until the starts wander independently."""


def _starts(cloud: np.ndarray, rng) -> np.ndarray:
    """:data:`SADDLE_STARTS` points drawn from ``cloud (m, dim)`` and moved apart."""
    x = cloud[rng.choice(len(cloud), SADDLE_STARTS, replace=len(cloud) < SADDLE_STARTS)]
    d = rng.normal(size=x.shape)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return x + SADDLE_SPREAD * (1.0 + np.linalg.norm(x, axis=1, keepdims=True)) * d


def escape_rate(stage_left: np.ndarray, stages: int, stage_periods: int, burn_in: int = SADDLE_BURN_IN):
    """``(kappa, error)`` per period from the stage (1 ..) in which each point was seen
    leaving (0: still on the saddle after the last), counted from the end of stage
    ``burn_in`` (see the module): ``(0, nan)`` when none of those left, ``(inf, nan)`` when
    none was left to count."""
    at_risk = stage_left[(stage_left == 0) | (stage_left > burn_in)]
    if not len(at_risk):
        return math.inf, math.nan
    D = int(np.sum(at_risk > 0))
    E = int(np.sum(np.where(at_risk > 0, at_risk - burn_in - 1, stages - burn_in)))
    if D == 0:
        return 0.0, math.nan
    p = D / (D + E)
    kappa = -math.log1p(-p) / stage_periods if p < 1 else math.inf
    err = math.sqrt(p * p * (1 - p) / D) / ((1 - p) * stage_periods) if p < 1 else math.nan
    return kappa, err


def mean_lifetime(kappa: float, error: float) -> tuple[float, float]:
    """The mean lifetime ``1 / kappa`` (periods) and its standard error ``error / kappa**2``
    from an escape rate and its error (:func:`escape_rate`): ``inf`` when no point left
    (``kappa = 0``), NaN when every point had left within the burn-in (``kappa = inf``: a
    lifetime too short to measure); the error NaN where the lifetime is not finite."""
    if math.isinf(kappa):
        return math.nan, math.nan
    if kappa <= 0:
        return math.inf, math.nan
    return 1.0 / kappa, error / kappa**2


def saddle_lifetimes(system, params, integrator, partition: FinePartition, saddles, attractors, *, periods: int,
                     max_period: int, bound: float) -> tuple[ChaoticSaddle, ...]:
    """A :class:`~jaxgear.ChaoticSaddle` per cloud of ``saddles`` (``(m, dim)`` each, the
    pool's), its mean lifetime measured over ``periods`` periods (the pool's verification
    length) from :data:`SADDLE_STARTS` of its points; ``attractors``: the value's
    ``[(points, period)]`` (the clouds of period 0 are where a point that reaches them has
    gone)."""
    if not saddles:
        return ()
    known = [np.asarray(p, np.float64) for p, k in attractors if int(k) == 0 and len(p)]
    keys = np.unique(np.asarray(cell_keys(partition, jnp.asarray(np.concatenate(known)).T))) if known else []
    keys = jnp.asarray(np.concatenate([[-2], keys]).astype(np.int64))  # (never a box's key: no empty array)
    stage_periods = max(-(-int(periods) // SADDLE_STAGES), 2 * int(max_period))
    out = []
    rng = np.random.default_rng(0)
    for cloud in saddles:
        cloud = np.asarray(cloud, np.float64)
        Y = jnp.asarray(_starts(cloud, rng).T)
        left = jnp.zeros(SADDLE_STARTS, bool)
        stage_left = np.zeros(SADDLE_STARTS, np.int64)
        for stage in range(1, SADDLE_STAGES + 1):
            Y, left = _stage(system, params, integrator, partition, keys, Y, left, stage_periods, int(max_period),
                             jnp.asarray(bound, jnp.float64))
            now = np.asarray(left)
            stage_left[now & (stage_left == 0)] = stage
        lifetime, error = mean_lifetime(*escape_rate(stage_left, SADDLE_STAGES, stage_periods))
        out.append(ChaoticSaddle(points=cloud, lifetime=lifetime, lifetime_error=error, starts=SADDLE_STARTS, periods=SADDLE_STAGES * stage_periods,
                                 left=float(np.mean(stage_left > 0))))
    return tuple(out)
