/* Multiresolution hash encoding (Instant-NGP, Mueller et al. 2022), with tiny-cuda-nn's
 * conventions so that a model configured here means what it means in the literature.
 *
 * Geometry. Inputs x are (B,3) in [0,1]^3 (the caller maps its box into the cube; coordinates
 * outside it, and NaN, are clamped to it). With b = exp((ln N_max - ln N_min) / (L-1)), level l
 * has
 *   scale_l = N_min * b^l - 1            (computed in double, rounded to float)
 *   res_l   = ceil(scale_l) + 1          (grid vertices per axis)
 *   pos     = x * scale_l + 0.5,  g = floor(pos),  frac = pos - g   (per axis, in float)
 * and the output is the trilinear interpolation of the 8 corner entries g + {0,1}^3, corner c
 * taking +1 on axis d when bit d of c is set, weight prod_d (bit ? frac_d : 1 - frac_d)
 * (multiplied in axis order x, y, z), summed over c = 0..7 in order from 0.
 *
 * Tables. A level with res^3 <= T = 2^log2_table_size is dense: corner (cx,cy,cz) has index
 * cx + cy*res + cz*res^2 and the table holds res^3 entries rounded up to a multiple of 8.
 * Otherwise it is hashed: index (cx*1 ^ cy*2654435761 ^ cz*805459861) mod 2^32, masked to T-1,
 * and the table holds T entries. As in tiny-cuda-nn, a dense index is taken modulo the table
 * size: because of the +0.5 offset, on a level whose scale has a fractional part of 0 or
 * >= 0.5 the upper corner reaches coordinate res within the band x >= (ceil(scale) - 0.5) /
 * scale below each upper face of the cube, and that corner then shares its entry with another
 * vertex (a collision, like those of the hashed levels), never an access out of bounds. On
 * the default config this is level 0 for x >= 0.967 and level 2 for x >= 0.998.
 *
 * Parameters are one float array: the level tables concatenated in level order, each entry
 * holding n_features consecutive floats (entry-major). Outputs are (B, L*F) sample-major, level
 * l's F features at columns l*F .. l*F+F-1, ready to be the input matrix of an MLP.
 *
 * Threads and determinism. The forward pass splits samples across threads; the backward pass
 * gives each thread whole levels (a fixed assignment computed from the config), and every
 * table entry receives its contributions from one thread in sample order, corner order. Both
 * results are therefore bit-identical for any thread count and timing, and bit-identical to
 * the scalar references. n_threads <= 0 takes the OpenMP default. Nothing here allocates.
 *
 * Memory. The kernels need no scratch (about 24 KB of stack per thread). The hashed tables
 * are 4 MB each, so gathers also miss the TLB: allocate params and the gradient 2 MB-aligned
 * and madvise(MADV_HUGEPAGE) them (Debian's THP setting is "madvise") for some 10% more speed.
 *
 * No gradient with respect to x is computed (a NeRF does not need one). */
#ifndef FG_FIELD_HASHGRID_H
#define FG_FIELD_HASHGRID_H

#include <stddef.h>
#include <stdint.h>

#define FG_HASHGRID_MAX_LEVELS 32
#define FG_HASHGRID_MAX_FEATURES 16

typedef struct fg_hashgrid_config {
  int n_levels;          /* L, 1..FG_HASHGRID_MAX_LEVELS (Instant-NGP: 16) */
  int n_features;        /* F per level, 1..FG_HASHGRID_MAX_FEATURES (2) */
  int log2_table_size;   /* log2 T, 4..28 (19) */
  int base_resolution;   /* N_min, >= 2 (16) */
  int finest_resolution; /* N_max, N_min..1<<20 (2048) */
} fg_hashgrid_config;

/* One level's geometry, for callers that want to show or check it. */
typedef struct fg_hashgrid_level {
  float scale;         /* scale_l above */
  uint32_t resolution; /* res_l, vertices per axis */
  uint32_t n_entries;  /* table entries (F floats each) */
  int dense;           /* 1: dense indexing, 0: hashed */
  size_t offset;       /* first float of this level's table in the parameter array */
} fg_hashgrid_level;

/* Fills cfg with Instant-NGP's NeRF defaults: L=16, F=2, T=2^19, N_min=16, N_max=2048. */
void fg_hashgrid_config_default(fg_hashgrid_config *cfg);

/* Checks cfg; returns 0 or FG_EINVAL with a detail naming the bad field. The kernels below
 * assume a config that passed this check (they do not check it again). */
int fg_hashgrid_config_check(const fg_hashgrid_config *cfg);

/* Parameter layout: level_offsets (L), when not NULL, receives the first float of each level's
 * table; *n_params (not NULL) the total number of floats. Returns 0 or FG_EINVAL. */
int fg_hashgrid_layout(const fg_hashgrid_config *cfg, size_t level_offsets[], size_t *n_params);

/* Geometry of level `level` (0..L-1) into *info. Returns 0 or FG_EINVAL. */
int fg_hashgrid_level_info(const fg_hashgrid_config *cfg, int level, fg_hashgrid_level *info);

/* Initialises params (n_params floats, caller-owned) uniformly in [-1e-4, 1e-4], as
 * Instant-NGP does, from a counter-based generator (splitmix64 of seed and index): the same
 * seed gives the same bytes on every machine. Returns 0 or FG_EINVAL. */
int fg_hashgrid_init(const fg_hashgrid_config *cfg, float *params, uint64_t seed);

/* Encodes B points. params (n_params), x is (B,3), out is (B, L*F) (overwritten). */
void fg_hashgrid_forward(const fg_hashgrid_config *cfg, const float *params, const float *x,
                         int B, float *out, int n_threads);

/* Accumulates (+=) d(loss)/d(params) into grad_params (n_params) given dout = d(loss)/d(out),
 * (B, L*F), for the same x (B,3) as the forward pass. Touches only entries some sample uses. */
void fg_hashgrid_backward(const fg_hashgrid_config *cfg, const float *x, int B,
                          const float *dout, float *grad_params, int n_threads);

/* Readable single-threaded references of the two kernels above (same arguments, no
 * n_threads): one sample, one level, one corner at a time. For tests. */
void fg_hashgrid_forward_ref(const fg_hashgrid_config *cfg, const float *params, const float *x,
                             int B, float *out);
void fg_hashgrid_backward_ref(const fg_hashgrid_config *cfg, const float *x, int B,
                              const float *dout, float *grad_params);

#endif
