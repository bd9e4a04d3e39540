"""fabric.yaml: the schema, the YAML line map and the validation rules.

``load_config(path)`` reads a fabric.yaml, checks every key and returns a frozen :class:`Config`; every
mistake raises :class:`~clothlab.errors.ConfigError` naming the file, the line, the dotted field, the value
found and what was expected.  The package holds one concept per module:

- :mod:`~clothlab.config.schema` - the validated dataclasses and their defaults;
- :mod:`~clothlab.config.linemap` - YAML values with the line and column of every node
  (:func:`load_yaml_with_lines`, :class:`LineMap`);
- :mod:`~clothlab.config.checks` - checks of one value, raising at its location;
- :mod:`~clothlab.config.validate` - the rules of every section, :func:`load_config`,
  :func:`config_from_dict`, :func:`apply_overrides`;
- :mod:`~clothlab.config.choices` - the metric and nlopt algorithm names (closed lists no lower layer owns);
- :mod:`~clothlab.config.build` - the one builder of a model: from a Config (:func:`model_from_config`), a fit
  directory (:func:`model_from_fit`) or a weave (:func:`model_from_weave`).

The key-by-key reference is the project's fabric.yaml reference page (``fabric-yaml.md``).
"""

from clothlab.config.choices import GLOBAL_ALGORITHMS, LOCAL_ALGORITHMS, METRICS
from clothlab.config.linemap import LineMap, load_yaml_with_lines, parse_yaml_with_lines
from clothlab.config.schema import (
    PRESET_PREFIX,
    Config,
    FitConfig,
    MeasurementConfig,
    ModelConfig,
    OptimizerConfig,
    OutputConfig,
    PosteriorConfig,
    QuadratureConfig,
    ReportConfig,
)
from clothlab.config.validate import apply_overrides, config_from_dict, load_config, override_quadrature

__all__ = [
    "GLOBAL_ALGORITHMS",
    "LOCAL_ALGORITHMS",
    "METRICS",
    "PRESET_PREFIX",
    "Config",
    "FitConfig",
    "LineMap",
    "MeasurementConfig",
    "ModelConfig",
    "OptimizerConfig",
    "OutputConfig",
    "PosteriorConfig",
    "QuadratureConfig",
    "ReportConfig",
    "apply_overrides",
    "config_from_dict",
    "load_config",
    "load_yaml_with_lines",
    "override_quadrature",
    "parse_yaml_with_lines",
]
