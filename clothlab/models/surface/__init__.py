"""The fabric surface model of Chen, Wang & Wang 2024 (sec. 3.1): single-ply curved-cylinder yarns with a
fibre microflake specular layer and a blended Lambertian (``kind: surface``).

Modules: ``parameters`` (declarations), ``geometry`` (ply normal and orientation, eq. 11 mapping, the tile's
projected area), ``kernels`` (eqs. 1-2, compiled), ``model`` (the tile average, for BRDF tables),
``texture`` (point evaluation at u, v).  The decisions the paper leaves open are listed in ``model``.
"""
