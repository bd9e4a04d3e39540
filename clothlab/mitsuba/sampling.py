"""Importance sampling of a fabric's reflection: a cosine-hemisphere lobe mixed with a tabulated 2-D distribution
per incident direction, built once per material and lazily per incident-direction bin (numpy only).

Directions are in the fabric frame (z normal, docs/design.md principle 1).  ``view`` is the given direction
(Mitsuba's ``si.wi``), ``w`` the sampled one.  The hemisphere of ``w`` is parameterised by (z, phi) =
(cos theta, azimuth), in which the solid angle is uniform (d omega = dz dphi), and cut into ``nz`` x ``nphi``
cells.  For the bin of ``view`` (``n_theta`` x ``n_phi`` bins of (theta, phi), built on first use), cell k gets

    P_k  proportional to  g(w_k) C_k,   g = mean_c f_r(w_k, view),   C_k = integral over the cell of cos theta
                                                                       = dphi (z1^2 - z0^2) / 2

(w_k: the cell centre; the tile-averaged reflectance model - its texture varies over the tile, the table is
the tile's mean lobe), and inside a cell the density follows cos theta exactly, so a lobe that is constant
over a cell (Lambert) is sampled with zero variance.  The sampling density is the mixture

    pdf(w) = c cos theta / pi + (1 - c) P_k(w) cos theta(w) / C_k(w)

with the cosine share ``c`` (``cosine_share``; 1 where the table is empty), so every direction of the upper
hemisphere has a positive density and the estimator f cos / pdf stays bounded by the table's resolution.
:meth:`pdf` uses the same bin as :meth:`sample`, so the two are exactly consistent (Mitsuba's chi-square test).
"""

from __future__ import annotations

import math

import numpy as np

TWO_PI = 2.0 * math.pi


class LobeSampler:
    """Mixture of cosine and a table per incident bin (module docstring).  ``lobe(w, view)`` -> (N,) >= 0 is
    the function tabulated (mean f_r over channels, 1/sr) at fabric-frame direction pairs (N, 3)."""

    def __init__(self, lobe, *, n_theta: int = 16, n_phi: int = 32, nz: int = 16, nphi: int = 32,
                 cosine_share: float = 0.25):
        self.lobe = lobe
        self.n_theta, self.n_phi, self.nz, self.nphi = int(n_theta), int(n_phi), int(nz), int(nphi)
        self.cosine_share = float(cosine_share)
        self.cells = self.nz * self.nphi
        self.cdf = np.zeros((self.n_theta * self.n_phi, self.cells))  # per bin; built when share is not NaN
        self.share = np.full(self.n_theta * self.n_phi, np.nan)  # cosine share per bin
        self.built = 0
        z = (np.arange(self.nz) + 0.5) / self.nz
        phi = (np.arange(self.nphi) + 0.5) * TWO_PI / self.nphi
        zz, pp = np.meshgrid(z, phi, indexing="ij")  # cell k = iz * nphi + ip
        s = np.sqrt(np.maximum(0.0, 1.0 - zz * zz))
        self.centres = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
        edges = np.arange(self.nz + 1) / self.nz
        #: C_k per cell (row iz of the (z, phi) grid): the integral of cos theta over the cell
        self.cell_cosine = np.repeat(0.5 * (edges[1:] ** 2 - edges[:-1] ** 2) * TWO_PI / self.nphi, self.nphi)

    # -------------------------------------------------------------------------------------------- bins

    def bins(self, view) -> np.ndarray:
        """The incident bin (N,) of fabric-frame directions ``view`` (N, 3) (theta, phi of the bin grid)."""
        view = np.asarray(view, dtype=np.float64)
        theta = np.arccos(np.clip(view[:, 2], -1.0, 1.0))
        phi = np.mod(np.arctan2(view[:, 1], view[:, 0]), TWO_PI)
        it = np.clip((theta / (0.5 * math.pi) * self.n_theta).astype(np.int64), 0, self.n_theta - 1)
        ip = np.clip((phi / TWO_PI * self.n_phi).astype(np.int64), 0, self.n_phi - 1)
        return it * self.n_phi + ip

    def bin_direction(self, b) -> np.ndarray:
        """The centre direction (M, 3) of incident bins ``b``."""
        b = np.asarray(b)
        theta = (b // self.n_phi + 0.5) * 0.5 * math.pi / self.n_theta
        phi = (b % self.n_phi + 0.5) * TWO_PI / self.n_phi
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)

    def _ensure(self, bins) -> None:
        """Build the tables of the bins not built yet, all in one lobe call."""
        todo = np.unique(bins)
        todo = todo[np.isnan(self.share[todo])]
        if todo.size == 0:
            return
        views = self.bin_direction(todo)
        m = self.cells
        w = np.tile(self.centres, (todo.size, 1))
        view = np.repeat(views, m, axis=0)
        g = np.asarray(self.lobe(w, view), dtype=np.float64).reshape(todo.size, m)
        g = np.where(np.isfinite(g) & (g > 0.0), g, 0.0) * self.cell_cosine[None, :]
        total = g.sum(axis=1)
        ok = total > 0.0
        cdf = np.cumsum(g, axis=1) / np.where(ok, total, 1.0)[:, None]
        cdf[:, -1] = 1.0
        cdf[~ok] = 0.0
        self.cdf[todo] = cdf
        self.share[todo] = np.where(ok, self.cosine_share, 1.0)
        self.built += todo.size

    def _cell_probability(self, bins, cell) -> np.ndarray:
        upper = self.cdf[bins, cell]
        lower = np.where(cell > 0, self.cdf[bins, np.maximum(cell - 1, 0)], 0.0)
        return upper - lower

    # -------------------------------------------------------------------------------------------- density

    def pdf(self, view, w) -> np.ndarray:
        """Solid-angle density (N,) of sampling ``w`` given ``view`` (both (N, 3), fabric frame); 0 below the
        surface (w_z <= 0) or for view_z <= 0."""
        view = np.atleast_2d(np.asarray(view, dtype=np.float64))
        w = np.atleast_2d(np.asarray(w, dtype=np.float64))
        out = np.zeros(len(w))
        ok = np.flatnonzero((w[:, 2] > 0.0) & (view[:, 2] > 0.0))
        if ok.size == 0:
            return out
        b = self.bins(view[ok])
        self._ensure(b)
        z = np.minimum(w[ok, 2], 1.0)
        phi = np.mod(np.arctan2(w[ok, 1], w[ok, 0]), TWO_PI)
        iz = np.clip((z * self.nz).astype(np.int64), 0, self.nz - 1)
        ip = np.clip((phi / TWO_PI * self.nphi).astype(np.int64), 0, self.nphi - 1)
        cell = iz * self.nphi + ip
        p = self._cell_probability(b, cell)
        c = self.share[b]
        out[ok] = c * z / math.pi + (1.0 - c) * p * z / self.cell_cosine[cell]
        return out

    def sample(self, view, u1, u2) -> tuple[np.ndarray, np.ndarray]:
        """(w (N, 3), pdf (N,)) from uniform numbers u1 (N,) (chooses the lobe) and u2 (N, 2); pdf 0 (and w = +z)
        where view_z <= 0."""
        view = np.atleast_2d(np.asarray(view, dtype=np.float64))
        u1 = np.asarray(u1, dtype=np.float64).reshape(-1)
        u2 = np.asarray(u2, dtype=np.float64).reshape(-1, 2)
        n = len(view)
        w = np.tile([0.0, 0.0, 1.0], (n, 1))
        ok = np.flatnonzero(view[:, 2] > 0.0)
        if ok.size:
            b = self.bins(view[ok])
            self._ensure(b)
            c = self.share[b]
            cosine = u1[ok] < c
            a, r = u2[ok, 0], u2[ok, 1]
            # cosine lobe (Malley: a uniform disk point lifted to the hemisphere)
            rad, ang = np.sqrt(a), TWO_PI * r
            wc = np.stack([rad * np.cos(ang), rad * np.sin(ang), np.sqrt(np.maximum(0.0, 1.0 - a))], axis=1)
            # table lobe: the cell by inverting the CDF with a, a uniform point in it from the rest of a and r
            # all tables as one increasing sequence (row b offset by b): one searchsorted for every lane
            flat = (self.cdf + np.arange(len(self.cdf))[:, None]).reshape(-1)
            index = np.searchsorted(flat, b + a, side="right")  # first entry > b + a: in row b since a < 1
            cell = np.clip(index - b * self.cells, 0, self.cells - 1)
            upper = self.cdf[b, cell]
            lower = np.where(cell > 0, self.cdf[b, np.maximum(cell - 1, 0)], 0.0)
            width = upper - lower
            frac = np.clip(np.where(width > 0.0, (a - lower) / np.where(width > 0.0, width, 1.0), 0.5), 0.0, 1.0)
            z0, z1 = (cell // self.nphi) / self.nz, (cell // self.nphi + 1) / self.nz
            z = np.clip(np.sqrt(z0 * z0 + frac * (z1 * z1 - z0 * z0)), 1e-12, 1.0)  # density ~ z in the cell
            phi = (cell % self.nphi + r) * TWO_PI / self.nphi
            s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
            wt = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
            w[ok] = np.where(cosine[:, None], wc, wt)
        return w, self.pdf(view, w)
