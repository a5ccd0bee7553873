/* Degree-4 spherical-harmonics encoding (see sh.h). The polynomials are the real spherical
 * harmonics written out in Cartesian form for a unit vector; the comments give each
 * constant's closed form. */
#include "field/sh.h"

#include <stddef.h>

void fg_sh4_encode(const float *d, int B, float *out) {
  for (int i = 0; i < B; i++) {
    const float x = d[(size_t)i * 3 + 0], y = d[(size_t)i * 3 + 1], z = d[(size_t)i * 3 + 2];
    const float xy = x * y, xz = x * z, yz = y * z, x2 = x * x, y2 = y * y, z2 = z * z;
    float *o = out + (size_t)i * FG_SH4_DIM;
    o[0] = 0.28209479177387814f;                             /* 1/(2 sqrt(pi)) */
    o[1] = -0.48860251190291987f * y;                        /* sqrt(3)/(2 sqrt(pi)) */
    o[2] = 0.48860251190291987f * z;
    o[3] = -0.48860251190291987f * x;
    o[4] = 1.0925484305920792f * xy;                         /* sqrt(15)/(2 sqrt(pi)) */
    o[5] = -1.0925484305920792f * yz;
    o[6] = 0.94617469575755997f * z2 - 0.31539156525251999f; /* sqrt(5)(3z^2-1)/(4 sqrt(pi)) */
    o[7] = -1.0925484305920792f * xz;
    o[8] = 0.54627421529603959f * x2 - 0.54627421529603959f * y2; /* sqrt(15)/(4 sqrt(pi)) */
    o[9] = 0.59004358992664352f * y * (-3.0f * x2 + y2);    /* sqrt(70)/(8 sqrt(pi)) */
    o[10] = 2.8906114426405538f * xy * z;                    /* sqrt(105)/(2 sqrt(pi)) */
    o[11] = 0.45704579946446572f * y * (1.0f - 5.0f * z2);   /* sqrt(42)/(8 sqrt(pi)) */
    o[12] = 0.3731763325901154f * z * (5.0f * z2 - 3.0f);    /* sqrt(7)/(4 sqrt(pi)) */
    o[13] = 0.45704579946446572f * x * (1.0f - 5.0f * z2);
    o[14] = 1.4453057213202769f * z * (x2 - y2);             /* sqrt(105)/(4 sqrt(pi)) */
    o[15] = 0.59004358992664352f * x * (-x2 + 3.0f * y2);
  }
}
