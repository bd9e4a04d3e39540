"""Simulated data: a virtual gonioreflectometer (:mod:`.gonio`), the shipped paper examples (:mod:`.examples`)
and simulated BTF stacks (:mod:`.btf`)."""
