/* Counter-based random numbers: a value is a pure function of (seed, index), so results never
 * depend on the thread count or on the order in which threads draw them. */
#ifndef FG_CORE_RNG_H
#define FG_CORE_RNG_H

#include <stdint.h>

/* splitmix64's finaliser (Steele, Lea, Flood 2014): a bijective mix of 64 bits, with no
 * increment (the counter-based hashes of training and the initialisers add their own). */
static inline uint64_t fg_mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/* One step of splitmix64: the golden-ratio increment, then the finaliser. */
static inline uint64_t fg_splitmix64(uint64_t z) { return fg_mix64(z + 0x9e3779b97f4a7c15ULL); }

/* Uniform double in [0, 1) (53 bits) for draw `index` of stream `seed`. */
static inline double fg_rng_uniform(uint64_t seed, uint64_t index) {
  return (double)(fg_splitmix64(fg_splitmix64(seed) ^ index) >> 11) * 0x1.0p-53;
}

#endif
