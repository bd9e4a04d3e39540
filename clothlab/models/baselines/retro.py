"""A back-scattering (retro-reflection) term: the brightening of a porous fibre layer toward the light source
(issue 28 item 5; docs/select.md, "Residual diagnostics of the default winners").

Near the retro-reflection direction (phase angle g = angle(wi, wo) -> 0) an observer sees the fibres' own
shadows hidden behind them: the shadow-hiding opposition effect of a particulate or fibrous medium (Hapke 1986,
"Bidirectional reflectance spectroscopy 4. The extinction coefficient and the opposition effect", Icarus 67,
264-280; the shadow-hiding function B(g) of his theory, written here without its amplitude, which is the
coefficient's):

    B(g) = 1 / (1 + tan(g / 2) / h),        h in (0, 2]: the angular width (h ~ porosity of the layer),

and the term is a Lambertian modulated by it (Hapke multiplies the singly scattered light by 1 + B_0 B(g)):

    f_retro(wi, wo) = B(g) / pi.

B(0) = 1, B decreases monotonically with g (to 0 at g = 180 deg); f is symmetric in wi, wo (reciprocal),
non-negative, 0 for back-facing pairs, and depends on the directions only through wi . wo = cos g (isotropic).
Its coefficient ``retro`` is solved linearly like kd and ks (kd + retro: the diffuse part with its opposition
surge).  The equation number is not given: the paper is not in /work/shared/papers.

==========  ====  ===========  =======  ==========================================================
parameter   unit  range        default  meaning
==========  ====  ===========  =======  ==========================================================
retro.h     1     [0.001, 10]  0.2      angular width h of the opposition surge (fit bounds 0.01-2)
==========  ====  ===========  =======  ==========================================================
"""

from __future__ import annotations

import numpy as np

from clothlab.models.base import front_facing
from clothlab.params import ParamSpec, ParamTable

RETRO_PARAMS = ParamTable([
    ParamSpec("retro.h", "1", (0.001, 10.0), (0.01, 2.0), 0.2, "log",
              "angular width h of the shadow-hiding opposition surge B(g) = 1 / (1 + tan(g/2) / h) (Hapke 1986)"),
])
RETRO_FREE = ("retro.h",)


def retro_lobe(wi: np.ndarray, wo: np.ndarray, h: float) -> np.ndarray:
    """f_retro = B(g) / pi (1/sr, module docstring) at (N, 3) unit directions; 0 for back-facing pairs."""
    cos_g = np.clip(np.einsum("ij,ij->i", wi, wo), -1.0, 1.0)
    # tan(g/2) = sqrt((1 - cos g) / (1 + cos g)); infinite at g = 180 deg (B = 0)
    tan_half = np.sqrt(np.divide(1.0 - cos_g, 1.0 + cos_g, out=np.full(len(wi), np.inf), where=cos_g > -1.0))
    return np.where(front_facing(wi, wo), 1.0 / (np.pi * (1.0 + tan_half / h)), 0.0)
