"""The in-memory measurement: what every loader returns and every fit consumes.

A :class:`Measurement` holds N direction pairs in clothlab's frame and convention
(:mod:`clothlab.frames`: angles in degrees, phi counter-clockwise from the weft) and an (N, C) array of
BRDF values in 1/sr (the quantity after conversion at loading: a Spectralon-relative reflectance factor is
divided by pi, a cosine-weighted value by cos theta).  ``sigma`` is the optional one-standard-deviation
uncertainty of each value, same shape and unit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clothlab.frames import spherical_to_vector


@dataclass(frozen=True)
class Measurement:
    """Direction pairs and BRDF values (1/sr) of one fabric sample.

    theta_i, phi_i, theta_o, phi_o : (N,) degrees, clothlab convention.
    values : (N, C) BRDF in 1/sr.   sigma : (N, C) or None, same unit.
    channels : names of the C channels (e.g. ('R', 'G', 'B')).
    provenance : free metadata (instrument, reference standard, sample name, simulated?, source file ...).

    >>> import numpy as np
    >>> m = Measurement(theta_i=np.array([30.0, 45.0, 60.0]), phi_i=np.zeros(3), theta_o=np.zeros(3),
    ...                 phi_o=np.zeros(3), values=np.array([0.3, 0.2, 0.1]), channels=("Y",))
    >>> m.n, m.values.shape  # one channel: values become (N, 1)
    (3, (3, 1))
    >>> m.subset(m.theta_i > 40.0).theta_i.tolist()
    [45.0, 60.0]
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_o: np.ndarray
    phi_o: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    sigma: np.ndarray | None = None
    provenance: dict = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self):
        n = len(self.theta_i)
        for name in ("phi_i", "theta_o", "phi_o"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"Measurement.{name} has {len(getattr(self, name))} rows, expected {n}")
        values = np.asarray(self.values, dtype=np.float64)
        if values.ndim == 1:
            values = values[:, None]
        object.__setattr__(self, "values", values)
        if values.shape != (n, len(self.channels)):
            raise ValueError(f"Measurement.values has shape {values.shape}, expected ({n}, {len(self.channels)})")
        if self.sigma is not None:
            sigma = np.asarray(self.sigma, dtype=np.float64).reshape(values.shape)
            object.__setattr__(self, "sigma", sigma)
        for name in ("theta_i", "phi_i", "theta_o", "phi_o"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        object.__setattr__(self, "channels", tuple(self.channels))

    @property
    def n(self) -> int:
        return len(self.theta_i)

    @property
    def isotropic(self) -> bool:
        """True when the data were measured as isotropic (``provenance['isotropic']``, e.g. a MERL table):
        they constrain only the BRDF averaged over the fabric's orientation about the normal, so the model to
        fit is the orientation-averaged one (docs/formats.md, "MERL")."""
        return self.provenance.get("isotropic") is True

    @property
    def wi(self) -> np.ndarray:
        """(N, 3) incident directions (towards the light), fabric frame."""
        return spherical_to_vector(self.theta_i, self.phi_i)

    @property
    def wo(self) -> np.ndarray:
        """(N, 3) exitant directions (towards the sensor), fabric frame."""
        return spherical_to_vector(self.theta_o, self.phi_o)

    def subset(self, mask) -> Measurement:
        """The rows selected by a boolean mask or index array."""
        return Measurement(
            self.theta_i[mask], self.phi_i[mask], self.theta_o[mask], self.phi_o[mask], self.values[mask],
            self.channels, None if self.sigma is None else self.sigma[mask], dict(self.provenance), self.source,
        )
