"""The closed vocabularies of fabric.yaml that no lower layer owns: fit metrics, CV schemes, nlopt algorithms.

The fitter imports these lists from here (:mod:`clothlab.fit.metrics`, :mod:`clothlab.fit.optimize`), so
what the validator accepts and what the fitter runs are the same names.  The other closed lists belong to
the modules that implement them and are imported from there: model kinds
(:data:`clothlab.models.registry.MODEL_KINDS`), quadrature rules
(:data:`clothlab.models.irawan.quadrature.RULES`) and measurement formats
(:data:`clothlab.io.loader.FORMAT_CHOICES`).

Algorithm names are nlopt's (the NLopt documentation, "NLopt Algorithms"): ``GN_*`` global derivative-free,
``G_MLSL_LDS`` multi-level single-linkage on a low-discrepancy sequence with a local optimiser run from
each start point, ``LN_*`` local derivative-free.
"""

from __future__ import annotations

METRICS = ("relative", "log", "cube-root")
"""What a fit minimises (``fit.metric``); defined in :mod:`clothlab.fit.metrics`."""

CV_SCHEMES = ("auto", "grouped", "grouped-incident", "leave-one-direction-out", "random")
"""``fit.cv_scheme``: cross-validation fold schemes; defined in :mod:`clothlab.fit.crossval`."""

CV_REFITS = ("neutral", "local")
"""``fit.cv_refit``: how a cross-validation fold refits its parameters; defined in :mod:`clothlab.fit.crossval`."""

LOSSES = ("squared", "l1", "huber", "cauchy")
"""``fit.loss``: the loss applied to the metric residuals; defined in :mod:`clothlab.fit.loss`."""

DEFAULT_LOSS_SCALE = 0.1
"""Default ``fit.loss_scale`` (the metric's units; 0.1 = 10 % under ``relative``); see :mod:`clothlab.fit.loss`."""

START_DESIGNS = ("sobol", "lhs", "none")
"""``fit.optimizer.design``: how the starts after the first are spread over the box (:mod:`clothlab.fit.optimize`)."""

GLOBAL_ALGORITHMS = ("GN_CRS2_LM", "GN_DIRECT_L", "GN_ISRES", "GN_ESCH", "G_MLSL_LDS")
"""``fit.optimizer.global``: the global stages the optimiser driver supports."""

LOCAL_ALGORITHMS = ("LN_BOBYQA", "LN_NELDERMEAD", "LN_SBPLX", "LN_COBYLA", "LN_PRAXIS")
"""``fit.optimizer.local``: the local polishes the optimiser driver supports."""

MLSL_LOCAL = "LN_BOBYQA"
"""The local optimiser G_MLSL_LDS runs from each of its start points."""

NEEDS_LOCAL = ("G_MLSL_LDS",)
"""Global algorithms a fabric.yaml may only name together with a local polish."""

DEFAULT_GLOBAL = "GN_CRS2_LM"
DEFAULT_LOCAL = "LN_BOBYQA"
"""The default optimiser: a controlled random search (CRS2 with local mutation), then BOBYQA."""
