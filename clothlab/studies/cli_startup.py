"""Bench section ``cli``: the start-up cost a user feels - ``python -m clothlab --help`` wall time (best and
median of 5, fresh interpreters) - and which heavy modules ``import clothlab`` pulls in (should be none)."""

from __future__ import annotations

import subprocess
import sys
import time

HEAVY_MODULES = ("matplotlib", "colour", "OpenImageIO", "emcee", "nlopt", "numba", "scipy")


def cli_startup(runs: int = 5) -> dict:
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "clothlab", "--help"], capture_output=True, check=True)
        times.append(time.perf_counter() - t)
    code = f"import sys, clothlab; print(','.join(m for m in {HEAVY_MODULES!r} if m in sys.modules))"
    heavy = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    times.sort()
    return {"help_seconds_best": times[0], "help_seconds_median": times[len(times) // 2],
            "import_pulls": heavy.split(",") if heavy else []}


def run(context) -> dict:
    return cli_startup()


def lines(result: dict) -> list[str]:
    return ["== cli ==", f"  clothlab --help: best {result['help_seconds_best']:.3f} s (median "
            f"{result['help_seconds_median']:.3f} s); import clothlab pulls in: "
            f"{', '.join(result['import_pulls']) or 'none of the heavy modules'}"]
