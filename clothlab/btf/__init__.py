"""BTF image stacks: loading (Bonn UBO2003 / UTIA names or a manifest), unit-tile averaging, simulation.

Heavy libraries (OpenImageIO, scipy.ndimage) are imported inside the functions that use them, so importing
this package stays cheap.  Public entry points:

- :class:`~clothlab.btf.stack.BtfStack` (``BtfStack.open(directory)``) and its ``tile_averages``;
- :func:`~clothlab.btf.period.estimate_period` / :func:`~clothlab.btf.period.average_tiles`;
- :func:`~clothlab.btf.write.write_btf_stack` (simulated stacks from any texture-evaluating callable).
"""

from __future__ import annotations

from clothlab.btf.names import BtfEntry, parse_angles
from clothlab.btf.period import Period, average_tiles, estimate_period
from clothlab.btf.stack import BtfStack, TileAverages
from clothlab.btf.write import write_btf_stack

__all__ = ["BtfEntry", "BtfStack", "Period", "TileAverages", "average_tiles", "estimate_period",
           "parse_angles", "write_btf_stack"]
