"""A small mutation-testing sweep over clothlab's core (issue 25 item 8): do the tests fail when the code is wrong?

Each entry of :data:`MUTANTS` is one deliberate single-line change (an operator swapped, a constant moved by
one, a statement dropped) to one of the core modules - the IM kernels (clothlab/models/irawan/kernels.py), the
NNLS solver (clothlab/fit/nnls.py, nnls_kernels.py), cross-validation (clothlab/fit/crossval.py), the posterior
checkpoint (clothlab/fit/posterior/checkpoint.py) and the strict readers (clothlab/untrusted.py).  For each, the
script applies the change to a **copy** of the package in a temporary directory (the checkout is never
touched), runs that module's tests (:data:`TESTS`) against the copy (``PYTHONPATH`` and the working directory
point at the copy), and calls the mutant *killed* when a test fails, *survived* when all pass.  The score is
killed / mutants, per module and overall.  The unmutated copy is run first and must pass (else nothing is
scored).

Usage (from the repository root; stdlib only, ~5-10 min on 2 cores, most of it numba recompiling the kernels)::

    python tests/mutation/run.py                 # the working tree as it is
    python tests/mutation/run.py --ref HEAD      # a commit (git archive): reproducible while others edit
    python tests/mutation/run.py --ref HEAD --only crossval-offset-dropped strict-limit-65
    python tests/mutation/run.py --list          # the mutants, no run
    python tests/mutation/run.py --check         # every mutation site occurs exactly once (working tree or --ref)

A mutation whose source line is not found exactly once is reported as ``missing`` (the code moved: update its
entry), never silently scored.  Scores and the commands of the last runs: docs/notes/mutation.md.  Run it before
a large change to the core and after adding tests; a survivor is either a missing test or an equivalent mutant
(say which in the notes).  The default test suite does not run this sweep (tests/mutation/test_run.py is
marked slow: ``--runslow``).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
COPIED = ("clothlab", "tests", "measurements", "fits/polyester-lining", "docs", "README.md", "pyproject.toml")
"""What the copy holds (the tests read measurements/, one saved fit and docs/ by paths relative to the root)."""

KERNELS = "clothlab/models/irawan/kernels.py"
NNLS = "clothlab/fit/nnls.py"
NNLS_KERNELS = "clothlab/fit/nnls_kernels.py"
CROSSVAL = "clothlab/fit/crossval.py"
CHECKPOINT = "clothlab/fit/posterior/checkpoint.py"
STRICT = "clothlab/untrusted.py"

TESTS = {
    "kernels": ("tests/test_irawan_kernels.py",),
    "nnls": ("tests/test_nnls.py",),
    "crossval": ("tests/test_crossval.py",),
    "checkpoint": ("tests/test_posterior.py",),
    "strict": ("tests/test_strict_limits.py", "tests/test_fuzz_inputs.py", "tests/test_fuzz_faults.py",
               "tests/test_fuzz_loaders.py", "tests/test_fuzz_corpus.py", "tests/test_io_table.py",
               "tests/test_config.py"),
}
"""The tests run for a mutant of each module (a file missing at the chosen ref is skipped)."""


@dataclass(frozen=True)
class Mutant:
    name: str
    module: str  # key of TESTS
    path: str
    old: str  # must occur exactly once in the file
    new: str
    what: str


MUTANTS = (
    # --- the IM kernels (Irawan & Marschner 2012, sec. 5-7)
    Mutant("kernels-axis-ratio-sign", "kernels", KERNELS,
           "return 1.0 + kappa * (1.0 + 1.0 / np.tan(umax))", "return 1.0 - kappa * (1.0 + 1.0 / np.tan(umax))",
           "sec. 5.4 r_hat: + -> -"),
    Mutant("kernels-half-length-sign", "kernels", KERNELS,
           "return 0.5 * l - 0.5 * w * np.sin(umax)", "return 0.5 * l + 0.5 * w * np.sin(umax)",
           "sec. 5.3 L: - -> +"),
    Mutant("kernels-seeliger-denominator", "kernels", KERNELS,
           "return ci * cr / (ci + cr)  # eq. 8", "return ci * cr / (ci * cr)  # eq. 8",
           "eq. 8 Seeliger: ci + cr -> ci * cr"),
    Mutant("kernels-smoothstep-constant", "kernels", KERNELS,
           "return x * x * (3.0 - 2.0 * x)", "return x * x * (3.0 - 3.0 * x)", "eq. 9 s(x): 2 x^3 -> 3 x^3"),
    Mutant("kernels-volume-element-sign", "kernels", KERNELS,
           "return a * (radius + a * cos_v)", "return a * (radius - a * cos_v)", "sec. 6.2 a (R + a cos v): + -> -"),
    Mutant("kernels-staple-cosines-or-and", "kernels", KERNELS,
           "    if ci <= 0.0 or cr <= 0.0:\n        return 0.0, cos_v, sin_v",
           "    if ci <= 0.0 and cr <= 0.0:\n        return 0.0, cos_v, sin_v",
           "eq. 8 staple: both cosines must be > 0 (or -> and)"),
    Mutant("kernels-lit-arc-side", "kernels", KERNELS,
           "    if wx > 0.0:\n        return v0, 0.5 * math.pi", "    if wx < 0.0:\n        return v0, 0.5 * math.pi",
           "lit arc: > -> <"),
    # --- NNLS
    Mutant("nnls-fallback-never-runs", "nnls", NNLS,
           "retry = np.flatnonzero(status == 1)", "retry = np.flatnonzero(status == 3)",
           "the QR re-solve of a failed check never runs (issue 25 survivor)"),
    Mutant("nnls-careful-path-unweighted-data", "nnls", NNLS,
           "np.multiply(wT, y.T, out=aug[:, k])", "np.multiply(1.0, y.T, out=aug[:, k])",
           "QR path: data row weights dropped"),
    Mutant("nnls-non-finite-status", "nnls", NNLS,
           "bad = status == 2", "bad = status == 1", "non-finite problems: status 2 -> 1"),
    Mutant("nnls-kernel-feasibility-dropped", "nnls", NNLS_KERNELS,
           "            if not feasible:\n                continue", "            if False:\n                continue",
           "negative supports not skipped (statement dropped)"),
    Mutant("nnls-kernel-best-comparison", "nnls", NNLS_KERNELS,
           "if s < best_score:", "if s > best_score:", "best support: < -> >"),
    Mutant("nnls-kernel-unscaled-coefficients", "nnls", NNLS_KERNELS,
           "best[idx[i]] = x[i] * scale[idx[i]]", "best[idx[i]] = x[i]", "column scaling not undone"),
    Mutant("nnls-kernel-check-never-fails", "nnls", NNLS_KERNELS,
           "            status[p] = 1\n", "            pass\n", "a failed check is not flagged (statement dropped)"),
    # --- cross-validation
    Mutant("crossval-offset-dropped", "crossval", CROSSVAL,
           "offset += rows.size", "pass", "grouped folds restart at fold 0 in every group (issue 25 survivor)"),
    Mutant("crossval-random-not-shuffled", "crossval", CROSSVAL,
           "labels[rng.permutation(measurement.n)] = np.arange(measurement.n) % k",
           "labels[np.arange(measurement.n)] = np.arange(measurement.n) % k",
           "random scheme deals rows in file order (issue 25 survivor)"),
    Mutant("crossval-held-out-mask", "crossval", CROSSVAL,
           "test = job.labels == fold", "test = job.labels != fold", "fold's held-out rows: == -> !="),
    Mutant("crossval-auto-grouped-boundary", "crossval", CROSSVAL,
           "    if smallest >= k:\n        return \"grouped\"", "    if smallest > k:\n        return \"grouped\"",
           "auto picks grouped: >= k -> > k"),
    Mutant("crossval-group-too-small-boundary", "crossval", CROSSVAL,
           "if rows.size < k:", "if rows.size < k - 1:", "a group of k - 1 rows accepted (off by one)"),
    # --- the posterior checkpoint
    Mutant("checkpoint-fingerprint-without-wo", "checkpoint", CHECKPOINT,
           "for array in (problem.y, m.sigma, problem.wi, problem.wo):",
           "for array in (problem.y, m.sigma, problem.wi):",
           "fingerprint omits the exitant directions (issue 25 survivor)"),
    Mutant("checkpoint-fingerprint-without-rule", "checkpoint", CHECKPOINT,
           'out["quadrature"] = {"rule": str(q.rule), "nodes": int(q.nodes)}',
           'out["quadrature"] = {"nodes": int(q.nodes)}',
           "fingerprint omits the quadrature rule"),
    Mutant("checkpoint-stale-check-dropped", "checkpoint", CHECKPOINT,
           "        if set(diff) & (TARGET_KEYS | {\"version\"}):", "        if False:",
           "another target refused instead of replaced"),
    Mutant("checkpoint-optimum-rounding", "checkpoint", CHECKPOINT,
           '"optimum": [f"{float(v):.10g}"', '"optimum": [f"{float(v):.2g}"', "optimum recorded to 2 digits, not 10"),
    # --- strict readers
    Mutant("strict-limit-65", "strict", STRICT,
           "MAX_NUMBER_CHARS = 64", "MAX_NUMBER_CHARS = 65", "the 64-character number limit moved by one (issue 25 "
           "survivor)"),
    Mutant("strict-limit-comparison", "strict", STRICT,
           "    if len(text) > MAX_NUMBER_CHARS:\n        raise error(",
           "    if len(text) >= MAX_NUMBER_CHARS:\n        raise error(", "a 64-character number refused (> -> >=)"),
    Mutant("strict-infinity-spelling", "strict", STRICT,
           'if text.lower().lstrip("+-") in ("nan", "inf", "infinity"):',
           'if text.lower().lstrip("+-") in ("nan", "inf"):',
           "'infinity' no longer named as not finite"),
    Mutant("strict-int-digits-boundary", "strict", STRICT,
           "if digits > MAX_INT_DIGITS:", "if digits >= MAX_INT_DIGITS:", "a 30-digit YAML integer refused"),
    Mutant("strict-file-size-boundary", "strict", STRICT,
           "    if info.st_size > limit:", "    if info.st_size >= limit:", "a file of exactly the limit refused"),
)


# ------------------------------------------------------------------------------------------------- the copy
def make_copy(dest: Path, ref: str | None) -> None:
    """The package, tests, measurements and pyproject.toml of ``ref`` (git archive) or of the working tree."""
    if ref is not None:
        archive = dest / "src.tar"
        with open(archive, "wb") as out:
            subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref, *COPIED], stdout=out, check=True)
        with tarfile.open(archive) as tar:
            tar.extractall(dest, filter="data")
        archive.unlink()
        return
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".hypothesis")
    for name in COPIED:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=ignore)
        else:
            shutil.copy2(src, dest / name)


def environment(copy: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(copy) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.pop("NUMBA_CACHE_DIR", None)  # the copy's own __pycache__: compiled code of a mutant stays in the copy
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def run_tests(copy: Path, files: tuple[str, ...], timeout: float) -> tuple[str, float, str]:
    """('pass' | 'fail' | 'timeout' | 'error', seconds, last line of pytest's output)."""
    present = [f for f in files if (copy / f).exists()]
    if not present:
        return "error", 0.0, "no test file of this module at this ref"
    # one process: with pytest-xdist's -n auto (pyproject addopts) a -x stop is "interrupted", exit code 2
    single = ["-n", "0"] if importlib.util.find_spec("xdist") else []
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *single, *present]
    started = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=copy, env=environment(copy), capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "timeout", time.perf_counter() - started, f"over {timeout:.0f} s"
    lines = [line for line in proc.stdout.splitlines() if line.strip()]
    last = lines[-1] if lines else proc.stderr.strip().splitlines()[-1:] or [""]
    last = last if isinstance(last, str) else last[0]
    outcome = {0: "pass", 1: "fail"}.get(proc.returncode, "error")
    return outcome, time.perf_counter() - started, last


def check_sites(mutants, ref: str | None = None) -> list[str]:
    """Names of the mutants whose ``old`` text does not occur exactly once in the working tree (or at ``ref``)."""
    def text(path: str) -> str:
        if ref is None:
            return (ROOT / path).read_text()
        return subprocess.run(["git", "-C", str(ROOT), "show", f"{ref}:{path}"], capture_output=True, text=True,
                              check=True).stdout

    return [m.name for m in mutants if text(m.path).count(m.old) != 1]


# ------------------------------------------------------------------------------------------------- the sweep
def sweep(mutants, ref: str | None, timeout: float, keep: Path | None) -> int:
    workdir = Path(tempfile.mkdtemp(prefix="clothlab-mutation-")) if keep is None else keep
    workdir.mkdir(parents=True, exist_ok=True)
    copy = workdir / "repo"
    if copy.exists():
        shutil.rmtree(copy)
    copy.mkdir()
    try:
        make_copy(copy, ref)
        where = subprocess.run([sys.executable, "-c", "import clothlab; print(clothlab.__file__)"], cwd=copy,
                               env=environment(copy), capture_output=True, text=True, check=True).stdout.strip()
        if not Path(where).resolve().is_relative_to(copy.resolve()):
            print(f"the copy's clothlab is not the one imported ({where}); aborting", file=sys.stderr)
            return 2
        source = f"git {ref}" if ref else "working tree"
        print(f"mutation sweep of {source} in {copy}; {len(mutants)} mutants")
        modules = sorted({m.module for m in mutants}, key=list(TESTS).index)
        for module in modules:  # the unmutated copy must pass (this also compiles the numba caches once)
            outcome, seconds, last = run_tests(copy, TESTS[module], timeout)
            print(f"  baseline {module:<10} {outcome:<7} {seconds:6.1f} s  {last}")
            if outcome != "pass":
                print(f"the unmutated {module} tests do not pass; nothing scored", file=sys.stderr)
                return 2
        results = []
        for m in mutants:
            path = copy / m.path
            original = path.read_bytes()
            text = original.decode()
            if text.count(m.old) != 1:
                results.append((m, "missing", 0.0, f"site found {text.count(m.old)} times"))
                print(f"  {m.name:<40} missing")
                continue
            path.write_text(text.replace(m.old, m.new))
            try:
                outcome, seconds, last = run_tests(copy, TESTS[m.module], timeout)
            finally:
                path.write_bytes(original)
            verdict = {"fail": "killed", "timeout": "killed", "pass": "SURVIVED"}.get(outcome, "error")
            results.append((m, verdict, seconds, last))
            print(f"  {m.name:<40} {verdict:<9} {seconds:6.1f} s  {m.what}")
        report(results)
        return 0
    finally:
        if keep is None:
            shutil.rmtree(workdir, ignore_errors=True)


def report(results) -> None:
    """Score per module and overall; survivors listed."""
    print("\nmodule      killed / scored")
    total_killed = total = 0
    for module in TESTS:
        rows = [r for r in results if r[0].module == module and r[1] in ("killed", "SURVIVED")]
        if not rows:
            continue
        killed = sum(r[1] == "killed" for r in rows)
        total_killed, total = total_killed + killed, total + len(rows)
        print(f"{module:<11} {killed:>3} / {len(rows):<3}")
    if total:
        print(f"mutation score: {total_killed} / {total} = {100.0 * total_killed / total:.0f} %")
    for m, verdict, _, last in results:
        if verdict != "killed":
            print(f"  {verdict}: {m.name} ({m.path}: {m.what}) {last if verdict != 'SURVIVED' else ''}".rstrip())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ref", help="a git commit to copy (git archive) instead of the working tree")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="run these mutants only")
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--check", action="store_true",
                        help="check every site occurs once in the working tree (or at --ref)")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per test run (default 900)")
    parser.add_argument("--keep", type=Path, help="work in this directory and keep it (default: a temporary one)")
    args = parser.parse_args(argv)
    mutants = MUTANTS
    if args.only:
        unknown = sorted(set(args.only) - {m.name for m in MUTANTS})
        if unknown:
            parser.error(f"unknown mutant(s): {', '.join(unknown)}")
        mutants = tuple(m for m in MUTANTS if m.name in args.only)
    if args.list:
        for m in mutants:
            print(f"{m.name:<40} {m.path}: {m.what}")
        return 0
    if args.check:
        missing = check_sites(mutants, args.ref)
        print("every mutation site found once" if not missing else f"sites not found once: {', '.join(missing)}")
        return 1 if missing else 0
    return sweep(mutants, args.ref, args.timeout, args.keep)


if __name__ == "__main__":
    sys.exit(main())
