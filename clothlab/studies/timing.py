"""The timing harness every benchmark section shares: fastest-call timings, paired (alternating) timings and
the machine description recorded beside the figures.

On a shared machine the minimum over many calls is the estimate least disturbed by other processes, and a
ratio of two run times is stable to a few per cent only when the two are timed call by call in alternation.
"""

from __future__ import annotations

import math
import os
import platform
import time

MIN_SAMPLE_S = 0.02
"""Every timing round calls a function for at least this long (a 1 ms evaluation ~20 times) and keeps the
fastest single call: one call of a sub-millisecond evaluation is too noisy to compare."""


def machine() -> dict:
    """CPU count, platform, processor and the versions of the packages clothlab uses."""
    from clothlab.fit.runner import package_versions

    return {"cpus": os.cpu_count(), "platform": platform.platform(), "processor": platform.processor(),
            "versions": package_versions()}


def clear_memo(model) -> None:
    """Empty a model's per-direction cache, if it has one, so that a timing measures the full evaluation."""
    model.forget_results()


def _once(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def _batch_size(fn, min_sample_s: float) -> int:
    """Calls per timing round (one call of ``fn`` measures it; that call also warms it up)."""
    return max(1, math.ceil(min_sample_s / max(_once(fn), 1e-9)))


def _fastest_call(fn, calls: int) -> float:
    return min(_once(fn) for _ in range(calls))


def best_time(fn, repeats: int, min_sample_s: float = MIN_SAMPLE_S) -> float:
    """Seconds per call of ``fn``: the fastest of ``repeats`` rounds of calls, each round lasting at least
    ``min_sample_s`` (so at least ``repeats`` calls)."""
    calls = _batch_size(fn, min_sample_s) if min_sample_s > 0 else 1
    return min(_fastest_call(fn, calls) for _ in range(repeats))


def paired_timings(base, fns, rounds: int, min_sample_s: float = MIN_SAMPLE_S):
    """Run times of ``fns`` against ``base``, each timed in strict alternation with it (base, fn, base, fn, ...:
    at least ``rounds`` pairs, and pairs lasting ``rounds x min_sample_s`` in all).

    Returns the base's fastest call over all pairings and, per function, (its fastest call, its fastest call /
    the base's fastest call in its own pairing).  Alternating call by call, a change in the machine's load hits
    both sides of a ratio alike.  A function that ``is`` the base is not timed again: it gets the base's fastest
    call and ratio 1."""
    t_base = max(_once(base), 1e-9)  # also the warm-up
    base_best, out = t_base, []
    for fn in fns:
        if fn is base:
            out.append(None)
            continue
        t_fn = max(_once(fn), 1e-9)
        pairs = max(rounds, math.ceil(rounds * min_sample_s / (t_fn + t_base)))
        best_b = best_f = math.inf
        for _ in range(pairs):
            best_b = min(best_b, _once(base))
            best_f = min(best_f, _once(fn))
        base_best = min(base_best, best_b)
        out.append((best_f, best_f / best_b))
    return base_best, [(base_best, 1.0) if o is None else o for o in out]


def alternating_timings(fns: list, rounds: int, min_sample_s: float = 0.05) -> list[dict]:
    """Seconds per call of each function in ``fns``, called in strict alternation (f0, f1, ..., f0, f1, ...) for
    at least ``rounds`` rounds and ``rounds x min_sample_s`` in all: per function the fastest call's wall time
    (``wall_s``, time.perf_counter) and CPU time (``cpu_s``, time.process_time, this process), and the median
    call's CPU time (``cpu_median_s``).  Alternating call by call, a change in the machine's load hits all alike;
    the CPU time of this process is what other processes disturb least."""
    import statistics

    best = [{"wall_s": math.inf, "cpu_s": math.inf} for _ in fns]
    cpu: list[list[float]] = [[] for _ in fns]
    start = time.perf_counter()
    done = 0
    while done < rounds or time.perf_counter() - start < rounds * min_sample_s:
        for b, calls, fn in zip(best, cpu, fns, strict=True):
            t, c = time.perf_counter(), time.process_time()
            fn()
            c = time.process_time() - c
            b["wall_s"] = min(b["wall_s"], time.perf_counter() - t)
            b["cpu_s"] = min(b["cpu_s"], c)
            calls.append(c)
        done += 1
    for b, calls in zip(best, cpu, strict=True):
        b["cpu_median_s"] = statistics.median(calls)
    return best
