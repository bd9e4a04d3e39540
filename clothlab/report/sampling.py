"""How a measurement samples the direction pairs, and which incident directions a scattered report shows.

Rule (docs/report.md): the rows are grouped by exitant direction (rounded to
:data:`clothlab.report.data.EXITANT_DECIMALS` deg).  The sampling is a **grid** - the paper's layout, a few
exitant directions each with a whole incident hemisphere (Irawan & Marschner 2012, sec. 4.1: 7 x 225) - when
there are at most :data:`MAX_GRID_DIRECTIONS` groups and each holds at least :data:`MIN_GRID_ROWS` rows.
Anything else is **scattered** (e.g. 205 samples over 154 view directions, most with one sample).

For scattered data the report draws a fixed number of panels (at most :data:`MAX_PANELS`), each the exitant
hemisphere of one representative incident direction, with the measured samples whose incident direction lies
within :data:`WINDOW_DEG` of it.  The representatives are measured incident directions chosen greedily: each
next one covers the most samples not covered yet (a set cover), so together they show as much of the data as
a few panels can.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clothlab.report.data import exitant_groups

MAX_GRID_DIRECTIONS = 12
"""Most exitant directions of a grid sampling (one hemisphere row each keeps the figure under 3000 px)."""
MIN_GRID_ROWS = 20
"""Fewest rows per exitant direction of a grid sampling (a disc needs an incident hemisphere of samples)."""
MAX_PANELS = 6
"""Incident directions shown for scattered data."""
WINDOW_DEG = 15.0
"""Angular window (deg) around a panel's incident direction: samples within it are overlaid on its panel."""
MAX_CANDIDATES = 400
"""Most distinct incident directions considered as panel centres (evenly thinned beyond)."""
MAX_COVER_ROWS = 10_000
"""Most rows the set cover counts (evenly thinned beyond; the panels' rows are then found exactly)."""


@dataclass(frozen=True)
class SamplingLayout:
    """``kind`` 'grid' or 'scattered', the rule's figures and the reason in words."""

    kind: str
    exitant_directions: int
    min_rows: int
    reason: str

    @property
    def scattered(self) -> bool:
        return self.kind == "scattered"


def sampling_layout(table: dict) -> SamplingLayout:
    """The layout of a predictions table (columns theta_i, phi_i, theta_o, phi_o in deg) by the module's rule."""
    groups = exitant_groups(table)
    sizes = [len(rows) for _, _, rows in groups]
    n, smallest = len(groups), min(sizes)
    if n <= MAX_GRID_DIRECTIONS and smallest >= MIN_GRID_ROWS:
        return SamplingLayout("grid", n, smallest, f"grid: {n} exitant direction(s), each with at least "
                                                    f"{smallest} incident directions")
    why = (f"more than {MAX_GRID_DIRECTIONS} exitant directions" if n > MAX_GRID_DIRECTIONS else
           f"an exitant direction with only {smallest} row(s), fewer than {MIN_GRID_ROWS}")
    return SamplingLayout("scattered", n, smallest, f"scattered: {n} exitant direction(s) ({why}); the maps "
                                                     f"show at most {MAX_PANELS} incident directions")


def unit_vectors(theta, phi) -> np.ndarray:
    """(N, 3) unit vectors of directions (deg; clothlab frame, docs/design.md principle 1)."""
    from clothlab.frames import spherical_to_vector

    return spherical_to_vector(np.asarray(theta, dtype=np.float64), np.asarray(phi, dtype=np.float64))


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (deg) between unit vectors, row by row (broadcasting); atan2 form, accurate near 0 and 180."""
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.rad2deg(np.arctan2(cross, np.sum(a * b, axis=-1)))


@dataclass(frozen=True)
class Panel:
    """One incident direction shown: its angles (deg) and the rows of the samples within the window."""

    theta_i: float
    phi_i: float
    rows: np.ndarray


def representative_incidents(table: dict, *, panels: int = MAX_PANELS, window: float = WINDOW_DEG) -> list[Panel]:
    """At most ``panels`` measured incident directions chosen by greedy set cover (module docstring), in
    order of theta_i, each with the row indices of the samples within ``window`` deg of it."""
    theta = np.round(np.asarray(table["theta_i"], dtype=np.float64), 3)
    phi = np.round(np.mod(np.asarray(table["phi_i"], dtype=np.float64), 360.0), 3)
    phi = np.where(theta == 0.0, 0.0, phi)  # every azimuth at the pole is one direction
    keys = np.unique(np.stack([theta, phi], axis=1), axis=0)
    if len(keys) > MAX_CANDIDATES:  # every k-th distinct direction: bounded work on huge tables
        keys = keys[np.linspace(0, len(keys) - 1, MAX_CANDIDATES).astype(int)]
    centres = unit_vectors(keys[:, 0], keys[:, 1])
    samples = unit_vectors(theta, phi)
    step = max(1, len(theta) // MAX_COVER_ROWS)  # the cover is chosen on every step-th row
    cos_window = np.cos(np.deg2rad(window))
    near = centres @ samples[::step].T >= cos_window  # (K, N / step) booleans, at most 4e6
    covered = np.zeros(near.shape[1], dtype=bool)
    chosen: list[int] = []
    for _ in range(min(panels, len(keys))):
        gain = (near & ~covered).sum(axis=1)
        gain[chosen] = -1
        best = int(np.argmax(gain))
        if gain[best] <= 0:
            break
        chosen.append(best)
        covered |= near[best]
    out = [Panel(float(keys[k, 0]), float(keys[k, 1]), np.flatnonzero(samples @ centres[k] >= cos_window))
           for k in chosen]
    return sorted(out, key=lambda p: (p.theta_i, p.phi_i))
