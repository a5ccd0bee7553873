/* Spherical-harmonics direction encoding, degree 4 (16 coefficients), with Instant-NGP's /
 * tiny-cuda-nn's real basis: the same constants, order and signs. Coefficient k = l*l + l + m
 * (l = 0..3, m = -l..l) is the orthonormal real spherical harmonic
 *   Y_l^m = sqrt(2) K_l^|m| P_l^|m|(z) sin(|m| phi)   m < 0
 *           K_l^0 P_l^0(z)                           m = 0
 *           sqrt(2) K_l^m  P_l^m(z)  cos(m phi)      m > 0
 * with K_l^m = sqrt((2l+1)/(4 pi) (l-m)!/(l+m)!) and P_l^m including the Condon-Shortley phase
 * (-1)^m, so that e.g. Y_1 = (-0.4886 y, 0.4886 z, -0.4886 x). Over the sphere,
 * integral Y_i Y_j = delta_ij.
 *
 * tiny-cuda-nn takes its input in [0,1]^3 and maps it with 2v-1; this takes the unit direction
 * itself. The direction is not normalised here: pass unit vectors. */
#ifndef FG_FIELD_SH_H
#define FG_FIELD_SH_H

#define FG_SH4_DIM 16

/* d is (B,3) unit directions, out is (B,16) (overwritten). */
void fg_sh4_encode(const float *d, int B, float *out);

#endif
