"""``kind: neural``: the trained numpy surrogate (:mod:`clothlab.neural`) behind the model interface."""
