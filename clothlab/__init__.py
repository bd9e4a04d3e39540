"""clothlab: measure, fit and report the appearance of woven cloth.

The package import is light (numpy only); heavy libraries (matplotlib, colour, OpenImageIO, emcee, nlopt)
are imported inside the functions that use them.
"""

__version__ = "0.1.0"
