"""Bench section ``texture``: time of one evaluation of the IM texture model (Irawan & Marschner 2012,
sec. 7, with the Perlin intensity noise of sec. 7.2.1) on a 512 x 512 grid of tile positions for one
direction pair (silk shantung, noise on), against the target of :data:`TARGET_S` (a 512 x 512 texture
image in under a second).  Fastest of ``repeats`` calls after a warm-up (compilation and albedo tables)."""

from __future__ import annotations

import numpy as np

from clothlab.studies.timing import best_time

TARGET_S = 1.0
FABRIC = "silk-shantung"
SIZE = 512


def texture_speed(quick: bool, size: int = SIZE) -> dict:
    """seconds (fastest call), pixels_per_second, and whether the target is met (scaled to ``size``)."""
    from clothlab.frames import spherical_to_vector
    from clothlab.models.irawan.texture import IrawanTexture
    from clothlab.weave.presets import get_preset

    texture = IrawanTexture(get_preset(FABRIC))
    centres = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(centres, centres)
    wi, wo = spherical_to_vector([30.0], [0.0]), spherical_to_vector([30.0], [180.0])
    texture.components(u[:2], v[:2], wi, wo)  # compile, albedo tables
    seconds = best_time(lambda: texture.components(u, v, wi, wo), 2 if quick else 5, min_sample_s=0.0)
    target = TARGET_S * (size / SIZE) ** 2
    return {"fabric": FABRIC, "size": size, "seconds": seconds, "pixels_per_second": size * size / seconds,
            "target_s": target, "meets_target": seconds < target}


def run(context) -> dict:
    return texture_speed(context.quick)


def lines(f: dict) -> list[str]:
    return [f"== texture model: {f['size']} x {f['size']} tile positions, one direction pair ({f['fabric']}, "
            "Perlin noise on) ==",
            f"  {f['seconds']:.3f} s ({f['pixels_per_second']:,.0f} positions/s); target < {f['target_s']:g} s: "
            f"{'met' if f['meets_target'] else 'NOT met'}"]
