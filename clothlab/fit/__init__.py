"""Fitting a model to a measurement: one module per step, importing downward only.

==============  ==============================================================================================
module          what it holds
==============  ==============================================================================================
``metrics``     error figures (Irawan & Marschner 2012, sec. 8) and the metric a fit minimises
``nnls``        exact non-negative least squares of the linear coefficients, per channel
``problem``     :class:`~clothlab.fit.problem.FitProblem` (unit box, coefficients solved inside) and
                :func:`~clothlab.fit.problem.build_problem` from a configuration
``optimize``    nlopt driver: :func:`~clothlab.fit.optimize.minimize`, the multi-start and the polish
``uncertainty`` Gauss-Newton standard errors and correlations at the optimum
``crossval``    k-fold cross-validated error percentiles
``posterior``   emcee posterior: likelihood, checkpoint, sampler, result
``fitreport``   the lmfit-style report (text and HTML) of a fit summary
``store``       fit directories: writing (:func:`~clothlab.fit.store.save_fit`) and reading
                (:func:`~clothlab.fit.store.load_fit`, :func:`~clothlab.fit.store.load_fitted`)
``runner``      :func:`~clothlab.fit.runner.run_fit` (orchestration only) and
                :class:`~clothlab.fit.runner.FitResult`
``evaluate``    evaluating a configured or fitted model on a table of directions
==============  ==============================================================================================
"""
