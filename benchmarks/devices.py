"""Scaling past one device and one process: plain script, figures printed, nothing asserted.

    python benchmarks/devices.py           # the paper grid on devices and on processes, then the sweep
    python benchmarks/devices.py --counts 10 6 12 --process-counts 10 6 12 --repeat 1 --only devices

Measures in one run on this machine (the reduced gear model, paper preset, the default
method :class:`jaxgear.Direct`):

1. *devices*: :func:`jaxgear.analyze_global` on ``--counts`` cells with 1 and with 2
   forced host devices (``XLA_FLAGS=--xla_force_host_platform_device_count``, each in a
   fresh process; ``min`` over ``--repeat`` calls after a warm-up call, compilation
   apart), and whether both give the same labels and shares;
2. *processes*: ``jaxgear analyze`` (no figures, no label uncertainty) on
   ``--process-counts`` cells (default the paper grid) as one process pinned to core 0
   (``taskset -c 0``) and as two processes of one JAX program (``--distributed``) pinned
   to cores 0 and 1, wall time of the whole command (start and the written file
   included), with a warm compilation cache (a first run of each fills it); whether both
   write the same labels and shares; and, as the floor two processes can reach, one
   process on half the cells (each of the two pays the start, the loading of the
   compiled computations, the pilot and the draining tail in full), and two such
   processes at once, one per core, without any exchange (what the machine gives two
   busy cores: shared caches, memory bandwidth and other tenants);
3. *sweep*: ``benchmarks/sweep_scale.py`` in a fresh process, the basin sweep of 8
   backlash values in one lane pool against 8 separate analyses.

Each section's last line is its ratio (sections 1 and 2: one / two, above 1 is faster on
two; section 3: separate / one pool, above 1 is faster in one pool).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

ANALYSIS = r'''
import json, sys, time, warnings
import numpy as np
import jax
import jaxgear as jg
warnings.simplefilter("ignore")
counts, repeat, out = tuple(json.loads(sys.argv[1])), int(sys.argv[2]), sys.argv[3]
grid = jg.CellGrid.paper(counts)
run = lambda: jg.analyze_global(jg.REDUCED, jg.paper_params(), grid, progress=False, uncertainty=0)
run()
times = []
for _ in range(repeat):
    t = time.perf_counter()
    r = run()
    times.append(time.perf_counter() - t)
np.savez(out, labels=np.asarray(r.labels), shares=np.array([a.share for a in r.attractors]))
print(json.dumps(dict(devices=jax.local_device_count(), seconds=min(times))))
'''

def env(**extra) -> dict:
    e = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p), JAX_PLATFORMS="cpu", **extra)
    if "XLA_FLAGS" not in extra:
        e.pop("XLA_FLAGS", None)
    return e


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def devices(counts, repeat: int, tmp: Path) -> None:
    import numpy as np

    print(f"1. direct analysis, {counts} cells, 1 vs 2 forced host devices (min of {repeat} after a warm-up)")
    out = {}
    for d in (1, 2):
        r = subprocess.run([sys.executable, "-c", ANALYSIS, json.dumps(counts), str(repeat), str(tmp / f"a{d}.npz")],
                           env=env(XLA_FLAGS=f"--xla_force_host_platform_device_count={d}"), capture_output=True,
                           text=True, check=True)
        out[d] = json.loads(r.stdout.strip().splitlines()[-1])
        print(f"   {d} device(s): {out[d]['seconds']:.2f} s")
    with np.load(tmp / "a1.npz") as a, np.load(tmp / "a2.npz") as b:
        same = np.array_equal(a["labels"], b["labels"]) and np.array_equal(a["shares"], b["shares"])
    print(f"   identical labels and shares: {same}")
    print(f"   devices ratio (1 device / 2 devices): {out[1]['seconds'] / out[2]['seconds']:.2f}x")


def _cli(args, cores, cache: Path, n: int = 1, pid: int = 0, port: str = "") -> subprocess.Popen:
    """``jaxgear ARGS`` pinned to ``cores``, as process ``pid`` of ``n`` (``--distributed``)."""
    extra = dict(JAXGEAR_CACHE_DIR=str(cache))
    if n > 1:
        extra.update(JAX_COORDINATOR_ADDRESS=f"localhost:{port}", JAX_NUM_PROCESSES=str(n), JAX_PROCESS_ID=str(pid))
        args = [*args, "--distributed"]
    return subprocess.Popen(["taskset", "-c", cores, sys.executable, "-m", "jaxgear", *args], env=env(**extra),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _wall(runs) -> float:
    """Start the commands ``runs`` (a list of argument tuples for :func:`_cli`) together
    and return the wall time until the last one ends."""
    t = time.perf_counter()
    procs = [_cli(*r) for r in runs]
    for p in procs:
        _, err = p.communicate()
        if p.returncode:
            raise SystemExit(err.decode()[-2000:])
    return time.perf_counter() - t


def processes(counts, repeat: int, tmp: Path) -> None:
    import numpy as np

    import jaxgear as jg

    grid = ",".join(str(c) for c in counts)
    half = ",".join(str(c) for c in (*counts[:-1], counts[-1] // 2))
    print(f"2. jaxgear analyze, {counts} cells: 1 process on core 0 vs 2 processes (--distributed) on cores 0, 1 "
          f"(warm compilation cache, min of {repeat} after a warm-up)")
    base = ["analyze", "--no-figures", "--uncertainty-samples", "0", "--quiet"]
    cache = tmp / "cache"
    configs = {
        "1 process": lambda: [(base + ["--grid", grid, "--out", str(tmp / "one")], "0", cache)],
        "2 processes": lambda: [(base + ["--grid", grid, "--out", str(tmp / "two")], str(i), cache, 2, i, port)
                                for i in range(2)],
        "1 process, half the cells": lambda: [(base + ["--grid", half, "--out", str(tmp / "half")], "0", cache)],
        "2 separate processes, half the cells each": lambda: [
            (base + ["--grid", half, "--out", str(tmp / f"half{i}")], str(i), cache) for i in range(2)],
    }
    walls = {}
    for name, runs in configs.items():
        times = []
        for _ in range(repeat + 1):  # the first fills the compilation cache
            port = str(free_port())
            times.append(_wall(runs()))
        walls[name] = min(times[1:])
        print(f"   {name}: {walls[name]:.2f} s")
    one, two = jg.load(tmp / "one" / "result.nc"), jg.load(tmp / "two" / "result.nc")
    same = np.array_equal(one.labels, two.labels) and [a.share for a in one.attractors] == [
        a.share for a in two.attractors]
    print(f"   identical labels and shares: {same}")
    print(f"   the floor of 2 processes (1 process of half the cells: start, compilation cache, pilot and "
          f"tail are paid in full): {walls['1 process'] / walls['1 process, half the cells']:.2f}x")
    print(f"   the floor on this machine (2 separate processes of half the cells, one per core, no exchange): "
          f"{walls['1 process'] / walls['2 separate processes, half the cells each']:.2f}x")
    print(f"   processes ratio (1 process / 2 processes): {walls['1 process'] / walls['2 processes']:.2f}x")


def sweep(repeat: int) -> None:
    """Section 3: ``benchmarks/sweep_scale.py`` (its defaults) in a fresh process."""
    print(f"3. basin sweep of 8 backlash values on [20, 12, 24] cells: one pool vs separate analyses "
          f"(benchmarks/sweep_scale.py, min of {repeat} after a warm-up)")
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "sweep_scale.py"), "--repeat", str(repeat)],
                       env=env(), capture_output=True, text=True, check=True)
    for line in r.stdout.strip().splitlines()[1:]:
        print(f"   {line}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs=3, default=(50, 30, 60), help="cells of section 1")
    ap.add_argument("--process-counts", type=int, nargs=3, default=(50, 30, 60),
                    help="cells of section 2 (default the paper grid)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--only", choices=("devices", "processes", "sweep"), default=None)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if a.only in (None, "devices"):
            devices(list(a.counts), a.repeat, Path(tmp))
        if a.only in (None, "processes"):
            processes(list(a.process_counts), a.repeat, Path(tmp))
        if a.only in (None, "sweep"):
            sweep(a.repeat)


if __name__ == "__main__":
    main()
