"""Past one device (issue 16): the batch axes split over several devices give the results
of one device.

References that do not come from the code under test: the same analyses run with one
device (``XLA_FLAGS=--xla_force_host_platform_device_count=1``), in a fresh process each;
spies on the sharded pool of the direct method (:mod:`jaxgear.analysis._placement`: the
sharding of its state, the threads that call it) and on the ``shard_map`` call of
:func:`jaxgear._devices.shard_rows` (the stateless maps: the sharding of its output) show
that the work really was split.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


def _env(devices: int | None = None) -> dict:
    """The environment of a JAX process the tests start: on CPUs, this interpreter's
    ``sys.path``, and the suite's compilation flags (``tests/conftest.py``: they halve the
    compile time, which is most of these tests') without any forced host device count but
    ``devices`` where given."""
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    if devices is not None:
        flags.append(f"--xla_force_host_platform_device_count={devices}")
    return dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p), JAX_PLATFORMS="cpu",
                XLA_FLAGS=" ".join(flags))


SCRIPT = r'''
import sys
import threading
import numpy as np
import jax
import jaxgear as jg
from jaxgear import _devices
from jaxgear.analysis import _placement

pools = []  # devices spanned by the state of each call of the sharded pool
callers = set()  # the threads that ran pool rounds
plain = []  # calls of the one-device pool
real_blocks, real_run = _placement._run_mesh, _placement._run_one


def blocks_spy(*a, **k):
    callers.add(threading.get_ident())
    s, info = real_blocks(*a, **k)
    pools.append(len(s.cell.sharding.device_set))
    return s, info


def run_spy(*a, **k):
    callers.add(threading.get_ident())
    plain.append(1)
    return real_run(*a, **k)


_placement._run_mesh, _placement._run_one = blocks_spy, run_spy


def pooled():
    """The devices every call of the sharded pool spanned since the last section (1: none)."""
    n = set(pools) or {1}
    pools.clear()
    assert len(n) == 1, n
    return np.array(n.pop())

shards = []  # devices spanned by the output of each sharded call (shard_map or partitioned by XLA)


def shard_spy(real_call):
    def spy(*a):
        out = real_call(*a)
        shards.extend(len(x.sharding.device_set) for x in jax.tree.leaves(out))
        return out
    return spy


def spanned():
    """The devices every sharded call of the section spanned (1: only plain calls)."""
    n = set(shards) or {1}
    shards.clear()
    assert len(n) == 1, n
    return np.array(n.pop())


_devices._sharded_call = shard_spy(_devices._sharded_call)
_devices._partitioned_call = shard_spy(_devices._partitioned_call)
what = sys.argv[2].split(",")
out = {}
p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3, omega=1.3)
grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (12, 8), names=("x", "v"))
method = jg.Direct(integrator=jg.RK4(64), max_period=4)
if "direct" in what:
    pools.clear()
    r = jg.analyze_global(jg.DUFFING, p, grid, method, progress=False)
    out["direct_labels"] = np.asarray(r.labels)
    out["direct_shares"] = np.array([a.share for a in r.attractors])
    out["direct_points"] = np.concatenate([a.points for a in r.attractors])
    out["direct_jobs"] = pooled()
if "sweep" in what:
    pools.clear()
    s = jg.basin_sweep(jg.DUFFING, p, "omega", [1.0, 1.4], grid, method=method, runner=jg.Runner(progress=False))
    out["sweep_labels"], out["sweep_shares"], out["sweep_points"] = s.labels, s.shares, s.points
    out["sweep_jobs"] = pooled()
if "sharded" in what:  # no pilot; blocks of 46 and 45 cells: the shorter one padded
    pools.clear(), callers.clear(), plain.clear()
    r = jg.analyze_global(jg.DUFFING, p, jg.CellGrid.box([(-3, 3), (-3, 3)], (13, 7), names=("x", "v")), method,
                          progress=False, uncertainty=0)  # the pools of the analysis alone
    out["sharded_labels"] = np.asarray(r.labels)
    out["sharded_shares"] = np.array([a.share for a in r.attractors])
    out["sharded_points"] = np.concatenate([a.points for a in r.attractors])
    out["sharded_jobs"] = pooled()
    out["sharded_threads"] = np.array(callers == {threading.main_thread().ident})
    out["sharded_plain"] = np.array(len(plain))
if "chaotic" in what:  # no pilot: each device's pool meets the chaotic attractor by a candidate of its own
    real_characterise, candidates = _placement.DeviceMesh.characterise, []

    def characterise_spy(self, *a, **k):
        candidates.append(1)
        return real_characterise(self, *a, **k)

    _placement.DeviceMesh.characterise = characterise_spy
    r = jg.analyze_global(jg.DUFFING, jg.DuffingParams(delta=0.15, alpha=-1.0, beta=1.0, gamma=0.3, omega=1.0),
                          jg.CellGrid.box([(-2, 2), (-2, 2)], (16, 16)), jg.Direct(integrator=jg.RK4(64), pilot=0),
                          progress=False, uncertainty=0)
    _placement.DeviceMesh.characterise = real_characterise
    out["chaotic_labels"] = np.asarray(r.labels)
    out["chaotic_shares"] = np.array([a.share for a in r.attractors])
    out["chaotic_periods"] = np.array([a.period for a in r.attractors])
    out["chaotic_meshcandidates"] = np.array(len(candidates))
if "shoot" in what:
    shards.clear()
    seeds = jg.seeds_in_box(12, [-3, -3], [3, 3], seed=1)
    f = jg.find_periodic_orbits(jg.DUFFING, p, seeds, period=1, integrator=jg.RK4(64), chunk_size=6,
                                progress=False)  # two chunks: one per device
    out["shoot_points"] = np.concatenate([o.points for o in f.orbits])
    out["shoot_iterations"] = np.asarray(f.shots[1].iterations)
    out["shoot_status"] = np.asarray(f.shots[1].status)
    out["shoot_shards"] = spanned()
if "gear" in what:
    pools.clear()
    g = jg.analyze_global(jg.REDUCED, jg.paper_params(), jg.CellGrid.paper((6, 4, 8)), progress=False, uncertainty=0)
    out["gear_labels"] = np.asarray(g.labels)
    out["gear_shares"] = np.array([a.share for a in g.attractors])
    out["gear_points"] = np.concatenate([a.points for a in g.attractors])
    out["gear_jobs"] = pooled()
if "cellmap" in what:
    shards.clear()
    c = jg.analyze_global(jg.DUFFING, p, jg.CellGrid.box([(-3, 3), (-3, 3)], (16, 12), names=("x", "v")),
                          jg.StroboscopicCellMap(integrator=jg.RK4(64), max_period=4), progress=False, uncertainty=0)
    out["cellmap_labels"] = np.asarray(c.labels)
    out["cellmap_shares"] = np.array([a.share for a in c.attractors])
    out["cellmap_points"] = np.concatenate([a.points for a in c.attractors])
    out["cellmap_images"] = jg.cell_images(jg.DUFFING, p, jg.CellGrid.box([(-3, 3), (-3, 3)], (16, 12)),
                                           jg.StroboscopicCellMap(integrator=jg.RK4(64)), progress=False)
    out["cellmap_shards"] = spanned()
if "bifurcation" in what:
    shards.clear()
    b = jg.bifurcation_diagram(jg.DUFFING, p, "omega", np.linspace(1.0, 1.6, 6),
                               np.array([[0.0, 0.0], [2.0, 0.0]]),
                               transient=30, record=17, direction="independent", integrator=jg.RK4(32), max_period=8,
                               runner=jg.Runner(progress=False))
    out["bifurcation_points"] = np.asarray(b.points)
    out["bifurcation_labels"] = np.asarray(b.period)
    out["bifurcation_shards"] = spanned()
if "gearmaps" in what:  # the compiled kernel (an FFI custom call) inside shard_map
    shards.clear()
    g = jg.bifurcation_diagram(None, None, "b", [4.0, 4.5, 5.0], np.array([[0.1, 0, 0, 0], [0.5, 0, 0, 0]]),
                               transient=5, record=9, max_period=4, runner=jg.Runner(progress=False))
    out["gearmaps_points"] = np.asarray(g.points)
    out["gearmaps_images"] = jg.cell_images(jg.REDUCED, jg.paper_params(), jg.CellGrid.paper((5, 3, 4)),
                                            jg.PoincareCellMap(mapping_steps=3), progress=False)
    out["gearmaps_shards"] = spanned()
assert jax.local_device_count() == int(sys.argv[3])
np.savez(sys.argv[1], **out)
'''


def run_on_devices(tmp_path, devices: int, what: str) -> dict:
    """The script's arrays, run in a fresh process with ``devices`` forced host devices."""
    out = tmp_path / f"{what}_{devices}.npz"
    env = _env(devices)
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(out), what, str(devices)], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    with np.load(out) as z:
        return {k: z[k] for k in z.files}


EXACT = ("shoot", "cellmap", "bifurcation", "gearmaps")  # the sharded maps: bit for bit


def assert_same(one: dict, two: dict, what: str):
    for key in one:
        if key.endswith(("_jobs", "_shards")):
            assert int(one[key]) == 1 and int(two[key]) == 2, key  # two devices really took a block each
        elif key.endswith("_threads"):
            assert one[key] and two[key], key  # the pools ran from the main thread alone
        elif key.endswith("_meshcandidates"):
            assert int(one[key]) == 0 and int(two[key]) >= 1, key  # candidates characterised on the mesh
        elif key.endswith("_plain"):
            assert int(one[key]) > 0 and int(two[key]) == 0, key  # two devices: the sharded pool alone
        elif key.split("_")[0] in EXACT:
            np.testing.assert_array_equal(two[key], one[key], err_msg=key)
        elif key.endswith(("_labels", "_shares", "_periods", "_iterations", "_status")):
            np.testing.assert_array_equal(two[key], one[key], err_msg=key)
        else:  # orbits: to round-off
            np.testing.assert_allclose(two[key], one[key], rtol=0, atol=1e-10, err_msg=key)
    assert {k.split("_")[0] for k in one} == set(what.split(","))


SECTIONS = "direct,sweep,sharded,chaotic,shoot,gear,cellmap,bifurcation,gearmaps"
"""Every section of the script (it runs them in this order; each resets the spies it reads)."""


@pytest.fixture(scope="module")
def device_runs(tmp_path_factory):
    """The arrays of every section with one and with two forced host devices: one fresh
    process per device count, shared by the four tests below (the sections of a process
    share the programs it compiles). Each test reads its own sections."""
    tmp = tmp_path_factory.mktemp("devices")
    runs = {}

    def get(devices: int, what: str) -> dict:
        if devices not in runs:
            runs[devices] = run_on_devices(tmp, devices, SECTIONS)
        return {k: v for k, v in runs[devices].items() if k.split("_")[0] in what.split(",")}

    return get


@pytest.mark.slow
def test_two_devices_give_the_one_device_results(device_runs):
    """The direct analysis (cells) and a basin sweep (values x cells) on two forced host
    devices, one lane pool each: the labels, shares and orbits of one device."""
    what = "direct,sweep"
    assert_same(device_runs(1, what), device_runs(2, what), what)


@pytest.mark.slow
def test_two_devices_run_one_sharded_pool(device_runs):
    """The direct analysis on two forced host devices runs both devices' pools in one
    shard_map program (its state spans both devices; no one-device pool, no other thread
    runs pool rounds), the shorter block padded: the labels, shares and orbits of one
    device."""
    what = "sharded"
    assert_same(device_runs(1, what), device_runs(2, what), what)


@pytest.mark.slow
def test_two_devices_characterise_their_candidates(device_runs):
    """A chaotic attractor met by both devices' pools (no pilot): each pool's candidate is
    characterised by the sharded program of candidates, and the labels, shares and types
    are those of one device."""
    what = "chaotic"
    res = device_runs(2, what)
    assert 0 in set(res["chaotic_periods"].tolist())  # the chaotic attractor (period 0) was found
    assert_same(device_runs(1, what), res, what)


@pytest.mark.slow
def test_two_devices_shard_the_stateless_maps(device_runs):
    """Shooting (seeds), the stroboscopic cell map (its cell images and the analysis) and
    an independent bifurcation diagram (values x starts), each batch sharded over two
    forced host devices by one shard_map (its output spans both): the arrays of one
    device, bit for bit."""
    what = "shoot,cellmap,bifurcation"
    assert_same(device_runs(1, what), device_runs(2, what), what)


@pytest.mark.slow
def test_two_devices_with_the_compiled_kernel(device_runs):
    """The gear model through the compiled CPU kernel (an XLA FFI custom call) on two
    devices, in the direct method's pools and inside shard_map (a bifurcation diagram, the
    Poincaré-like cell images): the labels and orbits of one device."""
    what = "gear,gearmaps"
    assert_same(device_runs(1, what), device_runs(2, what), what)


# ----------------------------------------------------------------- several processes
PROCESS_SCRIPT = r'''
import sys
import jaxgear as jg
from jaxgear import _devices
from jaxgear.sweep import _basins

out, n, pid, port = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
if n > 1:
    _devices.initialize(f"localhost:{port}", n, pid)
assert _devices.process_count() == n and _devices.process_index() == pid
grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (12, 8), names=("x", "v"))
_basins.BLOCK_CELLS = grid.n_cells  # one value per block: a kill loses one value
p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3, omega=1.3)
jg.basin_sweep(jg.DUFFING, p, "omega", [1.0, 1.2, 1.3, 1.4], grid, method=jg.Direct(integrator=jg.RK4(64), max_period=4),
               runner=jg.Runner(out=out, progress=False))
'''


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _start(out, n: int) -> list[subprocess.Popen]:
    """``n`` processes of one JAX program (``jax.distributed.initialize`` on CPU) running
    the basin sweep into ``out``."""
    env = _env()
    port = str(_free_port())
    return [subprocess.Popen([sys.executable, "-c", PROCESS_SCRIPT, str(out), str(n), str(i), port], cwd=ROOT, env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for i in range(n)]


def _finish(procs, timeout=600):
    for p in procs:
        _, err = p.communicate(timeout=timeout)
        assert p.returncode == 0, err.decode()[-3000:]


def _kill(proc) -> None:
    """SIGKILL ``proc`` and reap it, its stderr pipe read and closed."""
    import signal

    proc.send_signal(signal.SIGKILL)
    proc.communicate()


@pytest.fixture(scope="module")
def one_process_sweep(tmp_path_factory) -> Path:
    """The basin sweep's file as one process writes it (the reference of the two tests
    below, run once)."""
    out = tmp_path_factory.mktemp("one-process") / "one"
    _finish(_start(out, 1))
    return out / "basins.nc"


@pytest.mark.slow
def test_two_processes_killed_and_rerun_write_the_one_process_file(tmp_path, one_process_sweep):
    """A basin sweep as two JAX processes (each takes every other value; process 0 writes
    the file): one of them killed (SIGKILL) after its first value, the job stopped, the
    same command rerun: the finished values are kept and the file equals that of one
    process."""
    import signal
    import time

    from test_sweep import _assert_same_file

    run = tmp_path / "two"
    procs = _start(run, 2)
    t0 = time.time()
    while time.time() - t0 < 300 and procs[1].poll() is None and not (run / "parts" / "value_00001.nc").exists():
        time.sleep(0.005)
    _kill(procs[1])
    assert procs[1].returncode == -signal.SIGKILL
    assert not (run / "parts" / "value_00003.nc").exists()  # process 1's second value: lost
    deadline = time.time() + 120  # process 0 finishes its own values, then waits for process 1's: stop the job
    while time.time() < deadline and not all((run / "parts" / f"value_0000{i}.nc").exists() for i in (0, 2)):
        time.sleep(0.05)
    _kill(procs[0])
    assert not (run / "basins.nc").exists()
    kept = sorted(p.name for p in (run / "parts").glob("value_*.nc"))
    assert kept == ["value_00000.nc", "value_00001.nc", "value_00002.nc"], kept
    stamps = {n: (run / "parts" / n).stat().st_mtime_ns for n in kept}
    _finish(_start(run, 2))
    assert all((run / "parts" / n).stat().st_mtime_ns == t for n, t in stamps.items())  # not recomputed
    _assert_same_file(one_process_sweep, run / "basins.nc")


@pytest.mark.slow
def test_two_processes_write_the_one_process_file(tmp_path, one_process_sweep):
    """An uninterrupted basin sweep as two JAX processes writes the file of one process."""
    from test_sweep import _assert_same_file

    _finish(_start(tmp_path / "two", 2))
    _assert_same_file(one_process_sweep, tmp_path / "two" / "basins.nc")


ANALYSIS_SCRIPT = r'''
import sys
import jaxgear as jg
from jaxgear import _devices

out, n, pid, port = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
if n > 1:
    _devices.initialize(f"localhost:{port}", n, pid)
p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3, omega=1.3)
r = jg.analyze_global(jg.DUFFING, p, jg.CellGrid.box([(-3, 3), (-3, 3)], (12, 8), names=("x", "v")),
                      jg.Direct(integrator=jg.RK4(64), max_period=4), progress=False)
r.save(f"{out}_{pid}.nc")  # every process holds the whole result
# 20 cells: one block of at least MIN_BLOCK_CELLS for the two processes, process 1 has none
t = jg.analyze_global(jg.DUFFING, p, jg.CellGrid.box([(-3, 3), (-3, 3)], (5, 4), names=("x", "v")),
                      jg.Direct(integrator=jg.RK4(64), max_period=4), progress=False, uncertainty=0)
t.save(f"{out}_{pid}_tiny.nc")
'''


@pytest.mark.slow
def test_two_processes_analyze_the_cells_of_one(tmp_path):
    """The direct analysis as two JAX processes (the cells split over both, the blocks
    exchanged): each process returns the result of one process, also when the queue is
    too short for a block per process."""
    import jaxgear as jg

    env = _env()
    for n in (1, 2):
        port = str(_free_port())
        procs = [subprocess.Popen([sys.executable, "-c", ANALYSIS_SCRIPT, str(tmp_path / f"r{n}"), str(n), str(i), port],
                                  cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                 for i in range(n)]
        _finish(procs)
    for tiny in ("", "_tiny"):  # the tiny queue: a process without a block
        one = jg.load(tmp_path / f"r1_0{tiny}.nc")
        for i in (0, 1):
            two = jg.load(tmp_path / f"r2_{i}{tiny}.nc")
            np.testing.assert_array_equal(two.labels, one.labels)
            assert [a.share for a in two.attractors] == [a.share for a in one.attractors]
            for a, b in zip(two.attractors, one.attractors):
                np.testing.assert_allclose(a.points, b.points, rtol=0, atol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("command", [["analyze", "--grid", "6,4,8"],
                                     ["sweep", "--kind", "basins", "--param", "b", "--values", "4:5:2", "--grid", "3,2,3"],
                                     ["sweep", "--kind", "basins", "--param", "kappa_amp", "--values", "0.36:0.37:2",
                                      "--param2", "b", "--values2", "4:5:3", "--grid", "3,2,3"],
                                     ["sweep", "--kind", "bifurcation", "--param", "b", "--values", "4:6:5",
                                      "--starts", "3", "--transient", "20", "--record", "40",
                                      "--direction", "all"]])
def test_cli_distributed_writes_the_one_process_files(tmp_path, command):
    """`jaxgear analyze|sweep --distributed` (basins, a basin map, bifurcation) as two
    processes (coordinator from the JAX_* variables): process 0 writes the result file of
    one process."""
    import jaxgear as jg

    env = _env()
    base = [sys.executable, "-m", "jaxgear", *command, "--quiet", "--no-figures"]
    r = subprocess.run(base + ["--out", str(tmp_path / "one")], cwd=ROOT, env=env, capture_output=True, timeout=600)
    assert r.returncode == 0, r.stderr.decode()[-3000:]
    env.update(JAX_COORDINATOR_ADDRESS=f"localhost:{_free_port()}", JAX_NUM_PROCESSES="2")
    _finish([subprocess.Popen(base + ["--out", str(tmp_path / "two"), "--distributed"], cwd=ROOT,
                              env=dict(env, JAX_PROCESS_ID=str(i)), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
             for i in range(2)])
    if command[0] == "sweep":  # basins.nc, basin_map.nc, bifurcation.nc: the whole file
        from test_sweep import _assert_same_file

        name = "basin_map.nc" if "--param2" in command else f"{command[2]}.nc"
        _assert_same_file(tmp_path / "one" / name, tmp_path / "two" / name)
    else:
        one, two = jg.load(tmp_path / "one" / "result.nc"), jg.load(tmp_path / "two" / "result.nc")
        np.testing.assert_array_equal(two.labels, one.labels)
        assert [a.share for a in two.attractors] == [a.share for a in one.attractors]
        assert two.uncertainty == one.uncertainty


SWEEP_SCRIPT = r'''
import sys
import numpy as np
import jaxgear as jg
from jaxgear import _devices
from jaxgear.sweep import _kernels

out, n, pid, port = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
if n > 1:
    _devices.initialize(f"localhost:{port}", n, pid)
computed = []  # the parameter rows this process integrated
real = _kernels.shard_rows


def spy(kernel, *args, **kw):
    computed.extend(np.asarray(args[3])[:, 0].tolist())
    return real(kernel, *args, **kw)


_kernels.shard_rows = spy
p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3, omega=1.3)
X0 = np.array([[0.0, 0.0], [2.0, 0.0]])
b = jg.bifurcation_diagram(jg.DUFFING, p, "omega", np.linspace(1.0, 1.6, 7), X0, transient=30, record=17,
                           direction="all", integrator=jg.RK4(32), max_period=8, chunk_size=8,
                           runner=jg.Runner(out=f"{out}/bif_{pid}", progress=False))
m = jg.parameter_map(jg.DUFFING, p, "omega", np.linspace(1.0, 1.6, 3), "gamma", [0.2, 0.3], X0, transient=30,
                     integrator=jg.RK4(32), max_period=4, chunk_size=6,
                     runner=jg.Runner(out=f"{out}/map_{pid}", progress=False))
np.savez(f"{out}/arrays_{pid}.npz", points=b.points, period=b.period, attractor=b.attractor, map_period=m.period,
         map_attractor=m.attractor, map_last=m.last_point, computed=np.array(computed))
'''


@pytest.mark.slow
def test_two_processes_sweep_the_values_of_one(tmp_path):
    """A bifurcation diagram (independent values and the up and down sweeps) and a
    parameter map as two JAX processes: each process integrates its part of every block of
    independent values, every process returns the arrays of one process (floating-point
    values to round-off: XLA may round a batch of fewer rows otherwise), and only process
    0 writes its folder (the file of one process)."""
    from test_sweep import _assert_same_array, _assert_same_file

    env = _env()
    for n in (1, 2):
        port = str(_free_port())
        (tmp_path / f"r{n}").mkdir()
        _finish([subprocess.Popen([sys.executable, "-c", SWEEP_SCRIPT, str(tmp_path / f"r{n}"), str(n), str(i), port],
                                  cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                 for i in range(n)])
    with np.load(tmp_path / "r1" / "arrays_0.npz") as z:
        one = {k: z[k] for k in z.files}
    parts = []
    for i in (0, 1):
        with np.load(tmp_path / "r2" / f"arrays_{i}.npz") as z:
            two = {k: z[k] for k in z.files}
        for key in one:
            if key != "computed":  # each process integrates fewer rows at once: round-off may differ
                _assert_same_array(two[key], one[key], key)
        parts.append(two["computed"])
    # the values split: each process integrated a part of them, together every value
    assert all(len(c) < len(one["computed"]) for c in parts)
    assert set(np.concatenate(parts).tolist()) == set(one["computed"].tolist())
    for kind, name in (("bif", "bifurcation.nc"), ("map", "parameter_map.nc")):
        assert not (tmp_path / "r2" / f"{kind}_1").exists()  # process 1 writes nothing
        _assert_same_file(tmp_path / "r1" / f"{kind}_0" / name, tmp_path / "r2" / f"{kind}_0" / name, roundoff=True)
