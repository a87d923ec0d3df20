"""One engine and one slot vocabulary (STYLE note 12): the direct method's lane pool
(jaxgear.analysis._lanes, _placement, _pool) is the only code that runs a pool of lanes
refilled from a queue; the detection by recurrences (_recurrence, _boxes, _cloud,
_recurrence_options) supplies the pure functions it calls and a view of it
(classify_by_recurrence), and no module but _lanes spells a slot code.

The checks read the source (an AST scan); each scan is first shown to find what it
looks for in a hand-written second engine, so it cannot pass by finding nothing.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from jaxgear.analysis._lanes import SlotKind, slot_code, slot_kind, slot_period

PACKAGE = Path(__file__).resolve().parent.parent / "jaxgear"
ANALYSIS = PACKAGE / "analysis"
POOL_MODULES = {"_lanes.py", "_placement.py", "_pool.py"}
"""The pool: its device program, where it runs, its host driver."""
RECURRENCE_MODULES = ("_recurrence.py", "_boxes.py", "_cloud.py", "_recurrence_options.py")
QUEUE_STATE = {"next_cell", "n_done"}
"""What the state of a pool of lanes refilled from a queue holds: the next cell to take and
the count of decided cells."""
LOOPS = {"while_loop", "fori_loop"}
NOT_OVER_LANES = {
    ("_boxes.py", "insert"): "one insertion after the other over the distinct keys",
    ("_cloud.py", "staged_cloud"): "the stages of one candidate's cloud",
}
"""The loops of the recurrence modules, none over the lanes of a pool."""
MAIN_LOOP = re.compile(r"kernel|refill|decide|rounds?$|period$|main|register|characteri[sz]e", re.I)
"""Names of a pool engine's parts (its kernel, round, period, decisions, refill, registration)."""

SECOND_ENGINE = '''
from typing import NamedTuple
import jax

class _State(NamedTuple):
    Y: object
    next_cell: object
    n_done: object

def _refill(s):
    return s._replace(next_cell=s.next_cell + 1)

def _classify_kernel(s, n):
    return jax.lax.while_loop(lambda s: s.n_done < n, _refill, s)
'''
"""A hand-written second engine, in the shape of the standalone classifier this replaced."""


def _queue_state(tree) -> list[str]:
    """Where a module holds a lane queue's state (a field, an attribute, a keyword)."""
    out = []
    for node in ast.walk(tree):
        name = (node.attr if isinstance(node, ast.Attribute) else node.arg if isinstance(node, ast.keyword)
                else node.target.id if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                else None)
        if name in QUEUE_STATE:
            out.append(f"line {node.lineno}: {name}")
    return out


def _loops(tree):
    """``(function name, line)`` of every ``while_loop`` / ``fori_loop`` call, by the
    outermost function it is in."""
    out = []
    for fn in tree.body:
        if isinstance(fn, (ast.FunctionDef, ast.ClassDef)):
            for node in ast.walk(fn):
                if isinstance(node, ast.Call):
                    f = node.func
                    name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else None
                    if name in LOOPS:
                        out.append((fn.name, node.lineno))
    return out


def _engine_parts(module: str, source: str) -> list[str]:
    """What in the source of a recurrence module ``module`` belongs to a pool engine: a
    lane queue's state, a loop that is not one of :data:`NOT_OVER_LANES`, a function
    named like an engine's part; and, for ``_recurrence.py`` (the view), any loop at
    all or no call of the pool."""
    tree = ast.parse(source)
    out = [f"queue state at {where}" for where in _queue_state(tree)]
    for fn, line in _loops(tree):
        if module == "_recurrence.py" or (module, fn) not in NOT_OVER_LANES:
            out.append(f"a loop in {fn} (line {line})")
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and MAIN_LOOP.search(node.name.lstrip("_")):
            out.append(f"function {node.name} (line {node.lineno})")
    if module == "_recurrence.py" and "run_pool" not in {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}:
        out.append("no call of run_pool")
    return out


def test_the_scans_find_a_second_engine():
    """The hand-written second engine is found by every scan: its queue state, its loop,
    its parts' names, and (as the view) its missing call of the pool."""
    found = _engine_parts("_recurrence.py", SECOND_ENGINE)
    assert any(f.startswith("queue state") for f in found)
    assert any(f.startswith("a loop in _classify_kernel") for f in found)
    assert {f.split()[1] for f in found if f.startswith("function")} == {"_refill", "_classify_kernel"}
    assert "no call of run_pool" in found
    assert _engine_parts("_cloud.py", SECOND_ENGINE)


@pytest.mark.parametrize("module", RECURRENCE_MODULES)
def test_recurrence_modules_hold_no_engine(module):
    """The recurrence modules hold no part of a pool engine; their only loops are over
    keys and cloud stages (:data:`NOT_OVER_LANES`), and the view calls the pool."""
    assert _engine_parts(module, (ANALYSIS / module).read_text()) == []


def test_only_the_pool_holds_a_lane_queue():
    """No module of the package but the pool's holds a lane queue's state."""
    found = {str(p.relative_to(PACKAGE)): _queue_state(ast.parse(p.read_text()))
             for p in sorted(PACKAGE.rglob("*.py")) if not (p.parent == ANALYSIS and p.name in POOL_MODULES)}
    assert {p: f for p, f in found.items() if f} == {}
    assert _queue_state(ast.parse(SECOND_ENGINE))


# --------------------------------------------------------------------------- slot codes


def _spelled_codes(source: str) -> list[int]:
    """Lines that spell a slot code beyond the periods: ``M + 1``, ``M + 2`` (or with
    ``max_period``)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            for a, b in ((node.left, node.right), (node.right, node.left)):
                name = a.id if isinstance(a, ast.Name) else a.attr if isinstance(a, ast.Attribute) else None
                if name in ("M", "max_period") and isinstance(b, ast.Constant) and b.value in (1, 2):
                    out.append(node.lineno)
    return out


def test_no_module_but_the_pool_program_spells_a_slot_code():
    """The modules that read attractor tables' slot codes (``AttractorTable.codes``), but
    ``_lanes`` that defines them, spell none (as ``mark = M + 1``): they read them through
    ``slot_kind``."""
    readers = [p for p in sorted(ANALYSIS.glob("*.py")) if p.name != "_lanes.py" and ".codes" in p.read_text()]
    assert {p.name for p in readers} >= {"_placement.py", "_pool.py"}
    assert {p.name: _spelled_codes(p.read_text()) for p in readers if _spelled_codes(p.read_text())} == {}
    assert _spelled_codes("mark = M + 1\nsaddle = o.max_period + 2\n") == [1, 2]


@pytest.mark.parametrize("M", [1, 8, 16])
def test_slot_codes_round_trip(M):
    """Every kind's code reads back as that kind (and a cycle's or a repeller's as its
    period), on numpy and JAX arrays; the codes of different slots differ; a period
    outside 1..M is refused."""
    slots = [(SlotKind.EMPTY, 0), (SlotKind.BOXES, 0), (SlotKind.SADDLE, 0)]
    slots += [(kind, k) for kind in (SlotKind.CYCLE, SlotKind.REPELLER) for k in range(1, M + 1)]
    codes = np.array([slot_code(kind, M, k) for kind, k in slots], np.int32)
    assert len(set(codes.tolist())) == len(slots)
    for arr in (codes, jnp.asarray(codes)):
        np.testing.assert_array_equal(np.asarray(slot_kind(arr, M)), [int(kind) for kind, _ in slots])
        np.testing.assert_array_equal(np.asarray(slot_period(arr, M)), [k for _, k in slots])
    with pytest.raises(ValueError, match="period"):
        slot_code(SlotKind.CYCLE, M, M + 1)
    with pytest.raises(ValueError, match="period"):
        slot_code(SlotKind.REPELLER, M, 0)


# --------------------------------------------------------------------------- attractor tables
LOOSE_TABLE = {"att_pts", "att_k", "n_att", "att_cloud"}
"""The names the four arrays of the attractor tables had when they travelled apart."""


def _loose_tables(source: str) -> list[str]:
    """Where a source passes the attractor tables as loose arrays: a parameter, a field, a
    keyword or an attribute named :data:`LOOSE_TABLE`, or a ``*`` unpacking of a table."""
    out = []
    for node in ast.walk(ast.parse(source)):
        name = (node.arg if isinstance(node, (ast.arg, ast.keyword)) else node.attr if isinstance(node, ast.Attribute)
                else node.target.id if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                else None)
        if name in LOOSE_TABLE:
            out.append(f"line {node.lineno}: {name}")
        if isinstance(node, ast.Starred) and isinstance(node.value, ast.Name) and node.value.id in ("att", "tables"):
            out.append(f"line {node.lineno}: *{node.value.id}")
    return out


def test_attractor_tables_travel_as_one_typed_pytree():
    """The pool's modules pass an attractor table as one ``AttractorTable`` (points, codes,
    counts, clouds), never as four loose arrays; the scan finds the loose form."""
    assert sorted(_loose_tables("def init(L, att_pts, att_k, n_att, att_cloud):\n    f(*att)\n    s.n_att\n")) == [
        "line 1: att_cloud", "line 1: att_k", "line 1: att_pts", "line 1: n_att", "line 2: *att", "line 3: n_att"]
    assert {m: _loose_tables((ANALYSIS / m).read_text()) for m in sorted(POOL_MODULES)} == {m: [] for m in
                                                                                             sorted(POOL_MODULES)}
    from jaxgear.analysis._lanes import AttractorTable, PoolState, seed_tables

    t = seed_tables([[(np.zeros((2, 3)), 2)], []], 4, 3, Q=5)
    assert type(t) is AttractorTable and (t.n_values, t.n_slots) == (2, 8) and t.counts.tolist() == [1, 0]
    grown = t.with_slots(16)
    assert grown.points.shape == (2, 16, 4, 3) and grown.clouds.shape == (2, 16, 5, 3)
    assert (slot_kind(grown.codes[:, 8:], 4) == SlotKind.EMPTY).all() and np.array_equal(grown.codes[:, :8], t.codes)
    assert "attractors" in PoolState._fields and not LOOSE_TABLE & set(PoolState._fields)
