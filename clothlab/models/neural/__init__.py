"""``kind: neural``: the trained numpy surrogate (:mod:`clothlab.surrogate`) behind the model interface."""
