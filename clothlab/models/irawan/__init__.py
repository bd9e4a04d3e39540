"""The Irawan-Marschner model of woven cloth (Irawan & Marschner 2012, "Specular reflection from woven
cloth", ACM TOG 31(1)): reflectance model (sec. 7.1, :mod:`.model`) and texture model (sec. 7.2, :mod:`.texture`).

Paper -> code.  Functions in ``kernels`` are compiled numba helpers, inlined into the loops; each is the
only implementation of its equation (yarn frame: z normal, y along the yarn; angles in radians).

=============  =========================================================  =========================================
paper          meaning                                                    code
=============  =========================================================  =========================================
sec. 5.3       L = l/2 - a sin umax, the spine's half extent              ``kernels.half_length``
sec. 5.4       r_hat = 1 + kappa (1 + cot umax), the axis ratio           ``kernels.axis_ratio``
sec. 5.4       R(u), spine radius of curvature (three branches in one)    ``kernels.spine_radius`` (``spine``)
sec. 5.4, 9    the arc a smoothed filament's R(u) is fitted to            ``kernels.spine_arc``
               (``filament_arc``: full = paper, shortened = renderer)
sec. 5.2       n(u, v) and its cosines w . n with wi, wo                  ``kernels.spine_normal_cosine``,
                                                                          ``kernels.normal_cosine``
sec. 6.2       h = (wi + wo) / |wi + wo|, the half vector                 ``kernels.half_vector``
sec. 6.2       a (R(u) + a cos v), the volume element at r = a            ``kernels.volume_element``
eq. 1          f_s = int G_v f_c A du (staple, over u)                    ``kernels.staple_quadrature``
eq. 2          f_s = int G_u f_c A dv (filament, over v)                  ``kernels.filament_quadrature``
eq. 3          specular v(wi, u, wo), with D and the |D| <= 1 test        ``kernels.specular_v``
eq. 3          ends of its support |D| <= 1 and the cut |v| = pi/2        ``kernels.staple_break_angles``
eq. 4          specular u(wi, v, wo) of a filament                        ``kernels.specular_u``
eq. 5 x eq. 8  G_v A in bounded form (finite as n . h -> 0)               ``kernels.staple_geometry_attenuation``
eq. 6          |(t x h)_x|, the filament geometry factor's denominator    ``kernels.tangent_cross_h_x``
eq. 7          f_c = alpha + g(-wi . wo, beta), the von Mises lobe g      ``phase.phase_function``,
                                                                          ``phase.von_mises``
eq. 8          A = c_i c_r / (c_i + c_r), Seeliger's law                  ``kernels.seeliger``
eq. 8          v-arc where a clamped cosine of A is positive              ``kernels.lit_arc``
eqs. 3 x 8     u where c_i or c_r crosses 0 on the staple's specular       ``kernels.cosine_zero_quartic``,
               curve (roots of a quartic in tan u)                        ``kernels.quartic_roots``
sec. 7.3       the support rule's breakpoints and lit pieces              ``kernels.staple_breakpoints``,
                                                                          ``kernels.staple_lit_pieces``,
                                                                          ``kernels.staple_support_sum``
eq. 9          s(x), the smooth step, and the fade 1 - s(...) of A_s      ``kernels.smoothstep``,
                                                                          ``kernels.filament_fade``
Algorithm 1    the staple integrand G_v A (without f_c)                   ``kernels.staple_integrand``
Algorithm 2    the filament integrand G_u A_s (without f_c)               ``kernels.filament_direction``,
                                                                          ``kernels.filament_integrand``
eq. 10         I_j = the yarn integral of one segment type                ``yarn.yarn_integral``
sec. 7.3       quadrature rules (trapezoid with 11 samples, ...)          ``quadrature``
Table I        the parameters and their ranges                            ``parameters``
eqs. 11-13     texture: unrolling, band chi, brightness T                 ``texture``
Algs. 3-4      the integrands at one point of the texture                 ``kernels.staple_points``,
                                                                          ``kernels.filament_points``
sec. 7.2.1     texture noise (intensity and umax)                         ``texture_noise``
=============  =========================================================  =========================================

The literal, unfused form of these equations (one direction pair at a time, scipy quad) is kept as an
independent check in the test suite; the tests compare the two.
"""
