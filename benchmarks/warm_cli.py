"""Wall time of a warm ``jaxgear analyze`` from the shell, this checkout against another
revision, in one run.

Each revision gets its own git worktree (made here in a temporary folder) and its own
warm compilation cache; the two commands then alternate ``--repeat`` times, so the load
of a shared machine falls on both alike. Prints each run, the best of each revision and
their ratio.

    python benchmarks/warm_cli.py --before REV [--repeat 3] [--grid 50,30,60]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _run(checkout: Path, cache: Path, out: Path, grid: str) -> float:
    env = dict(os.environ, PYTHONPATH=str(checkout), JAXGEAR_CACHE_DIR=str(cache))
    cmd = [sys.executable, "-m", "jaxgear", "analyze", "--quiet", "--out", str(out)]
    if grid:
        cmd += ["--grid", grid]
    t = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, capture_output=True, text=True)
    return time.perf_counter() - t


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--before", required=True, help="the git revision to compare with (e.g. a commit hash)")
    p.add_argument("--repeat", type=int, default=3, help="alternating warm runs of each (default 3)")
    p.add_argument("--grid", default="", help="cells per axis (default: the paper grid)")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="jaxgear-warm-cli-") as tmp:
        tmp = Path(tmp)
        before = tmp / "before"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(before), a.before], check=True,
                       capture_output=True)
        try:
            sides = {"before": before, "now": ROOT}
            for name, checkout in sides.items():  # cold runs: compile and fill each cache
                print(f"{name}: cold run {_run(checkout, tmp / f'cache-{name}', tmp / f'out-{name}', a.grid):.2f} s")
            times = {name: [] for name in sides}
            for i in range(a.repeat):
                for name, checkout in sides.items():
                    t = _run(checkout, tmp / f"cache-{name}", tmp / f"out-{name}", a.grid)
                    times[name].append(t)
                    print(f"{name}: warm run {i + 1}: {t:.2f} s")
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(before)], check=False,
                           capture_output=True)
    best = {name: min(ts) for name, ts in times.items()}
    print(f"\nbest warm run: before {best['before']:.2f} s, now {best['now']:.2f} s, "
          f"now / before = {best['now'] / best['before']:.3f}")


if __name__ == "__main__":
    main()
