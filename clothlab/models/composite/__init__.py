"""Composite models (``kind: irawan+oren-nayar`` and the others of
:data:`clothlab.models.registry.COMPOSITE_KINDS`): one model's specular components over another's diffuse ones.
The model is in :mod:`.model`; the physics options over any kind (an added sheen lobe, a Fresnel / shadowing factor
on the specular components: :data:`clothlab.models.registry.TERM_KINDS`) in :mod:`.terms`."""

from clothlab.models.composite.model import CompositeModel, composite_class, union_table

__all__ = ["CompositeModel", "composite_class", "union_table"]
