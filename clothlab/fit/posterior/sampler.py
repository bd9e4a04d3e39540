"""Sampling the posterior with emcee: the walkers' start, chunks of steps, the convergence rule, resume.

Convergence (emcee docs, "Autocorrelation analysis"): sample in chunks of ``check_every`` steps; after each,
the integrated autocorrelation time tau of every coordinate (``emcee.autocorr.integrated_time``, tol=0); stop
(the default ``ess`` rule) once tau is stable - every tau changed by < :data:`TAU_STABLE` since the previous
check and steps >= :data:`TAU_RELIABLE` x max(tau) - and the smallest effective sample size reaches
:data:`ESS_TARGET`, or (the ``tau`` rule) when ``tol_factor * max(tau) < steps`` and every tau changed by
< :data:`TAU_CHANGE`; in both at least ``steps`` steps, at most ``max_steps``.  Burn-in 2 max(tau) is
discarded and the rest thinned by max(1, min(tau) / 2).  Measured side by side: ``clothlab bench --sections
posterior`` (docs/notes/speed.md).

Through a pool (issue 13): with a :class:`clothlab.parallel.Runner` the log-probability of the walkers emcee
hands over in one call is split into one chunk per worker slot, each chunk a task (the likelihood is placed on
the workers once).  Every walker's value depends on its own coordinates only, so the chain is the in-process
one bit for bit.  ``pool="auto"`` (the default) times both ways on the initial half-ensemble and keeps the
pool only when it is faster (small problems: the transfer costs more than the work); in-process is the
default without a runner.

Reproducible and resumable: the walkers start from the Laplace approximation (:data:`DEFAULT_START`) or in a
ball of radius :data:`BALL_RADIUS` (unit coordinates, reflected into the box), drawn from
``numpy.random.RandomState(seed)``, whose following state seeds the sampler (emcee has no seed argument);
:mod:`clothlab.fit.posterior.checkpoint` keeps the state between sessions.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from clothlab.errors import ParameterError
from clothlab.fit.metrics import LOG_FLOOR
from clothlab.fit.posterior.checkpoint import (
    _ChainState,
    _fingerprint,
    _load_checkpoint,
    _save_checkpoint,
    _StaleCheckpoint,
)
from clothlab.fit.posterior.likelihood import NOISE_RANGE, _Likelihood
from clothlab.fit.posterior.result import PosteriorResult
from clothlab.parallel import raise_failures
from clothlab.progress import Progress, get_logger

log = get_logger(__name__)

BALL_RADIUS = 1e-3
"""Standard deviation of the initial walker ball around the optimum, in unit-box coordinates."""

TAU_CHANGE = 0.01
"""The ``tau`` rule needs every tau to change by less than this fraction between successive checks."""

STOPS = ("ess", "tau")
DEFAULT_STOP = "ess"
ESS_TARGET = 1000.0
"""The ``ess`` rule: stop when the smallest effective sample size, walkers x (steps - burn-in) / max(tau), reaches
this (the 2.5 % and 97.5 % quantiles then carry a Monte Carlo error below 0.1 posterior standard deviations)."""
TAU_STABLE = 0.05
"""The ``ess`` rule needs every tau to change by less than this fraction between successive checks (tau is
stable: its estimate on a chain of a few hundred steps fluctuates by several per cent, so the 1 % of the
``tau`` rule waits for chance agreement)."""
TAU_RELIABLE = 20.0
"""The ``ess`` rule needs steps >= this x max(tau) (the estimate of tau itself is biased low on shorter
chains; emcee docs, "Autocorrelation analysis")."""

LAPLACE_MAX_SD = 0.1
"""The Laplace start's standard deviation per unit coordinate is capped at this (a tenth of the box): where the
data hardly determine a coordinate the approximation means nothing and the prior's box is the scale."""
STARTS = ("laplace", "ball")
DEFAULT_START = "laplace"
"""Walkers start from the Laplace approximation at the optimum: the Gauss-Newton covariance of the likelihood's
own residuals (:func:`clothlab.fit.uncertainty.laplace_covariance`), so the ensemble starts with the
posterior's spread and orientation and burn-in is short; ``ball`` is the tiny ball of :data:`BALL_RADIUS` (the
ensemble has to grow to the posterior's width first).  A singular Gauss-Newton matrix falls back to the ball."""


def laplace_start(like: _Likelihood, x_opt: np.ndarray) -> np.ndarray | None:
    """(D, D) covariance of the sampled coordinates at ``x_opt`` by the Laplace approximation of the likelihood:
    Gauss-Newton on its own residuals (r = (m - y) / sigma; or log(m / y) with the noise scale s, the
    covariance then s^2 (J^T J)^-1 and the noise coordinate's variance 1 / (2 n) in log s), the coefficients
    profiled at every point (one batched call for all 2 k shifted points).  None when singular."""
    from clothlab.fit.uncertainty import STEP, central_jacobian, laplace_covariance

    k = like.k

    def residuals_many(X):
        _, model = like.solve_many(like.problem.from_unit_many(X))
        if like.noise == "gaussian-sigma":
            return ((model - like.y[None]) * like.weights[None]).reshape(len(X), -1)
        return np.log(np.maximum(model, LOG_FLOOR * like.y[None]) / like.y[None]).reshape(len(X), -1)

    if k == 0:
        return None
    J = central_jacobian(residuals_many, x_opt[:k], STEP)
    scale = 1.0
    if like.noise != "gaussian-sigma":
        s = like.noise_scale(x_opt[k])
        scale = float(s * s)
    cov = laplace_covariance(J, scale)
    if cov is None:
        return None
    sd = np.sqrt(np.diag(cov))  # a coordinate the data hardly determine: the prior's box bounds it, not J
    cap = np.minimum(1.0, LAPLACE_MAX_SD / sd)
    cov = cov * np.outer(cap, cap)
    if like.ndim > k:  # log s has variance 1 / (2 n); the unit coordinate is log s / log(hi / lo)
        span = np.log(NOISE_RANGE[1] / NOISE_RANGE[0])
        full = np.zeros((like.ndim, like.ndim))
        full[:k, :k] = cov
        full[k, k] = 1.0 / (2.0 * like.y.size) / span**2
        cov = full
    return cov


def _initial_state(like: _Likelihood, x_opt: np.ndarray, walkers: int, seed: int,
                   cov: np.ndarray | None = None) -> _ChainState:
    """Walkers around the optimum (unit coordinates, reflected into the box), checked finite: drawn from
    N(x_opt, cov) (the Laplace start; walkers whose log-probability is not finite are drawn again at half the
    spread, up to 8 times, then from the ball), or in the ball of :data:`BALL_RADIUS` when ``cov`` is None."""
    rng = np.random.RandomState(seed)
    z = rng.standard_normal((walkers, like.ndim))
    root = BALL_RADIUS * np.eye(like.ndim) if cov is None else np.linalg.cholesky(cov)

    def place(offsets):
        p = np.abs(x_opt[None, :] + offsets)  # reflect at 0 ...
        p = 1.0 - np.abs(1.0 - p)  # ... and at 1: distinct walkers even for an optimum on a bound
        if cov is None:
            return p
        p = np.mod(p, 2.0)  # a wide Laplace spread: reflected as often as it takes (still distinct walkers)
        return np.where(p > 1.0, 2.0 - p, p)

    p0 = place(z @ root.T)
    lp = like(p0)
    for attempt in range(9 if cov is not None else 0):  # the Laplace start: redraw the walkers outside
        bad = ~np.isfinite(lp)
        if not bad.any():
            break
        spread = 0.5 ** (attempt + 1) if attempt < 8 else BALL_RADIUS / np.sqrt(np.max(np.diag(cov)))
        p0[bad] = place(spread * (z[bad] @ root.T))
        lp[bad] = like(p0[bad])
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


class _Interruptible:
    """The log-probability as emcee calls it, with a Ctrl-C (and any other exception) kept out of emcee.

    emcee wraps the function in ``_FunctionWrapper``, whose bare ``except`` prints "emcee: Exception while
    calling your likelihood function" and a traceback for any exception, KeyboardInterrupt included (and a
    Ctrl-C landing in a compiled kernel comes out as a SystemError).  Here an exception inside the call is
    kept and every walker gets -inf (the call returns normally, so emcee prints nothing); the step that saw it
    is then discarded by the sampling loop, which raises it itself (:meth:`raise_kept`): the chain and its
    checkpoint hold only whole steps of the uninterrupted chain."""

    def __init__(self, log_prob):
        self.log_prob = log_prob
        self.kept: BaseException | None = None

    @property
    def interrupted(self) -> bool:
        return self.kept is not None

    def __call__(self, X) -> np.ndarray:
        if self.kept is None:
            try:
                return self.log_prob(X)
            except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - raised again outside emcee
                self.kept = exc
        return np.full(len(np.atleast_2d(X)), -np.inf)

    def raise_kept(self) -> None:
        """KeyboardInterrupt for an interrupt (also one a compiled kernel turned into another error while a
        Ctrl-C was recorded, :func:`clothlab.atomic.was_interrupted`), else the exception itself."""
        from clothlab.atomic import was_interrupted

        exc, self.kept = self.kept, None
        if exc is None:
            return
        if isinstance(exc, KeyboardInterrupt) or was_interrupted():
            raise KeyboardInterrupt
        raise exc


def _chunk_log_prob(like, X):
    """One pool task: the log-probabilities of a chunk of walkers."""
    return like(X)


class _PooledLogProb:
    """``like(X)`` for a batch of walkers as one task per chunk on ``runner`` (one chunk per worker slot)."""

    def __init__(self, like: _Likelihood, runner):
        self.runner = runner
        self.shared = runner.share(like)
        self.chunks = max(1, int(runner.workers))

    def __call__(self, X) -> np.ndarray:
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        parts = np.array_split(X, min(self.chunks, len(X)))
        out = self.runner.map(_chunk_log_prob, parts, shared=self.shared, desc="posterior walkers", progress=False)
        return np.concatenate(raise_failures(out, "posterior log-probability chunks"))


def _best_time(fn, X, repeats: int = 2) -> float:
    best = np.inf
    for _ in range(repeats):
        tic = time.perf_counter()
        fn(X)
        best = min(best, time.perf_counter() - tic)
    return best


def choose_log_prob(like: _Likelihood, runner, pool, half: np.ndarray):
    """The log-probability emcee calls: ``like`` itself, or through ``runner``'s pool (:class:`_PooledLogProb`)
    when ``pool`` is True, or when ``pool == "auto"`` and the pool evaluated ``half`` (the walkers of one emcee
    call) faster than in-process (after one warm-up call that places the model on the workers).
    Returns (function, {"pool": bool, "in_process_s": .., "pool_s": ..})."""
    if runner is None or pool is False:
        return like, {"pool": False}
    if pool not in (True, "auto"):
        raise ValueError(f"pool must be True, False or 'auto', got {pool!r}")
    pooled = _PooledLogProb(like, runner)
    if pool is True:
        return pooled, {"pool": True}
    pooled(half)  # warm-up: the workers load the model and compile nothing twice
    local_s, pool_s = _best_time(like, half), _best_time(pooled, half)
    use = pool_s < local_s
    log.info("posterior: %d walkers per call, in-process %.3g s, pool of %d %.3g s: %s", len(half), local_s,
             pooled.chunks, pool_s, "using the pool" if use else "staying in-process")
    return (pooled if use else like), {"pool": use, "in_process_s": local_s, "pool_s": pool_s}


class _StepProgress:
    """The sampler's progress: one :class:`clothlab.progress.Progress` of steps, its description naming the
    minimum and the cap and, after each convergence check, the tau estimate."""

    def __init__(self, enabled: bool, min_steps: int, max_steps: int, resumed: int = 0):
        self.head = f"posterior (min {min_steps}, max {max_steps})"
        self.bar = Progress(max_steps, self.head, unit="step", enabled=None if enabled else False)
        self.bar.update(resumed)

    def note(self, text: str) -> None:
        self.bar.set_description(f"{self.head}, {text}")

    def step(self) -> None:
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


#: The proposal of the posterior (default of :func:`run_posterior`): differential-evolution moves (ter Braak
#: 2006) with a fifth of snooker updates (ter Braak & Vrugt 2008), emcee's ``DEMove`` and ``DESnookerMove``.
#: Against emcee's default stretch move, same targets, 32 walkers, seed 1: polyester-lining max tau 57 -> 29,
#: 3,900 -> 2,700 steps to the tau rule; cotton-twill 112 -> 45, 6,600 -> 3,600 steps (docs/notes/posterior-moves.md;
#: ``clothlab bench --sections posterior`` measures both side by side).
DEFAULT_MOVES = "de-snooker"
MOVES = {"stretch": "emcee stretch move (a = 2)",
         "de-snooker": "emcee DEMove 0.8 + DESnookerMove 0.2 (differential evolution)",
         "gaussian": "emcee GaussianMove, Metropolis with the Laplace covariance x 2.38^2 / D"}


def make_moves(name: str = DEFAULT_MOVES, cov: np.ndarray | None = None):
    """The emcee moves called ``name`` (:data:`MOVES`); ``gaussian`` needs ``cov``, the Laplace covariance of
    the sampled coordinates (:func:`laplace_start`), scaled by 2.38^2 / D (the optimal random-walk scale for a
    Gaussian target, Gelman, Roberts & Gilks 1996)."""
    import emcee

    if name == "stretch":
        return emcee.moves.StretchMove()
    if name == "de-snooker":
        return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    if name == "gaussian":
        if cov is None:
            raise ValueError("the gaussian moves need the Laplace covariance, which is singular here")
        return emcee.moves.GaussianMove(cov * 2.38**2 / cov.shape[0])
    raise ValueError(f"unknown moves {name!r}; expected one of {', '.join(MOVES)}")


def run_posterior(problem, optimum_params: dict, *, walkers: int, steps: int, max_steps: int, seed: int,
                  checkpoint_path=None, progress: bool = True, tol_factor: float = 50.0, check_every: int = 100,
                  max_seconds: float | None = None, moves: str = DEFAULT_MOVES,
                  on_step: Callable[[int], None] | None = None, runner=None, pool="auto",
                  start: str = DEFAULT_START, stop: str = DEFAULT_STOP,
                  ess_target: float = ESS_TARGET) -> PosteriorResult:
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
        is replaced by a new chain, with a logged warning and a note in the warnings; one of the same target
        with other walkers or seed is refused (InputError).
    progress : show progress ("posterior (min 1000, max 12000): 1200/12000 step") through
        :class:`clothlab.progress.Progress` when it is enabled; False: never.
    tol_factor : the ``tau`` rule needs ``tol_factor * max(tau) < steps`` (and tau settled to 1 %).
    max_seconds : optional wall-time cap (the run then stops unconverged after the current step).
    moves : the proposal, a name of :data:`MOVES` (default :data:`DEFAULT_MOVES`); part of the checkpoint's
        sampler settings (a checkpoint made with other moves is refused, like other walkers or seed).
    on_step : called with the number of completed steps after each step (tests raise KeyboardInterrupt here).
    runner, pool : a :class:`clothlab.parallel.Runner` to evaluate chunks of walkers on, and whether to use it
        (True, False or "auto": measured, :func:`choose_log_prob`); the chain is the same either way.
    start : ``laplace`` (default: walkers drawn from the Laplace approximation, :func:`laplace_start`) or
        ``ball`` (:data:`BALL_RADIUS`); part of the checkpoint's sampler settings.
    stop : ``ess`` (default): at least ``steps``, every tau changed < :data:`TAU_STABLE` since the previous
        check, steps >= :data:`TAU_RELIABLE` x max(tau) and the smallest effective sample size
        walkers x (steps - burn-in) / max(tau) >= ``ess_target``; ``tau``: the emcee docs' rule,
        ``tol_factor`` x max(tau) < steps and every tau changed < :data:`TAU_CHANGE`.
    """
    import emcee

    started = time.perf_counter()
    like = _Likelihood(problem)
    if like.ndim == 0:
        raise ValueError("nothing to sample: the problem has no free parameter (its coefficients are solved exactly)")
    notes: list[str] = []
    need = 2 * like.ndim
    if walkers < need or walkers % 2:
        fixed = max(walkers, need) + (max(walkers, need) % 2)
        notes.append(f"walkers raised from {walkers} to {fixed} (emcee needs an even number >= 2 x {like.ndim} "
                     "sampled dimensions)")
        walkers = fixed
    if not 1 <= steps <= max_steps:
        raise ValueError(f"need 1 <= steps <= max_steps, got steps = {steps}, max_steps = {max_steps}")
    from clothlab.config.validate import MAX_POSTERIOR_STEPS, MAX_WALKERS

    if max_steps > MAX_POSTERIOR_STEPS or walkers > MAX_WALKERS:  # the documented limits of fabric.yaml
        raise ValueError(f"at most {MAX_POSTERIOR_STEPS} steps and {MAX_WALKERS} walkers, got max_steps = "
                         f"{max_steps}, walkers = {walkers}")
    if check_every < 1:
        raise ValueError(f"check_every must be >= 1, got {check_every}")
    x_opt = problem.to_unit(optimum_params)
    if like.noise != "gaussian-sigma":
        sol = problem.solve(optimum_params)
        r = np.log(np.maximum(sol.prediction, LOG_FLOOR * like.y) / like.y)
        x_opt = np.append(x_opt, like.noise_unit(max(float(np.sqrt(np.mean(r**2))), NOISE_RANGE[0])))
    if moves not in MOVES:
        raise ValueError(f"unknown moves {moves!r}; expected one of {', '.join(MOVES)}")
    if start not in STARTS or stop not in STOPS:
        raise ValueError(f"start must be one of {', '.join(STARTS)} and stop one of {', '.join(STOPS)}, got "
                         f"{start!r}, {stop!r}")
    cov = laplace_start(like, x_opt) if start == "laplace" or moves == "gaussian" else None
    if cov is None and start == "laplace":
        notes.append("the Gauss-Newton matrix at the optimum is singular: the walkers start in the small ball")
    fingerprint = _fingerprint(problem, like, walkers, seed, x_opt, moves, start=start)
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
            log.warning(message)
    if st is None:
        st = _initial_state(like, x_opt, walkers, seed, cov if start == "laplace" else None)
    st.started = started

    log_prob, _ = choose_log_prob(like, runner, pool, st.coords[: walkers // 2])
    log_prob = guarded = _Interruptible(log_prob)  # a Ctrl-C never passes through emcee's wrapper (it prints)
    sampler = emcee.EnsembleSampler(walkers, like.ndim, log_prob, vectorize=True, moves=make_moves(moves, cov))
    bar = _StepProgress(progress, steps, max_steps, resumed=st.steps)
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
                    need = (tol_factor * np.max(tau) if stop == "tau" else
                            max(TAU_RELIABLE, ess_target / walkers + 2.0) * np.max(tau))
                    bar.note(f"tau_max {np.max(tau):.1f}, needs {need:.0f} steps, acceptance "
                             f"{np.mean(_acceptance(np.concatenate(chain_chunks), st.initial)):.2f}")
                    if path is not None:
                        _save_checkpoint(path, fingerprint, snapshot())
                    if n >= steps and _converged(stop, n, tau, tau_at(prev) if prev > 0 else None, walkers,
                                                 tol_factor, ess_target):
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
                        if guarded.interrupted:  # a Ctrl-C inside this step's log-probability: not a real step
                            guarded.raise_kept()
                        record.append((state.coords.copy(), state.log_prob.copy(), state.random_state))
                        n = sum(len(c) for c in chain_chunks) + len(record)
                        bar.step()
                        if on_step is not None:
                            on_step(n)
                    guarded.raise_kept()
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
    bar.close()
    return _summarise(problem, like, optimum_params, x_opt, st, seed=seed, walkers=walkers, min_steps=steps,
                      max_steps=max_steps, tol_factor=tol_factor, check_every=check_every, stop_reason=stop_reason,
                      wall_time=st.elapsed + st.session(), resumed_from=resumed_from, notes=notes,
                      moves_text=MOVES[moves], rule=_rule_text(stop, tol_factor, ess_target, check_every, steps,
                                                               max_steps), start=start if cov is not None else "ball")


def _burn_in(tau: np.ndarray, n: int) -> int:
    """Steps discarded as burn-in: 2 max(tau), at most half the chain."""
    return min(int(2 * np.max(tau)), n // 2)


def _converged(stop: str, n: int, tau: np.ndarray, previous: np.ndarray | None, walkers: int, tol_factor: float,
               ess_target: float) -> bool:
    """The stopping rule ``stop`` (:func:`run_posterior`) at ``n`` steps with the tau estimates at ``n`` and at
    the previous check (None: no previous check)."""
    if previous is None:
        return False
    change = np.abs(previous - tau)
    if stop == "tau":
        return bool(tol_factor * np.max(tau) < n and np.all(change < TAU_CHANGE * tau))
    ess = walkers * (n - _burn_in(tau, n)) / np.max(tau)
    return bool(np.all(change < TAU_STABLE * tau) and n >= TAU_RELIABLE * np.max(tau) and ess >= ess_target)


def _rule_text(stop, tol_factor, ess_target, check_every, min_steps, max_steps) -> str:
    if stop == "tau":
        head = (f"{tol_factor:g} x max(tau) < steps and every tau changed < {100 * TAU_CHANGE:g} % between checks "
                f"every {check_every} steps")
    else:
        head = (f"effective sample size walkers x (steps - burn-in) / max(tau) >= {ess_target:g}, every tau changed "
                f"< {100 * TAU_STABLE:g} % between checks every {check_every} steps, steps >= {TAU_RELIABLE:g} x "
                "max(tau)")
    return f"{head}, at least {min_steps} steps, at most {max_steps}"


def _summarise(problem, like, optimum_params, x_opt, st, *, seed, walkers, min_steps, max_steps, tol_factor,
               check_every, stop_reason, wall_time, resumed_from, notes, moves_text, rule,
               start) -> PosteriorResult:
    n = st.steps
    if n < 2:
        raise ValueError("the posterior run stopped before two steps were sampled (max_seconds too small?)")
    tau = st.tau_history.get(n)
    if tau is None:
        tau = _tau(st.chain)
    converged = stop_reason == "converged"
    burn = _burn_in(tau, n)
    thin = max(1, int(0.5 * np.min(tau)))
    kept = st.chain[burn::thin]
    unit = kept.reshape(-1, like.ndim)
    samples = _to_declared(problem, like, unit)
    if not converged:
        notes.append(f"not converged ({stop_reason}): {n} steps, max tau {np.max(tau):.1f}, effective sample "
                     f"size {walkers * (n - burn) / np.max(tau):.0f} (rule: {rule}); treat the intervals as "
                     "indicative only")
    return PosteriorResult(problem=problem, names=list(like.names), units=list(like.units), samples=samples,
                           unit_samples=unit, chain=st.chain, log_prob=st.log_prob, tau=tau,
                           acceptance=_acceptance(st.chain, st.initial), burn_in=burn, thin=thin, converged=converged,
                           steps=n, walkers=walkers, wall_time=wall_time, seed=seed, noise=like.noise,
                           likelihood=like.description, optimum=dict(optimum_params), optimum_unit=x_opt,
                           min_steps=min_steps, max_steps=max_steps, tol_factor=tol_factor, check_every=check_every,
                           stop_reason=stop_reason, resumed_from=resumed_from, warnings=notes, _like=like,
                           moves=moves_text, convergence_rule=rule, start=start)


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
