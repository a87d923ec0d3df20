"""Attractors of every type by recurrences on a fine partition: the boxes
(jaxgear.analysis._boxes), the candidates' clouds (jaxgear.analysis._cloud) and
classify_by_recurrence (jaxgear.analysis._recurrence), a view of the direct method's lane
pool, so the classifications below exercise the pool itself.

References that do not come from the code: a Python dict for the box table, numpy floors
for the box keys, hand-made clouds, and brute-force long integrations of the forced
Duffing oscillator (in numpy, its own RK4 with another step; and long stroboscopic orbits)
for the attractor each state ends on, compared state by state.
"""

from __future__ import annotations

import itertools

import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear  # noqa: F401  (float64)
from jaxgear._examples import DUFFING, DuffingParams
from jaxgear.analysis import PoolOptions, _boxes, _cloud
from jaxgear.analysis import _recurrence as rec
from jaxgear.integrate import RK4

# --------------------------------------------------------------------------- the box table


def _insert_all(table, batches):
    dropped = 0
    for label, keys in batches:
        table, d = _boxes.insert(table, jnp.asarray(keys, jnp.int64), label)
        dropped += int(d)
    return table, dropped


@pytest.mark.parametrize("capacity, n_keys, key_range", [(64, 40, 2**62), (1024, 600, 700)])
def test_table_agrees_with_a_dict(capacity, n_keys, key_range):
    """Insert batches of random keys (repeats within and across batches; 40 keys in 64
    slots force long shared probe chains) and look up present and absent keys: the same
    answers as a dict where the first label of a key wins."""
    rng = np.random.default_rng(capacity)
    pool = rng.choice(key_range, size=n_keys, replace=False).astype(np.int64)
    batches = [(lab, rng.choice(pool, size=n_keys // 2)) for lab in range(5)]
    ref: dict[int, int] = {}
    for lab, keys in batches:
        for k in keys:
            ref.setdefault(int(k), lab)
    table, dropped = _insert_all(_boxes.empty_table(capacity), batches)
    assert dropped == 0
    absent = rng.integers(0, key_range, size=200)
    absent = absent[~np.isin(absent, pool)]
    probe = np.concatenate([pool, absent, [-1]])
    got = np.asarray(_boxes.lookup(table, jnp.asarray(probe, jnp.int64)))
    want = np.array([ref.get(int(k), -1) for k in probe])
    np.testing.assert_array_equal(got, want)


def test_table_overflow_is_counted():
    """100 distinct keys into 64 slots: at least 36 are dropped, the count says exactly how
    many, the others keep their labels and the dropped ones are absent."""
    keys = np.arange(1, 101, dtype=np.int64) * 7919
    labels = np.arange(100) % 7
    table, dropped = _boxes.insert(_boxes.empty_table(64), jnp.asarray(keys), jnp.asarray(labels))
    dropped = int(dropped)
    got = np.asarray(_boxes.lookup(table, jnp.asarray(keys)))
    stored = got >= 0
    assert dropped >= 36
    assert stored.sum() == 100 - dropped
    np.testing.assert_array_equal(got[stored], labels[stored])


def test_table_capacity_must_be_a_power_of_two():
    with pytest.raises(ValueError, match="capacity=100"):
        _boxes.empty_table(100)
    with pytest.raises(ValueError, match="capacity"):
        rec.RecurrenceOptions(capacity=3000)


# --------------------------------------------------------------------------- box keys


def test_packed_keys_are_the_numpy_box_coordinates():
    """dim 4: the key unpacks into floor((y - lo) / width) computed in numpy; -1 outside."""
    part = _boxes.partition_from_box([-25, -10, -10, -5], [25, 20, 50, 5], 100)
    rng = np.random.default_rng(0)
    Y = rng.uniform(-30, 60, (4, 500))
    Y[:, :3] = [[1e9, np.nan, -1e9]] * 4  # outside the index range, not finite
    keys = np.asarray(_boxes.cell_keys(part, jnp.asarray(Y)))
    lo, w = np.asarray(part.lo), np.asarray(part.width)
    idx = np.floor((Y - lo[:, None]) / w[:, None])
    assert np.all(keys[:3] == -1)
    mask = (1 << _boxes.INDEX_BITS) - 1
    dec = np.stack([(keys[3:] >> (_boxes.INDEX_BITS * d)) & mask for d in range(4)])
    np.testing.assert_array_equal(dec, idx[:, 3:].astype(np.int64))
    np.testing.assert_allclose(w, [0.5, 0.3, 0.6, 0.1])


def test_hashed_keys_separate_boxes_in_eight_dimensions():
    """dim 8 (the 3-planet model): 4,000 boxes, many of them neighbours that differ in one
    coordinate, each sampled twice inside: equal keys within a box, distinct across."""
    dim = 8
    part = _boxes.partition_from_box(np.zeros(dim), np.ones(dim), 64)
    rng = np.random.default_rng(1)
    boxes = np.unique(rng.integers(0, 4, (4000, dim)), axis=0)
    boxes = np.concatenate([boxes, boxes[:500] + np.eye(dim, dtype=np.int64)[rng.integers(0, dim, 500)]])
    boxes = np.unique(boxes, axis=0) + (1 << (_boxes.INDEX_BITS - 1))
    lo, w = np.asarray(part.lo), np.asarray(part.width)
    pts = [lo + (boxes + rng.uniform(0.05, 0.95, boxes.shape)) * w for _ in range(2)]
    k1, k2 = (np.asarray(_boxes.cell_keys(part, jnp.asarray(p.T))) for p in pts)
    np.testing.assert_array_equal(k1, k2)
    assert np.all(k1 >= 0)
    assert len(np.unique(k1)) == len(boxes)


# --------------------------------------------------------------------------- per-lane runs


def test_track_hits_runs():
    """Hand-written sequences: hits on attractor 0 count, unregistered boxes are tolerated up
    to max_misses in a row, a box of attractor 1 restarts the run on 1."""
    seqs = {
        "clean": ([0, 0, 0, 0], (0, 4)),
        "tolerated": ([0, -1, 0, -1, -1, 0], (0, 3)),
        "lost": ([0, 0, -1, -1, -1], (-1, 0)),  # three misses > max_misses = 2
        "other": ([0, 0, 0, 1, 1], (1, 2)),
        "back": ([0, 1, 0], (0, 1)),
    }
    L = len(seqs)
    att, hits, misses = jnp.full(L, -1, jnp.int32), jnp.zeros(L, jnp.int32), jnp.zeros(L, jnp.int32)
    n = max(len(s) for s, _ in seqs.values())
    for t in range(n):
        lab = jnp.asarray([s[t] if t < len(s) else -9 for s, _ in seqs.values()], jnp.int32)
        a, h, m = _boxes.track_hits(lab, att, hits, misses, 2)
        keep = lab == -9  # this sequence has ended
        att, hits, misses = (jnp.where(keep, x, y) for x, y in ((att, a), (hits, h), (misses, m)))
    assert list(zip(np.asarray(att).tolist(), np.asarray(hits).tolist())) == [want for _, want in seqs.values()]


# --------------------------------------------------------------------------- clouds


def _one_copy(points):
    """``(P, dim)`` -> ``(P, dim, 1)``."""
    return jnp.asarray(np.asarray(points)[:, :, None])


def test_recurrence_share_tells_attractors_from_transients():
    """An irrational rotation of a circle recurs (its second half lies in the first half's
    boxes); a drift along a line (a transient still moving on) does not."""
    part = _boxes.partition_from_box([-1, -1], [1, 1], 40)
    t = np.arange(4000) * 2 * np.pi * (np.sqrt(5) - 1) / 2
    circle = np.column_stack([np.cos(t), np.sin(t)])
    line = np.column_stack([np.linspace(-1, 1, 4000), np.zeros(4000)])
    assert float(_cloud.recurrence_share(part, _one_copy(circle))) > 0.99
    assert float(_cloud.recurrence_share(part, _one_copy(line))) == 0.0


def test_near_periodic_sees_cycles_not_rotations():
    """A P-3 cycle approached geometrically (its distance to the cycle times 0.97 per
    period) is a cycle, and so is the cycle itself (errors at round-off do not shrink any
    more); the same cycle with noise that does not die out (three bands a third of a box
    wide: an attractor that repeats within a box but never converges, as a narrow-banded
    chaotic one) is not, nor the irrational rotation."""
    part = _boxes.partition_from_box([-1, -1], [1, 1], 40)
    w = float(part.width[0])
    t = np.arange(600)
    cyc = np.array([[0.5, 0.1], [-0.3, 0.7], [0.2, -0.6]])[t % 3]
    approach = cyc + 0.8 * w * 0.97 ** t[:, None] * np.column_stack([np.cos(t), np.sin(t)])
    reached = cyc + 1e-15 * np.random.default_rng(1).standard_normal((600, 2))
    bands = cyc + np.random.default_rng(2).uniform(-w / 6, w / 6, (600, 2))
    th = t * 2 * np.pi * (np.sqrt(5) - 1) / 2
    rot = np.column_stack([np.cos(th), np.sin(th)])
    assert bool(_cloud.near_periodic(part, _one_copy(approach), 8))
    assert bool(_cloud.near_periodic(part, _one_copy(reached), 8))
    assert not bool(_cloud.near_periodic(part, _one_copy(bands), 8))
    assert not bool(_cloud.near_periodic(part, _one_copy(rot), 8))


def test_near_cycle_lanes():
    """Rings of the last 2 M points (newest first): a lane settling on a P-2 cycle (within a
    box of it, closer every period) is near a cycle; one moving away from the cycle, one
    on noisy bands around it whose newest errors exceed the older ones, one on the
    irrational rotation and one without history yet (NaN) are not."""
    M = 4
    part = _boxes.partition_from_box([-1, -1], [1, 1], 40)
    w = float(part.width[0])
    t = np.arange(2 * M)  # periods back
    cyc = np.array([[0.5, 0.1], [-0.3, 0.7]])[t % 2]
    settling = cyc + 0.3 * w * 0.8 ** (2 * M - t)[:, None]
    leaving = cyc + 0.3 * w * 0.8 ** t[:, None]
    noisy = cyc + np.where(t < M // 2, 0.3, 0.05)[:, None] * w * np.array([1.0, -1.0]) * (-1) ** (t // 2)[:, None]
    rot = np.column_stack([np.cos(2.4 * t), np.sin(2.4 * t)])
    young = np.full((2 * M, 2), np.nan)
    ring = jnp.asarray(np.stack([settling, leaving, noisy, rot, young], axis=-1))  # (2M, 2, 5)
    assert np.asarray(_cloud.near_cycle_lanes(ring, part.width, M)).tolist() == [True, False, False, False, False]


def test_oldest_off_cycle_picks_the_oldest_lane_not_settling():
    """Of 100 lanes with random ages, some eligible, some settling on a P-2 cycle (their
    rings shrink onto it), the candidate is the oldest eligible lane not settling (a
    sort in numpy); with more than CANDIDATE_POOL older eligible lanes all settling,
    there is none this round."""
    M, L = 4, 100
    rng = np.random.default_rng(7)
    t = np.arange(2 * M)
    cyc = np.array([[0.5, 0.1], [-0.3, 0.7]])[t % 2]
    settling = cyc + 1e-3 * 0.8 ** (2 * M - t)[:, None]
    wander = rng.uniform(-1, 1, (2 * M, 2, L))
    width = jnp.asarray([0.05, 0.05])
    ages = rng.permutation(L).astype(np.int32) + 100
    eligible = rng.random(L) < 0.6
    near = rng.random(L) < 0.5
    ring = np.where(near[None, None], settling[:, :, None], wander)
    lane, found = _cloud.oldest_off_cycle(jnp.asarray(eligible), jnp.asarray(ages), lambda i: jnp.asarray(ring)[:, :, i],
                                       width, M)
    ok = np.flatnonzero(eligible & ~near)
    assert bool(found) and int(lane) == ok[np.argmax(ages[ok])]
    # the CANDIDATE_POOL oldest eligible lanes settle; the only lane that does not is younger
    K = _cloud.CANDIDATE_POOL
    L2 = K + 8
    ages2 = np.arange(L2, dtype=np.int32)[::-1] + 100  # lane 0 oldest
    ring2 = np.repeat(settling[:, :, None], L2, axis=2)
    ring2[:, :, L2 - 1] = wander[:, :, 0]
    lane, found = _cloud.oldest_off_cycle(jnp.ones(L2, bool), jnp.asarray(ages2), lambda i: jnp.asarray(ring2)[:, :, i],
                                       width, M)
    assert not bool(found)
    lane, found = _cloud.oldest_off_cycle(jnp.arange(L2) >= 8, jnp.asarray(ages2), lambda i: jnp.asarray(ring2)[:, :, i],
                                       width, M)  # now it is among the pool's oldest eligible lanes
    assert bool(found) and int(lane) == L2 - 1
    # no eligible lane: no candidate, and the lane the search over none would give (the first)
    lane, found = _cloud.oldest_off_cycle(jnp.zeros(L, bool), jnp.asarray(ages), lambda i: jnp.asarray(ring)[:, :, i],
                                       width, M)
    assert not bool(found) and int(lane) == 0


@pytest.mark.parametrize("seed", range(3))
def test_the_rows_minimum_is_numpy_s_with_ties_infinities_and_nans(seed):
    """The pool's nearest cycle point per lane (``_min_rows``, one pass over the rows)
    gives numpy's ``min`` and ``argmin`` over the rows: the first row on ties, a NaN first,
    rows of infinities (the slots past a cycle's period)."""
    from jaxgear.analysis._lanes import _min_rows

    rng = np.random.default_rng(seed)
    d = rng.integers(0, 4, (16, 500)).astype(np.float64)  # many ties
    d[rng.random(d.shape) < 0.05] = np.nan
    d[rng.random(d.shape) < 0.2] = np.inf
    d[:, :3] = np.inf  # a lane with no valid row
    best, arg = _min_rows(jnp.asarray(d))
    np.testing.assert_array_equal(np.asarray(best), np.min(d, axis=0))
    np.testing.assert_array_equal(np.asarray(arg), np.argmin(d, axis=0))


def test_overlap_shares_match_clouds_by_boxes():
    """Boxes of a circle registered as attractor 0 and of a smaller circle as attractor 1: a
    new sampling of the first circle lies in 0's boxes, a disjoint circle in none."""
    part = _boxes.partition_from_box([-1, -1], [1, 1], 40)
    t = np.arange(3000) * 2 * np.pi * (np.sqrt(5) - 1) / 2
    ring = np.column_stack([np.cos(t), np.sin(t)])
    table, _ = _boxes.insert(_boxes.empty_table(1024), _boxes.cell_keys(part, jnp.asarray(0.8 * ring.T)), 0)
    table, _ = _boxes.insert(table, _boxes.cell_keys(part, jnp.asarray(0.3 * ring.T)), 1)
    s = np.random.default_rng(4).uniform(0, 2 * np.pi, 500)
    again = jnp.asarray(0.8 * np.stack([np.cos(s), np.sin(s)]))
    other = jnp.asarray(0.55 * np.stack([np.cos(s), np.sin(s)]))
    np.testing.assert_allclose(np.asarray(_cloud.overlap_shares(table, _boxes.cell_keys(part, again), 2)), [1.0, 0.0])
    np.testing.assert_allclose(np.asarray(_cloud.overlap_shares(table, _boxes.cell_keys(part, other), 2)), [0.0, 0.0])


# --------------------------------------------------------------------------- a chaotic and a periodic attractor

# x'' + 0.15 x' - x + x^3 = 0.3 cos t: a chaotic attractor coexists with a P-1 cycle
# (about 2/3 of the states of [-2, 2]^2 reach the chaotic one).
DUFF = dict(delta=0.15, alpha=-1.0, beta=1.0, gamma=0.3, omega=1.0)


def _duffing_brute_force(X, periods, tail, steps=80):
    """numpy RK4 (``steps`` per period) of every state of ``X (n, 2)``: ``(labels, last points
    (n, 2))``, label 1 for a P-k end (k <= 8: the last ``tail`` section points repeat to
    1e-6), 0 for a bounded aperiodic end."""
    d, a, b, g, w = (DUFF[k] for k in ("delta", "alpha", "beta", "gamma", "omega"))
    T = 2 * np.pi / w
    h = T / steps

    def f(t, x, v):
        return v, g * np.cos(w * t) - d * v - a * x - b * x**3

    x, v = X[:, 0].copy(), X[:, 1].copy()
    pts = []
    for p in range(periods + tail):
        for i in range(steps):
            t = i * h  # the forcing is T-periodic: every period repeats the step times
            k1 = f(t, x, v)
            k2 = f(t + h / 2, x + h / 2 * k1[0], v + h / 2 * k1[1])
            k3 = f(t + h / 2, x + h / 2 * k2[0], v + h / 2 * k2[1])
            k4 = f(t + h, x + h * k3[0], v + h * k3[1])
            x = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        if p >= periods:
            pts.append(np.stack([x, v], axis=1))
    pts = np.array(pts)  # (tail, n, 2)
    assert np.all(np.abs(pts) < 10)
    periodic = np.zeros(len(X), bool)
    for k in range(1, 9):
        periodic |= np.max(np.abs(pts[k:] - pts[:-k]), axis=(0, 2)) < 1e-6
    return periodic.astype(int), pts[-1]


N_STATES = 200
"""States of each classification below: one queue shape, so one compiled pool serves them all."""
POOL = PoolOptions(lanes=N_STATES)
OPTIONS = rec.RecurrenceOptions(resolution=100, cloud_periods=400)


def _classify(params, X):
    """:func:`classify_by_recurrence` of the Duffing states ``X (N_STATES, 2)`` (RK4, 64 steps a period)."""
    return rec.classify_by_recurrence(DUFFING, DuffingParams(**params), X, options=OPTIONS, integrator=RK4(64),
                                      pool=POOL)


def _box_coords(partition, pts):
    """The integer box coordinates of the points ``pts (m, dim)``, as tuples (numpy floors)."""
    lo, w = np.asarray(partition.lo), np.asarray(partition.width)
    return list(map(tuple, np.floor((pts - lo) / w).astype(np.int64)))


def _near_boxes(partition, cloud):
    """The boxes of the finite points of ``cloud (m, dim)`` and their neighbours (a finite
    cloud covers an attractor only partly), as a set of coordinate tuples."""
    cloud = cloud[np.all(np.isfinite(cloud), axis=1)]
    steps = np.array(list(itertools.product((-1, 0, 1), repeat=cloud.shape[1])))
    boxes = np.unique(np.array(_box_coords(partition, cloud)), axis=0)
    return set(map(tuple, (boxes[:, None] + steps[None]).reshape(-1, cloud.shape[1])))


def test_chaotic_and_periodic_attractors_coexist():
    """Both attractors are found (one P-1 cycle, one aperiodic attractor of boxes), every
    state is decided in time, and state by state on the attractor a brute-force
    numpy integration of the same random states ends on (at most 2 of the 200 may differ:
    a state on the basin boundary may go either way under another step; none does today,
    with 72 or 64 steps a period); the cycle's point is the brute force's, and the brute
    force's chaotic end points lie in the boxes of the aperiodic attractor's cloud or next
    to them (where few random states of the region do)."""
    X = np.random.default_rng(7).uniform(-2, 2, (N_STATES, 2))
    r = _classify(DUFF, X)
    labels, used = np.asarray(r.labels), np.asarray(r.periods_used)
    periods = np.asarray(r.periods).tolist()
    assert sorted(periods) == [rec.APERIODIC, 1]
    assert np.all(labels >= 0)
    # decided before the limit (a state decided by its own cloud is charged the cloud and its verification)
    assert np.all((used > 0) & (used < POOL.max_periods + OPTIONS.cloud_periods + OPTIONS.verify_periods))
    chaotic = periods.index(rec.APERIODIC)

    ref, last = _duffing_brute_force(X, periods=250, tail=30, steps=72)
    assert 0.2 < np.mean(ref == 0) < 0.9  # both attractors have a sizeable basin
    differ = np.flatnonzero((labels == chaotic) != (ref == 0))
    assert len(differ) <= 2, differ.tolist()

    points = np.asarray(r.points)
    cycle = points[periods.index(1)]
    assert np.all(np.isnan(cycle[1:]))  # one point: a P-1 cycle
    np.testing.assert_allclose(last[ref == 1], np.broadcast_to(cycle[0], last[ref == 1].shape), atol=1e-3)
    assert np.sum(np.all(np.isfinite(points[chaotic]), axis=1)) > 100
    near = _near_boxes(r.partition, points[chaotic])  # a cloud of 1,600 points: the attractor in part
    assert np.mean([b in near for b in _box_coords(r.partition, last[ref == 0])]) > 0.95
    anywhere = np.random.default_rng(0).uniform(-2, 2, (2000, 2))  # the attractor is thin: few of these
    assert np.mean([b in near for b in _box_coords(r.partition, anywhere)]) < 0.3


def test_settled_lanes():
    """Last 2 M points (newest first): a lane on a P-3 cycle to 1e-5 box widths has settled;
    one still approaching it (errors 0.05 box widths), one on an irrational rotation of a
    tiny circle (a tenth of a box wide: it comes back near itself without repeating) and
    one without history (NaN) have not."""
    M = 4
    part = _boxes.partition_from_box([-1, -1], [1, 1], 40)
    w = float(part.width[0])
    t = np.arange(2 * M)
    cyc = np.array([[0.5, 0.1], [-0.3, 0.7], [0.2, -0.4]])[t % 3]
    on = cyc + 1e-5 * w * np.sin(t)[:, None]
    near = cyc + 0.05 * w * 0.9 ** (2 * M - t)[:, None]
    rot = 0.05 * w * np.column_stack([np.cos(2.4 * t), np.sin(2.4 * t)])
    young = np.full((2 * M, 2), np.nan)
    pts = jnp.asarray(np.stack([on, near, rot, young], axis=-1))
    assert np.asarray(_cloud.settled_lanes(pts, part.width, M)).tolist() == [True, False, False, False]


# Just past its boundary crisis (about gamma = 0.31515 with RK4 at 64 steps a period) the
# chaotic attractor of DUFF is a chaotic saddle: a mean of about 500 periods on it, then a cycle.
SADDLE = {**DUFF, "gamma": 0.315151}


def _orbit_ends(params, X, periods):
    """The stroboscopic orbits of the states ``X (n, 2)`` over ``periods`` periods (RK4, 64
    steps): per state the period its orbit ends on (the smallest ``k <= 8`` with a repeat to
    1e-6 over the last 24 points; 0: still aperiodic), and its last point."""
    o = np.asarray(jaxgear.stroboscopic_orbit(DUFFING, DuffingParams(**params), X, n_points=periods,
                                              integrator=RK4(64)))
    tail = o[:, -24:]
    end = np.zeros(len(X), np.int64)
    for k in range(8, 0, -1):
        end = np.where(np.max(np.abs(tail[:, k:] - tail[:, :-k]), axis=(1, 2)) < 1e-6, k, end)
    return end, o[:, -1]


def _still_wandering(params, X, periods):
    """Those of the states ``X (n, 2)`` still aperiodic after ``periods`` periods
    (:func:`_orbit_ends`), at their last point (on the chaotic set)."""
    end, last = _orbit_ends(params, X, periods)
    return last[end == 0]


def test_leaving_share_tells_a_saddle_from_an_attractor():
    """Points of the chaotic attractor (gamma = 0.3) stay on it for 2,000 periods: none
    leaves. Points of the chaotic saddle (still wandering after 300 periods) mostly settle
    on a cycle within 2,000 periods: about 1 - exp(-2000 / 500); at least the share of
    those whose brute-force orbit of 2,000 periods ends on a cycle, less 3 binomial errors."""
    part = _boxes.partition_from_box([-2, -2], [2, 2], 100)
    on_attractor = _still_wandering(DUFF, np.random.default_rng(1).uniform(-2, 2, (120, 2)), 300)[:64]
    assert len(on_attractor) == 64
    share = _cloud.leaving_share(DUFFING, DuffingParams(**DUFF), RK4(64), part, jnp.asarray(on_attractor.T),
                              periods=2000, max_period=8, bound=1e6)
    assert float(share) == 0.0

    on_saddle = _still_wandering(SADDLE, np.random.default_rng(2).uniform(-2, 2, (200, 2)), 300)[:64]
    assert len(on_saddle) >= 32
    share = float(_cloud.leaving_share(DUFFING, DuffingParams(**SADDLE), RK4(64), part, jnp.asarray(on_saddle.T),
                                    periods=2000, max_period=8, bound=1e6))
    left = 1.0 - len(_still_wandering(SADDLE, on_saddle, 2000)) / len(on_saddle)
    se = np.sqrt(max(left * (1 - left), 0.05) / len(on_saddle))
    assert left > 0.8 and share >= left - 3 * se


def test_chaotic_saddle_is_no_attractor():
    """Just past the crisis the pool registers no aperiodic attractor for the chaotic saddle,
    only cycles; at least 90 % of the states are decided, and each decided state's cycle has
    the period its brute-force orbit of 3,000 periods ends on (which of the two P-2 cycles is
    not compared: a long transient on the saddle amplifies round-off, so two integrations of
    one state may end on either)."""
    X = np.random.default_rng(3).uniform(-2, 2, (N_STATES, 2))
    r = _classify(SADDLE, X)
    periods, labels = np.asarray(r.periods), np.asarray(r.labels)
    assert len(periods) and np.all(periods > 0), periods.tolist()
    decided = labels >= 0
    assert np.mean(decided) >= 0.9
    end, _ = _orbit_ends(SADDLE, X, 3000)
    assert np.mean(end == 0) <= 0.1  # the brute force: (nearly) all on cycles
    both = decided & (end > 0)
    np.testing.assert_array_equal(periods[labels[both]], end[both])


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="accept_share"):
        rec.RecurrenceOptions(accept_share=1.5)
    with pytest.raises(ValueError, match="X must be"):
        rec.classify_by_recurrence(DUFFING, DuffingParams(**DUFF), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="unknown option 'chunk'"):
        rec.classify_by_recurrence(DUFFING, DuffingParams(**DUFF), np.zeros((3, 2)), chunk=3)
    with pytest.raises(ValueError, match="resolution"):
        _boxes.partition_from_box([0, 0], [1, 1], 0)


def test_bad_verification_options_are_refused():
    """The verification's options are checked, by name: a negative stretch, no lanes, a share
    outside (0, 1]; a stretch shorter than the last 2 max_period points it judges is lengthened."""
    from jaxgear import Direct

    with pytest.raises(ValueError, match="verify_periods"):
        rec.RecurrenceOptions(verify_periods=-1)
    with pytest.raises(ValueError, match="verify_lanes"):
        rec.RecurrenceOptions(verify_lanes=0)
    with pytest.raises(ValueError, match="leave_share"):
        rec.RecurrenceOptions(leave_share=0.0)
    # a verification shorter than the cycle test's history runs that history instead
    assert _cloud.verify_length(rec.RecurrenceOptions(verify_periods=20), 16) == 32
    assert _cloud.verify_length(rec.RecurrenceOptions(), 16) == rec.RecurrenceOptions().verify_periods
    assert Direct(recurrence=rec.RecurrenceOptions(verify_periods=0)).recurrence.verify_periods == 0


# --------------------------------------------------------------------------- the gear train in its chaotic band


@pytest.mark.slow
def test_gear_chaotic_band_every_state_decided():
    """The paper preset at b_sp = b_rp = 2 (inside the aperiodic band of the backlash
    diagram): every random state of the paper region is decided on one bounded aperiodic
    attractor, within far fewer periods than the direct method's limit (but for the state whose
    cloud registered it, charged that cloud and its verification). Independently of
    the classifier, a long stroboscopic orbit from a labelled state neither repeats (no
    P-k, k <= 16, to 1e-6) nor leaves the boxes of the attractor's cloud (or their neighbours)."""
    from jaxgear import paper_params, stroboscopic_orbit
    from jaxgear._model import REDUCED

    params = paper_params(b_sp=2, b_rp=2)
    rng = np.random.default_rng(3)
    n = 64
    X = np.column_stack([rng.uniform(-25, 25, n), rng.uniform(-10, 20, n), rng.uniform(-10, 50, n), np.zeros(n)])
    r = rec.classify_by_recurrence(REDUCED, params, X, pool=PoolOptions(lanes=n))
    labels = np.asarray(r.labels)
    used = np.asarray(r.periods_used)
    near = _near_boxes(r.partition, np.asarray(r.points)[0])
    print(f"mean periods per state {used.mean():.1f} (median {np.median(used):.0f}, max {used.max()}), "
          f"boxes of the cloud and their neighbours {len(near)}")
    assert np.asarray(r.periods).tolist() == [rec.APERIODIC]
    assert np.all(labels == 0)
    # twice the paper preset's 64 periods per cell, but for the candidate(s) that registered the
    # attractor: charged their cloud and its verification (600 + 2,000 periods)
    assert np.median(used) < 128 and np.sum(used >= 128) <= 2

    orbit = np.asarray(stroboscopic_orbit(REDUCED, params, X[:4], n_points=600))[:, 300:]  # (4, 300, 4)
    assert np.all(np.abs(orbit) < 100)
    for k in range(1, 17):
        assert np.all(np.max(np.abs(orbit[:, k:] - orbit[:, :-k]), axis=(1, 2)) > 1e-6)
    assert np.mean([b in near for b in _box_coords(r.partition, orbit.reshape(-1, 4))]) > 0.9


@pytest.mark.slow
def test_three_planet_model_uses_hashed_boxes():
    """The 3-planet model (state dimension 8: hashed box keys) started from the reduced
    model's states on its symmetric subspace, b = 2: every state is decided on one
    aperiodic attractor, whose cloud spans more than 20 boxes."""
    from jaxgear import paper_params
    from jaxgear._model import nplanet_system, reduced_to_nplanet

    rng = np.random.default_rng(3)
    n = 16
    X = np.column_stack([rng.uniform(-25, 25, n), rng.uniform(-10, 20, n), rng.uniform(-10, 50, n), np.zeros(n)])
    r = rec.classify_by_recurrence(nplanet_system(3), paper_params(b_sp=2, b_rp=2),
                                   np.asarray(reduced_to_nplanet(X, 3)), pool=PoolOptions(lanes=n))
    assert np.asarray(r.periods).tolist() == [rec.APERIODIC]
    assert np.all(np.asarray(r.labels) == 0)
    kept = np.asarray(r.points)[0]
    assert len(set(_box_coords(r.partition, kept[np.all(np.isfinite(kept), axis=1)]))) > 20
