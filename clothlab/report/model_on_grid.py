"""The fitted model of a fit directory, evaluated where the saved tables have no values (scattered data).

A grid-sampled fit's report reads everything from its files.  For scattered data the hemisphere maps need
the model on a grid of exitant directions and the slices along planes the fit did not save, so the report
rebuilds the model from ``fit.json`` + ``weave.wv`` (:func:`clothlab.fit.store.load_fitted`, the same path
as ``clothlab eval``) and evaluates f_r = sum_k coef_k component_k (docs/design.md principle 3).  When the
model cannot be rebuilt (a kind this version does not know, a missing weave.wv) the report says why and
shows the measured points alone.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from clothlab.errors import ClothlabError, GeometryWarning

#: Most direction pairs the report evaluates for one fit (the maps and the slices together).
MAX_PAIRS = 60_000


class FittedModel:
    """f_r (N, C) of a saved fit at fabric-frame directions; GeometryWarnings are collected in ``notes``."""

    def __init__(self, model, params: dict, coefficients: dict, channels: tuple[str, ...]):
        self.model, self.params, self.coefficients, self.channels = model, params, coefficients, channels
        self.notes: list[str] = []
        self.pairs = 0

    def __call__(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        from clothlab.models.components import combine

        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        self.pairs += len(wi)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", GeometryWarning)
            values = combine(self.model.components(wi, wo, self.params), self.coefficients)
        for w in caught:
            text = f"model evaluation: {w.message}"
            if issubclass(w.category, GeometryWarning) and text not in self.notes:
                self.notes.append(text)
            elif not issubclass(w.category, GeometryWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return np.asarray(values, dtype=np.float64)

    def channel(self, values: np.ndarray, key: str) -> np.ndarray:
        """One column of :meth:`__call__`'s result by channel name, or the channel mean for 'luminance'."""
        if key in self.channels:
            return values[:, self.channels.index(key)]
        return values.mean(axis=1)


def load_fitted_model(fit_dir) -> tuple[FittedModel | None, str | None]:
    """(model, None), or (None, why not) when the fit directory's model cannot be rebuilt."""
    from clothlab.fit.store import load_fitted

    try:
        model, params, coefficients, channels = load_fitted(Path(fit_dir))
    except ClothlabError as exc:
        return None, f"the fitted model could not be rebuilt ({exc}): the maps show the measured points only"
    return FittedModel(model, params, coefficients, channels), None
