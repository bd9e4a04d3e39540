"""clothlab: measure, fit and report the appearance of woven cloth.

The package import is light (numpy only); heavy libraries (matplotlib, colour, OpenImageIO, emcee, nlopt,
numba) are imported inside the functions that use them.  The objects the CLI uses are available here for
Jupyter, loaded on first access::

    import clothlab as cl
    result = cl.run_fit(cl.load_config("measurements/silk-charmeuse/fabric.yaml"))
    fit_dir = cl.save_fit(result, force=True)
    fig = cl.plots.plot_hemisphere_comparison(cl.load_fit_dir(fit_dir).predictions)

The paper's six fabrics ship with the package (Irawan & Marschner 2012, Table I):

>>> import clothlab as cl
>>> cl.PRESET_NAMES[-1]
'polyester-lining'
>>> charmeuse = cl.get_preset("silk-charmeuse")
>>> charmeuse.warp.umax, charmeuse.warp.kappa, charmeuse.beta
(40.0, 2.0, 7.3)
>>> errors = cl.error_percentiles([[0.20, 0.10]], [[0.22, 0.10]], percentiles=(50,))
>>> round(errors["per_channel"]["c0"]["p50"], 6), errors["overall"]["n"]  # relative errors, fractions
(0.1, 2)
"""

from importlib import import_module

from clothlab.renamed import install as _install_renamed

_install_renamed()  # old module names of one release (clothlab.renamed)

__version__ = "0.1.0"

_LAZY = {
    "load_config": "clothlab.config",
    "config_from_dict": "clothlab.config",
    "load_measurement": "clothlab.io.loader",
    "read_table": "clothlab.io.table",
    "write_table": "clothlab.io.table",
    "Measurement": "clothlab.io.measurement",
    "get_preset": "clothlab.weave.presets",
    "PRESET_NAMES": "clothlab.weave.presets",
    "parse_wv": "clothlab.weave.wvformat",
    "IrawanModel": "clothlab.models.irawan.model",
    "Quadrature": "clothlab.models.irawan.model",
    "KangModel": "clothlab.models.kang.model",
    "build_model": "clothlab.models.registry",
    "paper_sampling": "clothlab.simulate.gonio",
    "NoiseModel": "clothlab.simulate.gonio",
    "run_fit": "clothlab.fit.runner",
    "save_fit": "clothlab.fit.runner",
    "load_fitted": "clothlab.fit.store",
    "load_fit_dir": "clothlab.report.data",
    "build_report": "clothlab.report.build",
    "build_comparison": "clothlab.report.build",
    "error_percentiles": "clothlab.fit.metrics",
}
_MODULES = {"plots": "clothlab.report.plots"}

__all__ = sorted([*_LAZY, *_MODULES, "__version__"])


def __getattr__(name):
    if name in _MODULES:
        return import_module(_MODULES[name])
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'clothlab' has no attribute {name!r}")


def __dir__():
    return __all__
