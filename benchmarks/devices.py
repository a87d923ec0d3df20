"""Scaling past one device and one process: plain script, figures printed, nothing asserted.

    python benchmarks/devices.py                          # 20 x 12 x 24 cells, 4 sweep values
    python benchmarks/devices.py --counts 10 6 12 --values 2 --repeat 1

Measures in one run on this machine (the reduced gear model, paper preset, the default
method :class:`jaxgear.Direct`):

1. *devices*: :func:`jaxgear.analyze_global` on ``--counts`` cells with 1 and with 2
   forced host devices (``XLA_FLAGS=--xla_force_host_platform_device_count``, each in a
   fresh process; ``min`` over ``--repeat`` calls after a warm-up call, compilation
   apart), and whether both give the same labels and shares;
2. *processes*: the basin sweep of ``--values`` backlash values on the same grid as one
   process pinned to core 0 (``taskset -c 0``) and as two JAX processes
   (``jax.distributed.initialize``) pinned to cores 0 and 1, wall time of the whole
   command (start, compilation and the written file included in both), and whether
   both write the same file; as a reference for what the machine itself allows, two
   independent one-process sweeps of half the values each, pinned the same way, started
   together (on a machine shared with other jobs this is far from 2x).

Each section's last line is its ratio (one / two: above 1 is faster on two).
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

SWEEP = r'''
import json, sys, warnings
import numpy as np
import jaxgear as jg
warnings.simplefilter("ignore")
counts, n_values, out, n, pid, port = json.loads(sys.argv[1]), int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), sys.argv[6]
if n > 1:
    import jax
    jax.distributed.initialize(f"localhost:{port}", n, pid)
values = np.linspace(4.0, 6.0, n_values)
if len(sys.argv) > 7:  # one half of the values (the reference run)
    values = values[int(sys.argv[7])::2]
jg.basin_sweep(jg.REDUCED, jg.paper_params(), "b", values, jg.CellGrid.paper(tuple(counts)), progress=False, out=out)
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


def processes(counts, n_values: int, tmp: Path) -> None:
    import xarray as xr

    print(f"2. basin sweep, {n_values} values x {counts} cells: 1 process on core 0 vs 2 processes on cores 0, 1")
    walls = {}
    for n in (1, 2):
        out, port = tmp / f"sweep{n}", str(free_port())
        t = time.perf_counter()
        procs = [subprocess.Popen(["taskset", "-c", str(i), sys.executable, "-c", SWEEP, json.dumps(counts),
                                   str(n_values), str(out), str(n), str(i), port], env=env(),
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for i in range(n)]
        for p in procs:
            _, err = p.communicate()
            if p.returncode:
                raise SystemExit(err.decode()[-2000:])
        walls[n] = time.perf_counter() - t
        print(f"   {n} process(es): {walls[n]:.2f} s")
    # the machine's own capacity: two independent one-process sweeps of half the values each
    t = time.perf_counter()
    procs = [subprocess.Popen(["taskset", "-c", str(i), sys.executable, "-c", SWEEP, json.dumps(counts),
                               str(n_values), str(tmp / f"half{i}"), "1", "0", "0", str(i)], env=env(),
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for i in range(2)]
    for p in procs:
        _, err = p.communicate()
        if p.returncode:
            raise SystemExit(err.decode()[-2000:])
    walls["free"] = time.perf_counter() - t
    print(f"   reference, 2 independent processes of half the values each (no JAX runtime): {walls['free']:.2f} s")
    with xr.open_dataset(tmp / "sweep1" / "basins.nc", engine="h5netcdf") as a, \
            xr.open_dataset(tmp / "sweep2" / "basins.nc", engine="h5netcdf") as b:
        print(f"   identical files: {a.identical(b)}")
    print(f"   machine's parallel capacity (1 process / 2 independent halves): {walls[1] / walls['free']:.2f}x")
    print(f"   processes ratio (1 process / 2 processes): {walls[1] / walls[2]:.2f}x")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs=3, default=(20, 12, 24))
    ap.add_argument("--values", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--only", choices=("devices", "processes"), default=None)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if a.only != "processes":
            devices(list(a.counts), a.repeat, Path(tmp))
        if a.only != "devices":
            processes(list(a.counts), a.values, Path(tmp))


if __name__ == "__main__":
    main()
