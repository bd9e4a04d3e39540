"""clothlab in Mitsuba 3: a BSDF plugin ``type: clothlab`` for every registered model kind, and the scene
bridge behind ``clothlab render scene.yaml --renderer mitsuba`` (docs/mitsuba.md).

Optional: ``pip install "clothlab[mitsuba]"``.  Nothing here imports Mitsuba until a function needs it
(docs/design.md principle 5); :mod:`.material` and :mod:`.sampling` are numpy only.

- :func:`use_variant` selects a Mitsuba variant (default: the first of :data:`PREFERRED_VARIANTS` that runs
  here) and registers the plugin; :func:`~clothlab.mitsuba.plugin.register` registers it for a variant the
  caller set.
- :func:`~clothlab.mitsuba.material.load_material` - a fit directory or a preset as an evaluable material.
- :func:`~clothlab.mitsuba.scene.render_scene` - a clothlab scene rendered by Mitsuba with the plugin.
"""

from __future__ import annotations

from clothlab.errors import ConfigError

#: Variants tried in this order when none is named: the vectorised LLVM one (one model call per wavefront;
#: needs libLLVM >= 17, 19 measured, see docs/mitsuba.md) and the scalar one (one call per sample).
PREFERRED_VARIANTS = ("llvm_ad_rgb", "scalar_rgb")

#: The oldest libLLVM accepted: Dr.Jit 1.5 (Mitsuba 3.9) aborts the process in code generation with 15 and 16
#: ("Cannot select ... fmaximum"), refuses 14; 19 works (17 and 18 untested; Debian 12 ships 14, 15, 16, 19).
MIN_LLVM = (17, 0, 0)

__all__ = ["PREFERRED_VARIANTS", "available", "use_variant"]


def available() -> bool:
    """True when the ``mitsuba`` package can be imported."""
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return False
    return True


def _require():
    try:
        import mitsuba as mi
    except ImportError:
        raise ConfigError('Mitsuba 3 is not installed; pip install "clothlab[mitsuba]" (or pip install mitsuba)',
                          field="renderer") from None
    return mi


def use_variant(variant: str | None = None) -> str:
    """Set Mitsuba's variant (``variant``, or the first of :data:`PREFERRED_VARIANTS` that initialises here) and
    register the clothlab plugin for it; returns the variant.  ConfigError when none works."""
    mi = _require()
    from clothlab.mitsuba.plugin import register

    candidates = (variant,) if variant else PREFERRED_VARIANTS
    problems = []
    for name in candidates:
        if name not in mi.variants():
            problems.append(f"{name}: not built into this mitsuba")
            continue
        try:
            mi.set_variant(name)
            if name.startswith("llvm"):
                import drjit as dr

                version = tuple(dr.detail.llvm_version())
                if version < MIN_LLVM:  # LLVM 15 aborts the process in code generation ("Cannot select fmaximum")
                    problems.append(f"{name}: libLLVM {'.'.join(map(str, version))} is older than "
                                    f"{'.'.join(map(str, MIN_LLVM))} (set DRJIT_LIBLLVM_PATH to a newer one)")
                    continue
        except (ImportError, RuntimeError) as exc:
            problems.append(f"{name}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
            continue
        register()
        return name
    raise ConfigError("no usable Mitsuba variant: " + "; ".join(problems), field="variant")
