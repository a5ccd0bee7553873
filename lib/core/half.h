/* IEEE 754 binary16 <-> binary32, round to nearest even; NaN and Inf preserved. */
#ifndef FG_CORE_HALF_H
#define FG_CORE_HALF_H

#include <stddef.h>
#include <stdint.h>

float fg_half_to_float(uint16_t h);
uint16_t fg_float_to_half(float f);

/* dst[i] = half(src[i]) / float(src[i]) for n elements. */
void fg_half_to_float_n(const uint16_t *src, float *dst, size_t n);
void fg_float_to_half_n(const float *src, uint16_t *dst, size_t n);

#endif
