"""Fitting the Irawan-Marschner texture model (Irawan & Marschner 2012, sec. 7.2) to BTF stacks.

- :mod:`clothlab.simulate.btf`: simulated BTF stacks in the paper's Fig. 4 arrangement;
- :mod:`clothlab.texfit.fit`: fit the texture-only parameters (tile offset, rotation, segment ratio, hWidth,
  noise statistics) to a BTF stack with the reflectance fit's BRDF parameters held;
- :mod:`clothlab.texfit.plots`: measured vs model tiles in the Fig. 4 half circles, per-image errors.
"""
