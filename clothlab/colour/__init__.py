"""Colour calibration: the ColorChecker reference, a fitted correction from camera RGB to linear sRGB (D65)
and CIEDE2000 (:mod:`.chart`, colour-science imported inside the functions), and the calibration of a
photographed chart applied to a measurement (:mod:`.calibrate`)."""
