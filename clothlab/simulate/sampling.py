"""Direction samplings of the virtual gonioreflectometer besides the paper's grid (:mod:`.gonio`): scattered
sets such as a lab's sparse measurement (issue 14 item 9).

``--sampling`` of ``clothlab simulate`` (:func:`parse_sampling`):

* ``paper`` (default): the paper's 225 x 7 grid (Irawan & Marschner 2012, sec. 4.1; :func:`.gonio.paper_sampling`);
* ``random:N`` / ``random:N:uniform``: N independent pairs (wi, wo), each direction uniform over the upper
  hemisphere in solid angle (pdf 1 / (2 pi) per steradian: cos(theta) = 1 - xi1 uniform in (0, 1], phi = 2 pi xi2);
* ``random:N:cosine``: each direction cosine-weighted (pdf cos(theta) / pi: sin^2(theta) = xi1, Malley's method),
  which puts fewer samples near grazing;
  draws come from numpy's PCG64 seeded by ``seed`` (``--sampling-seed``, default 0), xi1 in (0, 1] so no
  direction lies exactly on the horizon (a reflection model is 0 there);
* a CSV file: a header ``theta_i,phi_i,theta_o,phi_o`` and one row per pair, in degrees, clothlab's azimuth
  convention (counter-clockwise from the weft, docs/design.md principle 1); '#' lines are comments; no pair
  twice.

Either holds at most :data:`MAX_RANDOM` (1,000,000) pairs, so that the simulated table fits in memory.

Each returns (theta_i, phi_i, theta_o, phi_o) in degrees, the form :func:`.gonio.simulate` takes.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError, InputError
from clothlab.frames import vector_to_spherical
from clothlab.untrusted import MAX_TABLE_BYTES, parse_number, read_text

DISTRIBUTIONS = ("uniform", "cosine")
COLUMNS = ("theta_i", "phi_i", "theta_o", "phi_o")
MAX_RANDOM = 1_000_000
"""Most direction pairs of a sampling (random:N or a file): a simulated table needs about 2 KB of memory per
pair while it is evaluated, checked and written (1,000,000 pairs: about 2 GB; the paper's grid has 1,575)."""
MAX_SEED = 2**64 - 1


def hemisphere_directions(n: int, rng, distribution: str = "uniform") -> np.ndarray:
    """(n, 3) unit directions above the surface, uniform in solid angle or cosine-weighted (module docstring)."""
    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
    xi1 = 1.0 - rng.random(n)  # (0, 1]
    phi = 2.0 * np.pi * rng.random(n)
    if distribution == "uniform":
        cos_t = xi1
        sin_t = np.sqrt(np.maximum(0.0, (1.0 - cos_t) * (1.0 + cos_t)))
    else:
        sin_t = np.sqrt(1.0 - xi1)  # sin^2 = 1 - xi1, uniform in [0, 1): Malley's method
        cos_t = np.sqrt(xi1)
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)


def random_sampling(n: int, seed: int = 0, distribution: str = "uniform"):
    """(theta_i, phi_i, theta_o, phi_o) in degrees of n seeded random pairs (module docstring)."""
    rng = np.random.default_rng(seed)
    wi = hemisphere_directions(n, rng, distribution)
    wo = hemisphere_directions(n, rng, distribution)
    ti, pi_ = vector_to_spherical(wi)
    to, po = vector_to_spherical(wo)
    return ti, pi_, to, po


def file_sampling(path):
    """(theta_i, phi_i, theta_o, phi_o) in degrees read from a CSV file (module docstring); InputError names
    the file, line and column of a bad value."""
    path = Path(path)
    text = read_text(path, limit=MAX_TABLE_BYTES, what="sampling file")
    rows, header, seen = [], None, {}
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = [f.strip() for f in stripped.split(",")]
        if header is None:
            header = [f.lower() for f in fields]
            if header != list(COLUMNS):
                raise InputError(f"expected the header {','.join(COLUMNS)}, got {stripped!r}", path=path,
                                 line=number)
            continue
        if len(fields) != len(COLUMNS):
            raise InputError(f"expected {len(COLUMNS)} values, got {len(fields)}", path=path, line=number)
        values = [parse_number(f, path=path, line=number, field=c) for f, c in zip(fields, COLUMNS, strict=True)]
        for column, value in zip(COLUMNS, values, strict=True):
            if column.startswith("theta") and not 0.0 <= value < 90.0:
                raise InputError(f"{column} = {value:g} deg; expected [0, 90) (directions above the surface)",
                                 path=path, line=number, field=column)
            if column.startswith("phi") and not -360.0 <= value <= 360.0:
                raise InputError(f"{column} = {value:g} deg; expected an azimuth within one turn",
                                 path=path, line=number, field=column)
        pair = (values[0], values[1] % 360.0, values[2], values[3] % 360.0)
        if pair in seen:  # a table cannot hold one direction pair twice
            raise InputError(f"the direction pair {tuple(values)} repeats line {seen[pair]}", path=path,
                             line=number, field="theta_i,phi_i,theta_o,phi_o")
        seen[pair] = number
        rows.append(values)
        if len(rows) > MAX_RANDOM:
            raise InputError(f"more than {MAX_RANDOM} direction pairs; a simulated table is bounded to that many "
                             "(about 2 KB of memory each)", path=path, line=number)
    if not rows:
        raise InputError(f"no direction pairs (expected the header {','.join(COLUMNS)} and rows)", path=path)
    a = np.array(rows, dtype=np.float64)
    return a[:, 0], np.mod(a[:, 1], 360.0), a[:, 2], np.mod(a[:, 3], 360.0)


def parse_sampling(spec: str | None, seed: int = 0, field: str = "--sampling"):
    """The sampling named by ``spec`` (module docstring) and a description for the provenance:
    (sampling or None for the paper's grid, description)."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"the sampling seed must be an integer in [0, {MAX_SEED}], got {seed!r}",
                          field=field + "-seed")
    if spec is None or spec == "paper":
        return None, "paper 225 x 7 grid (Irawan & Marschner 2012, sec. 4.1)"
    if spec.startswith("random:"):
        parts = spec.split(":")
        distribution = parts[2] if len(parts) == 3 else "uniform"
        count = parts[1]
        n = int(count) if re.fullmatch(r"[0-9]{1,12}", count) else 0  # plain digits: no '1_0', ' 5', '+5'
        if len(parts) > 3 or not 1 <= n <= MAX_RANDOM or distribution not in DISTRIBUTIONS:
            raise ConfigError(f"expected random:N or random:N:{'|'.join(DISTRIBUTIONS)} with 1 <= N <= "
                              f"{MAX_RANDOM}, got {spec!r}", field=field)
        return random_sampling(n, seed, distribution), (f"{n} random pairs, each direction {distribution} over "
                                                        f"the hemisphere (seed {seed})")
    try:
        pairs = file_sampling(spec)
    except InputError as exc:
        if exc.line is not None or exc.field is not None:
            raise
        # the file itself cannot be read (missing, a directory, too large): the option is what to fix
        raise ConfigError(f"expected paper, random:N[:{'|'.join(DISTRIBUTIONS)}] or a CSV file of direction "
                          f"pairs; {spec!r}: {exc.detail}", field=field) from None
    return pairs, f"direction pairs of {Path(spec).name}"
