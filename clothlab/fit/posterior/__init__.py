"""Posterior sampling of a fit with emcee: likelihood, priors, convergence, checkpoints, summaries.

Sampled coordinates are the unit box of :class:`clothlab.fit.problem.FitProblem` (x = (T(theta) - T(lo)) /
(T(hi) - T(lo)), T = log for log-scaled parameters), plus one coordinate for a noise scale when the data carry
no uncertainties.  So the **prior is uniform in the optimiser's transform**: uniform within the fit bounds for
linear parameters, log-uniform within them for log-scaled ones, zero outside.

Likelihood (per value n, channel c; model m = sum_k c_k[c] component_k(theta)[n]):

* measurement with ``sigma``: Gaussian, log L = -1/2 sum ((y - m) / sigma)^2;
* without ``sigma``: log-normal, log(m / y) ~ N(0, s^2) with s sampled (log-uniform prior on ``NOISE_RANGE``),
  log L = -sum [ log(m / y)^2 / (2 s^2) + log s ]  (m floored as in :data:`clothlab.fit.metrics.LOG_FLOOR`).

**The linear coefficients (kd, ks per channel and yarn type) are profiled out, not sampled**: at every
posterior point they are re-solved by weighted NNLS (weights 1 / sigma, or 1 / y for the log-normal case,
:func:`clothlab.fit.nnls.nnls_sets`; Irawan & Marschner 2012, sec. 8 fit them linearly too).  The chain
therefore samples the profile likelihood of the non-linear parameters: intervals are conditional on the best
coefficients at each point, which neglects the (small, with thousands of values per coefficient) extra width
that marginalising the coefficients would add, and a coefficient pinned at 0 by the non-negativity constraint
contributes no width.

Evaluation: emcee calls the log-probability once per ensemble half (``vectorize=True``) with all its walkers;
the model is evaluated for all of them in one call (:meth:`clothlab.models.base.Model.components_many`: for IM
the parameter-free parts once per direction set, the staple sums of all walkers in one compiled loop) and the
coefficients of all walkers and channels in one compiled NNLS call.  The chain is the one the walker-by-walker
path gives (same coordinates; log-probabilities equal to ~1e-14 relative).

Convergence (emcee docs, "Autocorrelation analysis"): sample in chunks of ``check_every`` steps;
after each, the integrated autocorrelation time tau of every coordinate (``emcee.autocorr.integrated_time``,
tol=0); by default (``stop="ess"``) stop once tau is stable (every tau changed by < 5 % since the previous
check, steps >= 20 max(tau)) and the smallest effective sample size walkers x (steps - burn-in) / max(tau)
reaches 1,000 (and at least ``steps`` were run), or at ``max_steps``; ``stop="tau"`` is the emcee docs' rule
``tol_factor * max(tau) < steps`` with every tau changed by < 1 %.  Burn-in 2 max(tau) is discarded and the
rest thinned by max(1, min(tau) / 2).

Reproducible and resumable: the walkers start from the Laplace approximation at the optimum (the Gauss-Newton
covariance of the likelihood's residuals, :func:`~clothlab.fit.posterior.sampler.laplace_start`; or, with
``start="ball"`` or a singular Gauss-Newton matrix, in a ball of radius ``BALL_RADIUS``), unit coordinates
reflected into the box, drawn from ``numpy.random.RandomState(seed)``, whose following state seeds the sampler
(emcee has no seed argument).  The checkpoint (``.npz``, written atomically after every chunk and on KeyboardInterrupt)
holds the chain, log-probabilities and the sampler's random state after the last completed step, so a resumed
run yields the same chain as an uninterrupted one.

Modules: :mod:`~clothlab.fit.posterior.likelihood` (prior and likelihood), :mod:`~clothlab.fit.posterior.checkpoint`
(fingerprint and saved state), :mod:`~clothlab.fit.posterior.sampler` (:func:`run_posterior`, convergence) and
:mod:`~clothlab.fit.posterior.result` (:class:`PosteriorResult`).
"""

from clothlab.fit.posterior.checkpoint import CHECKPOINT_VERSION, TARGET_KEYS
from clothlab.fit.posterior.likelihood import NOISE_NAME, NOISE_RANGE, NOISE_UNIT, PRIOR_TEXT, _Likelihood
from clothlab.fit.posterior.result import PILE_FRACTION, PILE_MARGIN, WIDE_FRACTION, PosteriorResult
from clothlab.fit.posterior.sampler import BALL_RADIUS, TAU_CHANGE, run_posterior

__all__ = ["run_posterior", "PosteriorResult", "NOISE_NAME", "NOISE_UNIT", "NOISE_RANGE", "PRIOR_TEXT",
           "BALL_RADIUS", "TAU_CHANGE", "WIDE_FRACTION", "PILE_MARGIN", "PILE_FRACTION", "CHECKPOINT_VERSION",
           "TARGET_KEYS", "_Likelihood"]
