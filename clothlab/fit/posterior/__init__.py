"""Posterior sampling of a fit with emcee: likelihood, priors, convergence, checkpoints, summaries.

Sampled coordinates are the unit box of :class:`clothlab.fit.problem.FitProblem` (x = (T(theta) - T(lo)) /
(T(hi) - T(lo)), T = log for log-scaled parameters), plus one coordinate for a noise scale when the data carry
no uncertainties.  So the **prior is uniform in the optimiser's transform**: uniform within the fit bounds for
linear parameters, log-uniform within them for log-scaled ones (DESIGN.md principle 4), zero outside.

Likelihood (per value n, channel c; model m = sum_k c_k[c] component_k(theta)[n]):

* measurement with ``sigma``: Gaussian, log L = -1/2 sum ((y - m) / sigma)^2;
* without ``sigma``: log-normal, log(m / y) ~ N(0, s^2) with s sampled (log-uniform prior on ``NOISE_RANGE``),
  log L = -sum [ log(m / y)^2 / (2 s^2) + log s ]  (m floored as in :data:`clothlab.fit.metrics.LOG_FLOOR`).

**The linear coefficients (kd, ks per channel and yarn type) are profiled out, not sampled**: at every
posterior point they are re-solved by weighted NNLS (weights 1 / sigma, or 1 / y for the log-normal case,
:func:`clothlab.fit.nnls.nnls_small`; paper sec. 8 fits them linearly too).  The chain therefore samples the
profile likelihood of the non-linear parameters: intervals are conditional on the best coefficients at each
point, which neglects the (small, with thousands of values per coefficient) extra width that marginalising the
coefficients would add, and a coefficient pinned at 0 by the non-negativity constraint contributes no width.

Convergence (emcee docs, "Autocorrelation analysis"; libraries.md): sample in chunks of ``check_every`` steps;
after each, the integrated autocorrelation time tau of every coordinate (``emcee.autocorr.integrated_time``,
tol=0); stop when ``tol_factor * max(tau) < steps`` and every tau changed by < 1 % since the previous check
(and at least ``steps`` were run), or at ``max_steps``.  Burn-in 2 max(tau) is discarded and the rest thinned
by max(1, min(tau) / 2).

Reproducible and resumable: the walkers start in a ball of radius ``BALL_RADIUS`` (unit coordinates, reflected
into the box) drawn from ``numpy.random.RandomState(seed)``, whose following state seeds the sampler (emcee has
no seed argument).  The checkpoint (``.npz``, written atomically by :mod:`clothlab.atomic` after every chunk and
on KeyboardInterrupt) holds the chain, log-probabilities and the sampler's random state after the last completed
step, so a resumed run yields the same chain as an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import InputError, ParameterError
from clothlab.fit.metrics import LOG_FLOOR, linear_weights
from clothlab.fit.nnls import nnls_small
from clothlab.fit.optimize import BOUND_TOLERANCE

NOISE_NAME = "noise.s"
NOISE_UNIT = "1 (std. dev. of log(model / measured))"
NOISE_RANGE = (1e-4, 2.0)
"""Log-uniform prior range of the log-normal noise scale s (used only without sigma columns)."""

BALL_RADIUS = 1e-3
"""Standard deviation of the initial walker ball around the optimum, in unit-box coordinates."""

TAU_CHANGE = 0.01
"""Convergence needs every tau to change by less than this fraction between successive checks."""

WIDE_FRACTION = 0.5
"""A 95 % interval covering more than this fraction of the prior (unit-box) range: not determined."""

PILE_MARGIN, PILE_FRACTION = 0.01, 0.10
"""More than PILE_FRACTION of the samples within PILE_MARGIN of the range from a bound: piles up at it."""

PRIOR_TEXT = ("uniform in the optimiser's transform within the fit bounds (uniform for linear parameters, "
              "log-uniform for log-scaled ones), zero outside")
CHECKPOINT_VERSION = 2


# ---------------------------------------------------------------------------------------------- likelihood
class _Likelihood:
    """log prior + log likelihood of a FitProblem on the unit box, vectorised over walkers."""

    def __init__(self, problem):
        self.problem = problem
        m = problem.measurement
        self.y = problem.y
        k = len(problem.free)
        self.names = list(problem.free)
        self.units = [s.unit for s in problem.specs]
        if m.sigma is not None:
            sigma = np.asarray(m.sigma, dtype=np.float64)
            bad = ~(np.isfinite(sigma) & (sigma > 0))
            if bad.any():
                row = int(np.argwhere(bad)[0][0])
                raise InputError(f"sigma must be finite and > 0 for the Gaussian likelihood; {int(bad.sum())} "
                                 f"values are not (first in row {row}: {float(sigma[bad][0])!r})",
                                 path=m.source, field="sigma")
            self.noise = "gaussian-sigma"
            self.weights = 1.0 / sigma
            self.ndim = k
        else:
            self.noise = "lognormal-fitted-scale"
            self.weights = linear_weights(self.y, "log")  # 1 / y; raises for measured <= 0
            self.ndim = k + 1
            self.names.append(NOISE_NAME)
            self.units.append(NOISE_UNIT)
        self.k = k

    @property
    def description(self) -> str:
        if self.noise == "gaussian-sigma":
            return "Gaussian on the values with the measurement's sigma: log L = -1/2 sum ((y - m) / sigma)^2"
        return ("log-normal: log(m / y) ~ N(0, s^2), s sampled with a log-uniform prior on "
                f"[{NOISE_RANGE[0]:g}, {NOISE_RANGE[1]:g}]: log L = -sum [log(m/y)^2 / (2 s^2) + log s]")

    def noise_scale(self, x):
        """s from its unit coordinate (log-uniform on NOISE_RANGE)."""
        lo, hi = np.log(NOISE_RANGE[0]), np.log(NOISE_RANGE[1])
        return np.exp(lo + np.asarray(x) * (hi - lo))

    def noise_unit(self, s) -> float:
        lo, hi = np.log(NOISE_RANGE[0]), np.log(NOISE_RANGE[1])
        return float(np.clip((np.log(s) - lo) / (hi - lo), 0.0, 1.0))

    def solve_many(self, params_list, wi=None, wo=None):
        """Profiled coefficients (k, m, C) for m parameter dicts (weighted NNLS on the measurement, one call for
        all of them) and the model (m, N', C) at (wi, wo) (the measurement's directions by default)."""
        problem = self.problem
        designs = np.stack([problem.design(p) for p in params_list], axis=2)  # (N, k, m)
        n_sets, n_channels = designs.shape[2], self.y.shape[1]
        coef, _ = nnls_small(np.repeat(designs, n_channels, axis=2), np.tile(self.y, (1, n_sets)),
                             np.tile(self.weights, (1, n_sets)))
        coef = coef.reshape(coef.shape[0], n_sets, n_channels)
        if wi is not None:
            designs = np.stack([_design_at(problem, p, wi, wo) for p in params_list], axis=2)
        return coef, np.einsum("nkm,kmc->mnc", designs, coef)

    def __call__(self, X) -> np.ndarray:
        """log posterior (up to a constant) at unit coordinates X (W, ndim); -inf outside the box."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        out = np.full(X.shape[0], -np.inf)
        inside = np.flatnonzero(np.all((X >= 0.0) & (X <= 1.0), axis=1))
        if inside.size == 0:
            return out
        params = [self.problem.from_unit(X[i, :self.k]) for i in inside]
        _, model = self.solve_many(params)  # (m, N, C)
        if self.noise == "gaussian-sigma":
            r = (self.y[None] - model) * self.weights[None]
            loglike = -0.5 * np.einsum("mnc,mnc->m", r, r)
        else:
            s = self.noise_scale(X[inside, self.k])
            with np.errstate(invalid="ignore"):
                r = np.log(np.maximum(model, LOG_FLOOR * self.y[None]) / self.y[None])
            loglike = -0.5 * np.einsum("mnc,mnc->m", r, r) / s**2 - self.y.size * np.log(s)
        out[inside] = np.where(np.isfinite(loglike), loglike, -np.inf)
        return out


def _design_at(problem, params, wi, wo) -> np.ndarray:
    """(N', k) model components of ``problem`` at other directions (un-normalised, like FitProblem.design)."""
    import warnings

    from clothlab.errors import GeometryWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        comps = problem.model.components(np.ascontiguousarray(wi, dtype=np.float64),
                                         np.ascontiguousarray(wo, dtype=np.float64), params, normalised=False,
                                         warn=False)
    return np.stack([comps[name] for name in problem.component_names], axis=1)


# ---------------------------------------------------------------------------------------------- checkpoint
def _model_settings(model) -> dict:
    """What of the model (besides the parameters) changes the likelihood: the quadrature (rule, nodes) of the
    IM yarn integrals, the other models' scalar options (e.g. Kang's tile_nodes), and the weave geometry."""
    out = {"kind": type(model).__name__}
    q = getattr(model, "quadrature", None)
    if q is not None:
        out["quadrature"] = {"rule": str(q.rule), "nodes": int(q.nodes)}
    for key, value in sorted(vars(model).items()):
        if not key.startswith("_") and key != "quadrature" and (value is None or isinstance(value, bool | int |
                                                                                             float | str)):
            out[key] = value
    weave = getattr(model, "weave", None)
    if weave is not None:
        from dataclasses import fields as dataclass_fields

        digest = hashlib.sha256(np.ascontiguousarray(weave.pattern).tobytes())
        digest.update(repr([getattr(weave, f.name) for f in dataclass_fields(weave)
                            if f.compare and f.name != "pattern"]).encode())
        out["weave"] = f"{weave.name}:{digest.hexdigest()[:16]}"
    return out


def _fingerprint(problem, like: _Likelihood, walkers: int, seed: int, x_opt: np.ndarray) -> str:
    """What fixes the target distribution and the chain: a resumed run must match it exactly.

    Keys of the target (:data:`TARGET_KEYS`: data, model and its quadrature, free / fixed parameters, bounds,
    noise model, the optimum the walkers start from) and of the sampler (walkers, seed, version).  The optimum
    is recorded in unit coordinates rounded to 10 significant digits (a rerun of the same seeded fit reproduces
    it; a changed fit budget or start does not)."""
    m = problem.measurement
    digest = hashlib.sha256()
    for array in (problem.y, m.sigma, problem.wi, problem.wo):
        if array is not None:
            digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    fixed = {k: v for k, v in sorted(problem.start.items()) if k not in problem.free}
    return json.dumps({"version": CHECKPOINT_VERSION, "model": _model_settings(problem.model), "free": like.names,
                       "lower": problem.lower.tolist(), "upper": problem.upper.tolist(), "fixed": fixed,
                       "noise": like.noise, "walkers": walkers, "seed": seed, "data": digest.hexdigest(),
                       "optimum": [f"{float(v):.10g}" for v in np.asarray(x_opt, dtype=np.float64)]},
                      sort_keys=True)


TARGET_KEYS = frozenset({"model", "free", "lower", "upper", "fixed", "noise", "data", "optimum"})
"""Fingerprint keys that define the target distribution (or its starting point): a checkpoint differing in any
of them (or in the checkpoint version) belongs to another fit and is replaced by a fresh run, with a message; a
checkpoint of the same target differing only in the sampler settings (walkers, seed) is refused, so a mistyped
option loses no chain."""


class _StaleCheckpoint(Exception):
    """The checkpoint was made for another target distribution (see TARGET_KEYS); ``diff`` names the keys."""

    def __init__(self, diff):
        super().__init__(", ".join(diff))
        self.diff = diff


@dataclass
class _ChainState:
    initial: np.ndarray  # (W, D) the starting ball
    chain: np.ndarray  # (n, W, D) unit coordinates
    log_prob: np.ndarray  # (n, W)
    coords: np.ndarray  # (W, D) last positions (the initial ones when n == 0)
    last_log_prob: np.ndarray  # (W,)
    random_state: tuple
    tau_history: dict = field(default_factory=dict)  # steps -> (D,) tau
    elapsed: float = 0.0  # sampling seconds of earlier sessions (resumed runs)
    started: float = field(default_factory=time.perf_counter)  # start of this session (perf_counter)

    @property
    def steps(self) -> int:
        return self.chain.shape[0]

    def session(self) -> float:
        """Seconds since this session started."""
        return time.perf_counter() - self.started


def _save_checkpoint(path: Path, fingerprint: str, st: _ChainState) -> None:
    """Write the chain state atomically (a reader sees the old or the new checkpoint, never a mix)."""
    name, keys, pos, has_gauss, cached = st.random_state
    steps_done = np.array(sorted(st.tau_history), dtype=np.int64)
    taus = np.array([st.tau_history[s] for s in steps_done]).reshape(len(steps_done), st.coords.shape[1])
    buf = io.BytesIO()
    np.savez(buf, fingerprint=np.array(fingerprint), initial=st.initial, chain=st.chain, log_prob=st.log_prob,
             coords=st.coords, last_log_prob=st.last_log_prob, rs_name=np.array(name), rs_keys=keys,
             rs_pos=np.array(pos), rs_has_gauss=np.array(has_gauss), rs_cached=np.array(cached),
             tau_steps=steps_done, tau_values=taus, elapsed=np.array(st.elapsed + st.session()))
    atomic_write_bytes(path, buf.getvalue())


def _load_checkpoint(path: Path, fingerprint: str) -> _ChainState:
    try:
        with np.load(path, allow_pickle=False) as z:
            stored = str(z["fingerprint"])
            data = {key: z[key] for key in z.files}
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"posterior checkpoint is unreadable ({exc}); delete it to start over", path=path) from None
    if stored != fingerprint:
        old, new = json.loads(stored), json.loads(fingerprint)
        diff = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
        if set(diff) & (TARGET_KEYS | {"version"}):
            raise _StaleCheckpoint(diff)
        raise InputError(f"posterior checkpoint was made with other settings (differs in: {', '.join(diff)}); "
                         "delete it to start over or restore the settings", path=path)
    tau = {int(s): v for s, v in zip(data["tau_steps"], data["tau_values"], strict=True)}
    rs = (str(data["rs_name"]), data["rs_keys"], int(data["rs_pos"]), int(data["rs_has_gauss"]),
          float(data["rs_cached"]))
    return _ChainState(data["initial"], data["chain"], data["log_prob"], data["coords"], data["last_log_prob"],
                       rs, tau, float(data["elapsed"]))


# ---------------------------------------------------------------------------------------------- sampling
def _initial_state(like: _Likelihood, x_opt: np.ndarray, walkers: int, seed: int) -> _ChainState:
    """Walkers in a ball around the optimum (unit coordinates, reflected into the box), checked finite."""
    rng = np.random.RandomState(seed)
    p0 = x_opt[None, :] + BALL_RADIUS * rng.standard_normal((walkers, like.ndim))
    p0 = np.abs(p0)  # reflect at 0 ...
    p0 = 1.0 - np.abs(1.0 - p0)  # ... and at 1: distinct walkers even for an optimum on a bound
    lp = like(p0)
    if not np.isfinite(lp).all():
        bad = np.flatnonzero(~np.isfinite(lp))
        raise ParameterError(f"log-probability is not finite for {bad.size} of {walkers} initial walkers around "
                             f"the optimum (first: {dict(zip(like.names, p0[bad[0]].tolist(), strict=True))} in "
                             "unit coordinates); the model cannot be evaluated near the optimum")
    D = like.ndim
    return _ChainState(p0, np.empty((0, walkers, D)), np.empty((0, walkers)), p0, lp, rng.get_state(legacy=True))


def _acceptance(chain: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """(W,) fraction of steps at which each walker moved (a proposal was accepted)."""
    if len(chain) == 0:
        return np.zeros(initial.shape[0])
    previous = np.concatenate([initial[None], chain[:-1]])
    return np.mean(np.any(chain != previous, axis=2), axis=0)


def _tau(chain: np.ndarray) -> np.ndarray:
    import emcee

    return np.asarray(emcee.autocorr.integrated_time(chain, c=5, tol=0), dtype=np.float64)


@contextlib.contextmanager
def _deferred_sigint():
    """Turn a first SIGINT into a flag checked between MCMC steps (so no step is cut in half and emcee does not
    print a traceback); a second SIGINT interrupts at once.  Only in the main thread under Python's default
    handler; otherwise nothing changes."""
    flag = {"hit": False}
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield flag
        return

    def handler(signum, frame):
        if flag["hit"]:
            raise KeyboardInterrupt
        flag["hit"] = True

    signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


class _Progress:
    """A one-line progress display on stderr (rewritten in place at most every 0.5 s)."""

    def __init__(self, enabled: bool, min_steps: int, max_steps: int):
        self.enabled, self.min_steps, self.max_steps = enabled, min_steps, max_steps
        self.last, self.start, self.note = 0.0, time.perf_counter(), ""

    def show(self, steps: int, acceptance: Callable[[], np.ndarray], force: bool = False):
        now = time.perf_counter()
        if not self.enabled or (not force and now - self.last < 0.5):
            return
        self.last = now
        sys.stderr.write(f"\rposterior: step {steps} (min {self.min_steps}, max {self.max_steps})  "
                         f"acceptance {np.mean(acceptance()):.2f}  {self.note}  {now - self.start:.0f} s   ")
        sys.stderr.flush()

    def close(self):
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()


def run_posterior(problem, optimum_params: dict, *, walkers: int, steps: int, max_steps: int, seed: int,
                  checkpoint_path=None, progress: bool = True, tol_factor: float = 50.0, check_every: int = 100,
                  max_seconds: float | None = None, moves=None,
                  on_step: Callable[[int], None] | None = None) -> PosteriorResult:
    """Sample the posterior of ``problem``'s free parameters with emcee (see the module docstring).

    Parameters
    ----------
    problem : FitProblem (its measurement, model, free parameters and fit bounds define the target).
    optimum_params : parameter dict at the optimum (e.g. ``FitResult.params``); walkers start around it.
    walkers : ensemble size (raised to 2 x dimensions, made even, if smaller; noted in the warnings).
    steps, max_steps : minimum number of steps before convergence may be declared, and the cap.
    seed : seeds the initial ball and the sampler; the same seed and settings give the same chain.
    checkpoint_path : ``.npz`` file; resumed from when it exists (same settings required), rewritten after each
        chunk of ``check_every`` steps and on KeyboardInterrupt (then the interrupt is re-raised).  A checkpoint
        of another target (other data, model, quadrature rule / nodes, bounds or optimum; :data:`TARGET_KEYS`)
        is replaced by a new chain, with a message on stderr and in the warnings; one of the same target with
        other walkers or seed is refused (InputError).
    tol_factor : convergence needs ``tol_factor * max(tau) < steps`` (and tau settled to 1 %).
    max_seconds : optional wall-time cap (the run then stops unconverged after the current step).
    moves : emcee moves (default: emcee's stretch move).
    on_step : called with the number of completed steps after each step (tests raise KeyboardInterrupt here).
    """
    import emcee

    started = time.perf_counter()
    like = _Likelihood(problem)
    notes: list[str] = []
    need = 2 * like.ndim
    if walkers < need or walkers % 2:
        fixed = max(walkers, need) + (max(walkers, need) % 2)
        notes.append(f"walkers raised from {walkers} to {fixed} (emcee needs an even number >= 2 x {like.ndim} "
                     "sampled dimensions)")
        walkers = fixed
    if not 1 <= steps <= max_steps:
        raise ValueError(f"need 1 <= steps <= max_steps, got steps = {steps}, max_steps = {max_steps}")
    if check_every < 1:
        raise ValueError(f"check_every must be >= 1, got {check_every}")
    x_opt = problem.to_unit(optimum_params)
    if like.noise != "gaussian-sigma":
        sol = problem.solve(optimum_params)
        r = np.log(np.maximum(sol.prediction, LOG_FLOOR * like.y) / like.y)
        x_opt = np.append(x_opt, like.noise_unit(max(float(np.sqrt(np.mean(r**2))), NOISE_RANGE[0])))
    fingerprint = _fingerprint(problem, like, walkers, seed, x_opt)
    path = Path(checkpoint_path) if checkpoint_path is not None else None
    resumed_from = 0
    st = None
    if path is not None and path.exists():
        try:
            st = _load_checkpoint(path, fingerprint)
            resumed_from = st.steps
        except _StaleCheckpoint as stale:
            message = (f"posterior checkpoint {path} belongs to another fit (differs in: {stale}); starting a new "
                       "chain (the old checkpoint is replaced)")
            notes.append(message)
            sys.stderr.write(message + "\n")
    if st is None:
        st = _initial_state(like, x_opt, walkers, seed)
    st.started = started

    sampler = emcee.EnsembleSampler(walkers, like.ndim, like, vectorize=True, moves=moves)
    bar = _Progress(progress, steps, max_steps)
    chain_chunks, lp_chunks = [st.chain], [st.log_prob]
    n = st.steps
    stop_reason = None

    def snapshot() -> _ChainState:
        """Fold the recorded steps into ``st`` (the recorded list is the single source of truth)."""
        nonlocal chain_chunks, lp_chunks
        chain_chunks = [np.concatenate(chain_chunks)]
        lp_chunks = [np.concatenate(lp_chunks)]
        st.chain, st.log_prob = chain_chunks[0], lp_chunks[0]
        return st

    def tau_at(m: int) -> np.ndarray:
        if m not in st.tau_history:
            st.tau_history[m] = _tau(np.concatenate(chain_chunks)[:m])
        return st.tau_history[m]

    with _deferred_sigint() as sigint:
        try:
            while True:
                if n > 0 and (n % check_every == 0 or n >= max_steps):
                    tau = tau_at(n)
                    prev = n - check_every
                    settled = prev > 0 and np.all(np.abs(tau_at(prev) - tau) < TAU_CHANGE * tau)
                    bar.note = f"tau_max {np.max(tau):.1f} (needs {tol_factor * np.max(tau):.0f} steps)"
                    if path is not None:
                        _save_checkpoint(path, fingerprint, snapshot())
                    if n >= steps and tol_factor * np.max(tau) < n and settled:
                        stop_reason = "converged"
                        break
                    if n >= max_steps:
                        stop_reason = "max_steps"
                        break
                if max_seconds is not None and time.perf_counter() - started > max_seconds:
                    stop_reason = "max_seconds"
                    break
                todo = min(check_every - n % check_every, max_steps - n)
                # One list.append per completed step (atomic with respect to SIGINT): coordinates, log-probability
                # and the random state after that step always travel together.
                record: list = []
                try:
                    for state in sampler.sample(emcee.State(st.coords, log_prob=st.last_log_prob,
                                                            random_state=st.random_state),
                                                iterations=todo, store=False, skip_initial_state_check=True):
                        record.append((state.coords.copy(), state.log_prob.copy(), state.random_state))
                        n = sum(len(c) for c in chain_chunks) + len(record)
                        bar.show(n, lambda rec=record: _acceptance(np.concatenate(chain_chunks + [[r[0] for r in rec]]),
                                                        st.initial))
                        if on_step is not None:
                            on_step(n)
                    if sigint["hit"]:
                        raise KeyboardInterrupt
                finally:
                    if record:
                        chain_chunks.append(np.array([r[0] for r in record]))
                        lp_chunks.append(np.array([r[1] for r in record]))
                        st.coords, st.last_log_prob, st.random_state = record[-1]
                    n = sum(len(c) for c in chain_chunks)
        except KeyboardInterrupt:
            if path is not None:
                _save_checkpoint(path, fingerprint, snapshot())
            bar.close()
            raise
    snapshot()
    if path is not None:
        _save_checkpoint(path, fingerprint, st)
    bar.show(n, lambda: _acceptance(st.chain, st.initial), force=True)
    bar.close()
    return _summarise(problem, like, optimum_params, x_opt, st, seed=seed, walkers=walkers, min_steps=steps,
                      max_steps=max_steps, tol_factor=tol_factor, check_every=check_every, stop_reason=stop_reason,
                      wall_time=st.elapsed + st.session(), resumed_from=resumed_from, notes=notes,
                      moves_text="emcee default (stretch move, a = 2)" if moves is None else repr(moves))


# ---------------------------------------------------------------------------------------------- results
def _summarise(problem, like, optimum_params, x_opt, st, *, seed, walkers, min_steps, max_steps, tol_factor,
               check_every, stop_reason, wall_time, resumed_from, notes, moves_text) -> PosteriorResult:
    n = st.steps
    if n < 2:
        raise ValueError("the posterior run stopped before two steps were sampled (max_seconds too small?)")
    tau = st.tau_history.get(n)
    if tau is None:
        tau = _tau(st.chain)
    converged = stop_reason == "converged"
    burn = min(int(2 * np.max(tau)), n // 2)
    thin = max(1, int(0.5 * np.min(tau)))
    kept = st.chain[burn::thin]
    unit = kept.reshape(-1, like.ndim)
    samples = _to_declared(problem, like, unit)
    if not converged:
        notes.append(f"not converged ({stop_reason}): {n} steps, {tol_factor:g} x max tau = "
                     f"{tol_factor * np.max(tau):.0f}; treat the intervals as indicative only")
    return PosteriorResult(problem=problem, names=list(like.names), units=list(like.units), samples=samples,
                           unit_samples=unit, chain=st.chain, log_prob=st.log_prob, tau=tau,
                           acceptance=_acceptance(st.chain, st.initial), burn_in=burn, thin=thin, converged=converged,
                           steps=n, walkers=walkers, wall_time=wall_time, seed=seed, noise=like.noise,
                           likelihood=like.description, optimum=dict(optimum_params), optimum_unit=x_opt,
                           min_steps=min_steps, max_steps=max_steps, tol_factor=tol_factor, check_every=check_every,
                           stop_reason=stop_reason, resumed_from=resumed_from, warnings=notes, _like=like,
                           moves=moves_text)


def _to_declared(problem, like, unit: np.ndarray) -> np.ndarray:
    """(M, D) unit coordinates -> declared units (via FitProblem.from_unit; noise scale appended)."""
    k = like.k
    out = np.empty_like(unit)
    for i, x in enumerate(unit):
        p = problem.from_unit(x[:k])
        out[i, :k] = [p[name] for name in problem.free]
    if like.ndim > k:
        out[:, k] = like.noise_scale(unit[:, k])
    return out


@dataclass
class PosteriorResult:
    """Posterior samples (after burn-in and thinning) and their summaries.

    ``samples`` (M, D) in declared units, ``unit_samples`` the same in unit-box coordinates; ``chain`` (steps,
    walkers, D) and ``log_prob`` the full chain in unit coordinates; ``tau`` (D,) integrated autocorrelation
    times [steps]; ``acceptance`` (walkers,) acceptance fractions.
    """

    problem: object
    names: list
    units: list
    samples: np.ndarray
    unit_samples: np.ndarray
    chain: np.ndarray
    log_prob: np.ndarray
    tau: np.ndarray
    acceptance: np.ndarray
    burn_in: int
    thin: int
    converged: bool
    steps: int
    walkers: int
    wall_time: float
    seed: int
    noise: str
    likelihood: str
    optimum: dict
    optimum_unit: np.ndarray
    min_steps: int
    max_steps: int
    tol_factor: float
    check_every: int
    stop_reason: str | None
    resumed_from: int
    moves: str = "emcee default (stretch move, a = 2)"
    warnings: list = field(default_factory=list)
    _like: object = None

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size per coordinate: walkers x (steps - burn-in) / tau."""
        return self.walkers * (self.steps - self.burn_in) / self.tau

    def percentiles(self) -> dict:
        """name -> {median, p16, p84, p2.5, p97.5} in declared units."""
        q = np.percentile(self.samples, [50, 16, 84, 2.5, 97.5], axis=0)
        return {name: dict(zip(("median", "p16", "p84", "p2.5", "p97.5"), map(float, q[:, j]), strict=True))
                for j, name in enumerate(self.names)}

    def correlation(self) -> np.ndarray:
        """(D, D) correlation of the sampled coordinates (linear in the transform: log for log-scaled)."""
        return np.corrcoef(self.unit_samples, rowvar=False).reshape(len(self.names), len(self.names))

    def identifiability(self) -> dict:
        """name -> list of reasons it is "not determined by these data" (empty when it is determined).

        Reasons: the 95 % interval covers more than WIDE_FRACTION of the prior range (unit-box coordinates);
        more than PILE_FRACTION of the samples lie within PILE_MARGIN of the range from a bound; the optimum
        lies at a bound (within BOUND_TOLERANCE of the range, as the optimiser flags it).
        """
        u = self.unit_samples
        lo95, hi95 = np.percentile(u, [2.5, 97.5], axis=0)
        out = {}
        for j, name in enumerate(self.names):
            reasons = []
            if hi95[j] - lo95[j] > WIDE_FRACTION:
                reasons.append(f"95 % interval spans {100 * (hi95[j] - lo95[j]):.0f} % of the allowed range")
            for side, near in (("lower", u[:, j] < PILE_MARGIN), ("upper", u[:, j] > 1.0 - PILE_MARGIN)):
                if np.mean(near) > PILE_FRACTION:
                    reasons.append(f"posterior piles up at the {side} bound ({100 * np.mean(near):.0f} % of "
                                   f"samples within {100 * PILE_MARGIN:g} % of the range)")
            x = self.optimum_unit[j]
            if j < len(self.problem.free) and (x <= BOUND_TOLERANCE or x >= 1.0 - BOUND_TOLERANCE):
                reasons.append(f"optimum at the {'lower' if x <= BOUND_TOLERANCE else 'upper'} bound")
            out[name] = reasons
        return out

    def not_determined(self) -> list:
        return [name for name, reasons in self.identifiability().items() if reasons]

    def _bounds(self, j: int) -> tuple[float, float]:
        if j < len(self.problem.free):
            return float(self.problem.lower[j]), float(self.problem.upper[j])
        return NOISE_RANGE

    def predictive_bands(self, wi, wo, *, draws: int = 200, percentiles=(5, 50, 95), seed: int = 0) -> dict:
        """Posterior-predictive bands of the model (noise excluded) at directions (wi, wo) (M, 3) each.

        ``draws`` posterior samples (drawn with ``seed``) are evaluated, each with its profiled coefficients;
        returns {"p5": (M, C), "p50": ..., "p95": ...} in 1/sr and "draws".
        """
        rng = np.random.default_rng(seed)
        pick = rng.choice(len(self.unit_samples), size=min(draws, len(self.unit_samples)), replace=False)
        params = [self.problem.from_unit(x[:len(self.problem.free)]) for x in self.unit_samples[pick]]
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        if wi.shape != wo.shape or wi.shape[1] != 3:
            raise ValueError(f"wi and wo must both have shape (M, 3), got {wi.shape} and {wo.shape}")
        values = []
        for start in range(0, len(params), 32):
            values.append(self._like.solve_many(params[start:start + 32], wi, wo)[1])
        q = np.percentile(np.concatenate(values), percentiles, axis=0)
        out = {f"p{p:g}": q[i] for i, p in enumerate(percentiles)}
        out["draws"] = len(params)
        return out

    def to_json(self) -> dict:
        """JSON-ready summary (posterior.json)."""
        pct = self.percentiles()
        ident = self.identifiability()
        truth = (self.problem.measurement.provenance or {}).get("parameters", {}) \
            if (self.problem.measurement.provenance or {}).get("simulated") else {}
        params = {}
        for j, name in enumerate(self.names):
            lo, hi = self._bounds(j)
            entry = {"unit": self.units[j], **pct[name], "lower": lo, "upper": hi,
                     "optimum": float(self.optimum[name]) if name in self.optimum
                     else float(self._like.noise_scale(self.optimum_unit[j])),
                     "tau": float(self.tau[j]), "ess": float(self.ess[j]),
                     "determined": not ident[name], "reasons": ident[name]}
            if name in truth:
                entry["truth"] = float(truth[name])
                entry["truth_in_95"] = bool(pct[name]["p2.5"] <= truth[name] <= pct[name]["p97.5"])
            params[name] = entry
        corr = self.correlation()
        warn = list(self.warnings)
        for name, reasons in ident.items():
            if reasons:
                warn.append(f"{name}: not determined by these data ({'; '.join(reasons)})")
        return {
            "method": "emcee EnsembleSampler (vectorised log-probability)",
            "moves": self.moves,
            "prior": PRIOR_TEXT,
            "likelihood": self.likelihood,
            "noise_model": self.noise,
            "coefficients": ("profiled out: kd, ks re-solved by weighted NNLS at every sample (not sampled); "
                             "intervals are conditional on the best coefficients at each point"),
            "parameters": params,
            "correlation": {"names": list(self.names), "matrix": _finite(corr),
                            "coordinates": "sampled (unit-box) coordinates: log for log-scaled parameters"},
            "not_determined": [n for n, r in ident.items() if r],
            "identifiability_rule": (f"not determined by these data: 95 % interval wider than {WIDE_FRACTION:.0%} "
                                     f"of the prior range (unit-box coordinates), or > {PILE_FRACTION:.0%} of samples "
                                     f"within {PILE_MARGIN:.0%} of the range from a bound, or optimum at a bound"),
            "convergence": {
                "converged": self.converged, "stop_reason": self.stop_reason,
                "rule": (f"{self.tol_factor:g} x max(tau) < steps and every tau changed < {100 * TAU_CHANGE:g} % "
                         f"between checks every {self.check_every} steps, at least {self.min_steps} steps, "
                         f"at most {self.max_steps}"),
                "steps": self.steps, "walkers": self.walkers, "burn_in": self.burn_in, "thin": self.thin,
                "samples": int(len(self.samples)), "tau": dict(zip(self.names, map(float, self.tau), strict=True)),
                "ess": dict(zip(self.names, map(float, self.ess), strict=True)),
                "acceptance_fraction": {"mean": float(np.mean(self.acceptance)),
                                        "min": float(np.min(self.acceptance)),
                                        "max": float(np.max(self.acceptance))},
                "resumed_from_step": self.resumed_from,
            },
            "seed": self.seed,
            "wall_time_s": self.wall_time,
            "wall_time_note": "sampling seconds summed over all sessions of a resumed run",
            "warnings": warn,
        }

    def corner_figure(self, truths=None):
        """Corner plot (corner.corner) of the samples in declared units; truths default to the generating
        values of simulated data, if recorded."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import corner

        if truths is None:
            prov = self.problem.measurement.provenance or {}
            known = prov.get("parameters", {}) if prov.get("simulated") else {}
            truths = [known.get(n) for n in self.names] if any(n in known for n in self.names) else None
        labels = [f"{n} [{u}]" if u and not u.startswith("1 ") else n for n, u in zip(self.names, self.units,
                                                                                      strict=True)]
        return corner.corner(self.samples, labels=labels, truths=truths, quantiles=[0.16, 0.5, 0.84],
                             show_titles=True, title_fmt=".3g")


def _finite(matrix: np.ndarray) -> list:
    return [[float(v) if math.isfinite(v) else None for v in row] for row in np.asarray(matrix)]
