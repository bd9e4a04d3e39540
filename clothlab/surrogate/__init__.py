"""The numpy neural surrogate of footprint-aggregated cloth reflectance (Chen, Wang & Wang 2024, sec. 4-5).

One concept per module: :mod:`.layers` (dense layers, leaky ReLU, residual blocks, hand-written backward
passes), :mod:`.network` (the encoder / decoder architecture of sec. 4.2), :mod:`.losses` (eqs. 9-11),
:mod:`.optimizer` (Adam, step schedule), :mod:`.encodings` (material vector, pattern descriptor, one-blob,
directions), :mod:`.labels` (label sources), :mod:`.data` (Table 2 sampling, chunked memory-mapped data),
:mod:`.training` (the training loop and held-out errors), :mod:`.surrogate` (inference on footprint queries)
and :mod:`.serialise` (``.npz`` + JSON sidecar).  numpy only.
"""
