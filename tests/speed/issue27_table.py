"""Issue 27's table, re-measured side by side: two checkouts (``before`` and ``after``) timed in alternation in
one run, so that the machine's load hits both alike.  Not a test (pytest does not collect it); run it on a
quiet machine and paste its output into docs/notes/speed.md::

    git worktree add /tmp/before 90be147 && git worktree add /tmp/after HEAD
    python tests/speed/issue27_table.py /tmp/before /tmp/after [--rounds 3] [--skip-main-job]

In-process figures run in a fresh interpreter per checkout and round (``PYTHONPATH=<checkout>``), each the
fastest of many calls after a warm-up (compilation excluded):

- objective: one ``FitProblem.__call__`` on cotton-denim (1,575 directions x 3 channels) at 64 points near the
  start (the memo is dropped between points by the new point itself);
- IM whole model per preset: ``IrawanModel.components`` (trapezoid-11, preset defaults) on the paper's 1,575
  directions, *warm* (the results memo cleared, the direction set kept) and *cold* (new directions every call:
  the set rotated by a fresh tiny angle so nothing cached applies; the rotation, two numpy (1575, 3) @ (3, 3)
  products, ~16 us, is inside the timed call) and *cold, pre-made* (new directions every call as well, taken in
  turn from 64 sets rotated before the timing, so the timed call is the model's alone; the model keeps only the
  last set, so each is new to it);
- Kang tile average per preset, cold: ``KangModel.components(need=specular)`` on new directions every call, at
  the preset's defaults and, where ``fits/<preset>-kang`` exists, at that fit's parameters (e.g. wool-gabardine's
  fitted lobe, nx 18.7, ny 0.71).

The main job (``clothlab -q fit fabric.yaml --force --report`` in a copy of measurements/polyester-lining):
first run on an empty ``NUMBA_CACHE_DIR``, then the second run; wall (perf_counter around the subprocess) and
CPU (children's user + sys).  The fit's own stages come from its fit.json ``timings``.  The load average is
printed before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

WORKER = r'''
import json, sys, time
import numpy as np

def best(fn, min_s=0.3, min_calls=15):
    fn()
    b, c, n, t0 = np.inf, np.inf, 0, time.perf_counter()
    while n < min_calls or time.perf_counter() - t0 < min_s:
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        b, c = min(b, time.perf_counter() - w0), min(c, time.process_time() - c0)
        n += 1
    return {"wall_s": b, "cpu_s": c}

def forget(model):
    if hasattr(model, "forget_results"):
        model.forget_results()
    elif hasattr(model, "_memo"):
        model._memo.clear()

from pathlib import Path
from clothlab.config import load_config
from clothlab.fit.problem import build_problem
from clothlab.fit.store import load_fitted
from clothlab.models.irawan.model import IrawanModel
from clothlab.models.kang.model import KangModel
from clothlab.simulate.gonio import paper_sampling
from clothlab.weave.presets import PRESET_NAMES, get_preset

out = {}
problem = build_problem(load_config("measurements/cotton-denim/fabric.yaml"))
rng = np.random.default_rng(0)
x0 = problem.to_unit(problem.start)
points = np.clip(x0 + rng.normal(0.0, 0.02, (64, len(x0))), 0.0, 1.0)
k = [0]
def objective():
    k[0] = (k[0] + 1) % len(points)
    problem(points[k[0]])
out["objective"] = best(objective, min_s=1.0, min_calls=200)

from clothlab.frames import spherical_to_vector
ti, pi_, to, po = paper_sampling()
wi, wo = spherical_to_vector(ti, pi_), spherical_to_vector(to, po)

def rotated(a):
    c, d = np.cos(a), np.sin(a)
    r = np.array([[c, -d, 0.0], [d, c, 0.0], [0.0, 0.0, 1.0]])
    return wi @ r.T, wo @ r.T

angles = iter(np.linspace(1e-4, 0.5, 100000))
for name in PRESET_NAMES:
    weave = get_preset(name)
    im = IrawanModel(weave)
    p = im.resolve({})
    def warm():
        forget(im)
        im.components(wi, wo, p)
    def cold():
        a, b = rotated(next(angles))
        forget(im)
        im.components(a, b, p)
    pool = [rotated(next(angles)) for _ in range(64)]
    turn = [0]
    def cold_premade():
        turn[0] = (turn[0] + 1) % len(pool)
        forget(im)
        im.components(*pool[turn[0]], p)
    kang = KangModel(weave)
    q = kang.resolve({})
    need = ("specular_warp", "specular_weft")
    def kang_cold():
        a, b = rotated(next(angles))
        forget(kang)
        kang.components(a, b, q, need=need)
    out[name] = {"im_warm": best(warm), "im_cold": best(cold), "im_cold_premade": best(cold_premade),
                 "kang_cold": best(kang_cold)}
    fit_dir = Path(f"fits/{name}-kang")
    if (fit_dir / "fit.json").exists():
        fitted, params, _, _ = load_fitted(fit_dir)
        q_fit = fitted.resolve({k: v for k, v in params.items() if k in fitted.params})
        def kang_fitted():
            a, b = rotated(next(angles))
            forget(fitted)
            fitted.components(a, b, q_fit, need=need)
        out[name]["kang_cold_fitted"] = best(kang_fitted)
out["pairs"] = len(wi)
print(json.dumps(out))
'''


def in_process(checkout: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(checkout), "OPENBLAS_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, "-c", WORKER], cwd=checkout, env=env, capture_output=True, text=True,
                       check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main_job(checkout: Path, cache: Path) -> dict:
    work = Path(tempfile.mkdtemp(prefix="issue27-"))
    pl = work / "measurements" / "polyester-lining"  # its fits/ and reports/ land in work/, as in the repo
    shutil.copytree(checkout / "measurements" / "polyester-lining", pl)
    env = {**os.environ, "PYTHONPATH": str(checkout), "NUMBA_CACHE_DIR": str(cache)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "clothlab", "-q", "fit", "fabric.yaml", "--force", "--report"],
                   cwd=pl, env=env, check=True, capture_output=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    fit = json.loads((work / "fits" / "polyester-lining" / "fit.json").read_text())
    shutil.rmtree(work)
    return {"wall_s": wall, "cpu_s": cpu, "timings": fit["timings"]}


def merge(rounds: list[dict]) -> dict:
    """Fastest of the rounds, per figure."""
    out = {}
    for key, value in rounds[0].items():
        if isinstance(value, dict) and "cpu_s" in value:
            out[key] = {f: min(r[key][f] for r in rounds) for f in ("wall_s", "cpu_s")}
        elif isinstance(value, dict):
            out[key] = merge([r[key] for r in rounds])
        else:
            out[key] = value
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--skip-main-job", action="store_true")
    parser.add_argument("--cpu", action="store_true", help="per-preset tables from CPU time (a loaded machine)")
    a = parser.parse_args()
    print(f"load average at start: {os.getloadavg()}")
    checkouts = {"before": a.before.resolve(), "after": a.after.resolve()}
    commits = {k: subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=c, capture_output=True,
                                 text=True).stdout.strip() for k, c in checkouts.items()}
    rounds = {k: [] for k in checkouts}
    for _ in range(a.rounds):
        for k, c in checkouts.items():
            rounds[k].append(in_process(c))
    result = {k: merge(v) for k, v in rounds.items()}
    if not a.skip_main_job:
        jobs = {k: {"first": [], "second": []} for k in checkouts}
        for _ in range(2):
            for k, c in checkouts.items():
                cache = Path(tempfile.mkdtemp(prefix="numba-"))
                jobs[k]["first"].append(main_job(c, cache))
                jobs[k]["second"].append(main_job(c, cache))
                shutil.rmtree(cache)
        for k in checkouts:
            result[k]["main_job"] = {n: min(v, key=lambda r: r["wall_s"]) for n, v in jobs[k].items()}
    print(f"load average at end: {os.getloadavg()}")
    print(json.dumps({"commits": commits, **result}, indent=1))
    b, f = result["before"], result["after"]
    print(f"\n| figure | before ({commits['before']}) | after ({commits['after']}) |\n|---|---|---|")
    if "main_job" in b:
        for n in ("second", "first"):
            print(f"| main job, {n} run: wall (CPU) | {b['main_job'][n]['wall_s']:.1f} s "
                  f"({b['main_job'][n]['cpu_s']:.1f} s) | {f['main_job'][n]['wall_s']:.1f} s "
                  f"({f['main_job'][n]['cpu_s']:.1f} s) |")
        for stage in ("optimisation_s", "posterior_s"):
            print(f"| {stage} (second run) | {b['main_job']['second']['timings'][stage]:.2f} s | "
                  f"{f['main_job']['second']['timings'][stage]:.2f} s |")
    print(f"| objective (fastest wall / CPU) | {b['objective']['wall_s'] * 1e3:.3f} / "
          f"{b['objective']['cpu_s'] * 1e3:.3f} ms | {f['objective']['wall_s'] * 1e3:.3f} / "
          f"{f['objective']['cpu_s'] * 1e3:.3f} ms |")
    clock = "cpu_s" if a.cpu else "wall_s"
    n = b["pairs"]
    print("\n| preset | IM warm / cold ms, ratio (before) | IM warm / cold ms, ratio (after) | "
          "IM cold pre-made ms, ratio (before) | (after) |\n|---|---|---|---|---|")
    for name, v in b.items():
        if not (isinstance(v, dict) and "im_warm" in v):
            continue
        w = f[name]
        cells = []
        for r in (v, w):
            cells.append(f"{r['im_warm'][clock] * 1e3:.3f} / {r['im_cold'][clock] * 1e3:.3f}, "
                         f"{r['im_cold'][clock] / r['im_warm'][clock]:.2f}x")
        for r in (v, w):
            cells.append(f"{r['im_cold_premade'][clock] * 1e3:.3f}, "
                         f"{r['im_cold_premade'][clock] / r['im_warm'][clock]:.2f}x" if "im_cold_premade" in r
                         else "-")
        print(f"| {name} | " + " | ".join(cells) + " |")
    print("\n| preset | Kang cold M pairs/s, defaults: before | after | fitted (fits/<preset>-kang): before | "
          "after |\n|---|---|---|---|---|")
    for name, v in b.items():
        if not (isinstance(v, dict) and "kang_cold" in v):
            continue
        w = f[name]
        fitted = [f"{n / r['kang_cold_fitted'][clock] / 1e6:.2f}" if "kang_cold_fitted" in r else "-"
                  for r in (v, w)]
        print(f"| {name} | {n / v['kang_cold'][clock] / 1e6:.2f} | {n / w['kang_cold'][clock] / 1e6:.2f} | "
              f"{fitted[0]} | {fitted[1]} |")
    print(f"\n({clock} of each checkout's fastest call; the JSON above has both clocks)")


if __name__ == "__main__":
    main()
