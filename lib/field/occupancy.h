/* Occupancy grid and ray marching (Instant-NGP, one cascade) over the field's unit cube.
 *
 * The grid covers [0,1]^3 with N^3 cells; cell (ix, iy, iz) covers [ix/N, (ix+1)/N) x ... and
 * has the linear index ix + N (iy + N iz). The caller maps its world box to the cube, and its
 * rays with it (rays_d stays a unit vector in cube units, so t and dt are cube lengths; for a
 * box of side L metres, t_m = L t and dt_m = L dt). Per cell the grid keeps
 *   density  a float EMA of the field's density sigma (in 1/cube unit, the unit of 1/dt),
 *   bits     one occupancy bit (N^3 / 8 bytes), set where density > threshold,
 *   rank     the number of set bits before each 64-bit word (to draw occupied cells),
 *   mips     up to 4 coarser bit levels (a block of 2^m cells per axis is set when one of its
 *            cells is), which the marcher uses to skip empty space in large jumps.
 * A new grid has density 0 and every bit set, so the first training steps march everything.
 *
 * Update, as Instant-NGP (split so the caller evaluates all densities in one batch):
 *   1. fg_occgrid_update_points() picks M cells and one jittered point in each;
 *   2. the caller evaluates sigma at the M points with its own network;
 *   3. fg_occgrid_update_density() decays every cell, density = max(density * decay, sigma)
 *      for the sampled cells (density * decay for the others; a cell drawn twice takes the
 *      larger sigma), then rebuilds the bits with
 *        threshold = min(density_threshold, mean density over the grid).
 *      Instant-NGP stores the optical thickness sigma * dt_min and thresholds it at
 *      NERF_MIN_OPTICAL_THICKNESS = 0.01; keeping sigma instead, the same test reads
 *        density_threshold = 0.01 / dt_min      (fg_occgrid_density_threshold(dt_min)),
 *      about 5.91 per cube unit for Instant-NGP's dt_min = sqrt(3) / 1024.
 * Randomness is a counter-based hash of (seed, step, index), never a shared generator: the
 * results do not depend on the thread count or timing. No function allocates after
 * fg_occgrid_new / fg_occgrid_init; none keeps a pointer to the caller's arrays.
 *
 * Marching (fg_occgrid_march): samples on a fixed lattice t_k = t_start + k dt (float
 * arithmetic, exactly that expression), t_start = t_near + u dt with u in [0,1) drawn per ray
 * from (seed, step, ray), or u = 0.5 for every ray when step < 0 (inference). A sample is
 * emitted when its cell is occupied; empty cells are
 * skipped with a DDA that lands on the first lattice point outside the cell, so the output is
 * bit-identical to fg_occgrid_march_ref, which visits every lattice point. */
#ifndef FG_FIELD_OCCUPANCY_H
#define FG_FIELD_OCCUPANCY_H

#include <stddef.h>
#include <stdint.h>

typedef struct fg_occgrid fg_occgrid;

#define FG_OCCGRID_DEFAULT_RES 128
/* Instant-NGP's NERF_MIN_OPTICAL_THICKNESS: a cell is empty when sigma dt_min <= 0.01. */
#define FG_OCCGRID_MIN_OPTICAL_THICKNESS 0.01f
/* Instant-NGP's marching step, sqrt(3) / 1024: 1024 steps along the cube's diagonal. */
#define FG_OCCGRID_DEFAULT_DT 0.0016914558f
#define FG_OCCGRID_DEFAULT_DECAY 0.95f
/* Steps during which every cell is updated (Instant-NGP: 256). */
#define FG_OCCGRID_DEFAULT_WARMUP_STEPS 256

/* ---- state ---------------------------------------------------------------------------- */

/* Bytes fg_occgrid_init needs for resolution N; 0 when N is invalid (N must be a multiple of
 * 4 in [4, 1024]). About 4.2 N^3 bytes: 8.8 MB for N = 128. Everything (densities, bits,
 * rank and mips) lives in this one block. */
size_t fg_occgrid_size(int N);

/* Lays a grid out in caller-owned memory mem (size bytes, aligned to 16 bytes at least) and
 * returns it in *out. The memory stays the caller's; the grid lives as long as it does, and
 * fg_occgrid_free() on such a grid does nothing. Returns FG_EINVAL for a bad N, FG_ERANGE
 * when size < fg_occgrid_size(N). */
int fg_occgrid_init(fg_occgrid **out, int N, void *mem, size_t size);

/* The same in one allocation the grid owns (fg_occgrid_free releases it). FG_ENOMEM. */
int fg_occgrid_new(fg_occgrid **out, int N);

/* Releases a grid made by fg_occgrid_new; accepts NULL and caller-owned grids (no-op). */
void fg_occgrid_free(fg_occgrid *g);

int fg_occgrid_resolution(const fg_occgrid *g);

/* The density EMA, (N^3) in cell order, owned by the grid. Writable: a caller (or a test)
 * may set densities directly and then call fg_occgrid_update_bits. */
float *fg_occgrid_density(fg_occgrid *g);

/* The occupancy bits, (N^3 / 64) words: cell c is bit c % 64 of word c / 64. Owned by the
 * grid; valid until the next update. */
const uint64_t *fg_occgrid_bits(const fg_occgrid *g);

/* 1 when cell c (in [0, N^3)) is occupied. */
int fg_occgrid_occupied(const fg_occgrid *g, int32_t cell);

/* Number of occupied cells, and the threshold and mean density of the last bit rebuild
 * (0 and 0 for a new grid). */
int64_t fg_occgrid_n_occupied(const fg_occgrid *g);
float fg_occgrid_threshold(const fg_occgrid *g);
float fg_occgrid_mean_density(const fg_occgrid *g);

/* 0.01 / dt_min: the density threshold equivalent to Instant-NGP's optical thickness. */
float fg_occgrid_density_threshold(float dt_min);

/* Rebuilds the bits from the densities: occupied iff density > min(density_threshold, mean),
 * the mean summed in double in a fixed order. Used by fg_occgrid_update_density. */
void fg_occgrid_update_bits(fg_occgrid *g, float density_threshold, int n_threads);

/* Replaces the bits with bits (N^3 / 64 words, cell c is bit c % 64 of word c / 64; only
 * read) and rebuilds what derives from them (rank table, n_occupied, coarse levels) as
 * fg_occgrid_update_bits does; densities, threshold and mean stay as they are. For loaders,
 * which restore bits that were saved rather than recompute them from rounded densities.
 * n_threads is accepted for symmetry (the rebuild is serial). 0, or FG_EINVAL for NULL. */
int fg_occgrid_set_bits(fg_occgrid *g, const uint64_t *bits, int n_threads);

/* Sets what fg_occgrid_threshold and fg_occgrid_mean_density report, for loaders that restore
 * a saved grid; changes nothing else. */
void fg_occgrid_set_stats(fg_occgrid *g, float threshold, float mean);

/* ---- update --------------------------------------------------------------------------- */

/* Number of points fg_occgrid_update_points writes at this step: N^3 while
 * step < warmup_steps, otherwise n_points (0 = N^3 / 4). */
int32_t fg_occgrid_update_count(const fg_occgrid *g, int32_t step, int32_t warmup_steps,
                                int32_t n_points);

/* Chooses M = fg_occgrid_update_count(...) cells and one uniformly jittered point inside each
 * (x in the cell's closed box). Warm-up (step < warmup_steps): every cell once, in order.
 * Afterwards: the first M/2 cells uniform over the grid, the other M - M/2 uniform over the
 * occupied cells (drawn exactly through the rank table; Instant-NGP rejection-samples with 10
 * tries instead), or uniform over the grid when none is occupied; cells may repeat.
 * cells_out is (M), x_out is (M,3). Returns FG_ERANGE (writing nothing) when
 * capacity < M, FG_EINVAL for negative arguments; *n_out = M in both success and FG_ERANGE. */
int fg_occgrid_update_points(const fg_occgrid *g, int32_t step, uint64_t seed,
                             int32_t warmup_steps, int32_t n_points, int32_t *cells_out,
                             float *x_out, int32_t capacity, int32_t *n_out, int n_threads);

/* Folds the densities sigma (M) measured at the points of cells (M) into the grid (see the
 * top of this file; decay 0.95 as Instant-NGP) and rebuilds the bits. A NaN sigma is ignored,
 * a negative one has no effect beyond the decay. Returns FG_EINVAL when a cell index is out
 * of range (the grid is then unchanged), or decay is not in [0, 1]. */
int fg_occgrid_update_density(fg_occgrid *g, const int32_t *cells, const float *sigma,
                              int32_t M, float decay, float density_threshold, int n_threads);

/* ---- marching ------------------------------------------------------------------------- */

/* Marches R rays through the occupied cells. rays_o (R,3) and rays_d (R,3) are in cube units,
 * rays_d of unit length (any nonzero length works; t is then in units of |d|). A ray's
 * interval is [t_near, t_far] = [max(0, entry), exit] of the cube (slabs; a zero direction
 * component is handled without division); rays that miss the cube, have a zero or non-finite
 * direction or a non-finite origin get no samples. Samples, for k = 0, 1, ...:
 *   t_k = t_start + (float)k * dt,  t_start = t_near + u dt,  u = hash(seed, step, ray) in [0,1)
 *                                                     (u = 0.5 when step < 0)
 *   while t_k <= t_far; position p = o + t_k d; cell = floor(p N) clamped to [0, N-1];
 *   emitted when that cell is occupied, until max_samples_per_ray have been emitted.
 * So a ray through an all-occupied grid gets floor((t_far - t_start) / dt) + 1 samples (as
 * evaluated in float: the number of k with t_k <= t_far), capped at max_samples_per_ray.
 * Output in render.h's layout, rays in order and each ray's samples near to far:
 *   ray_offset (R), ray_count (R), x (S,3) (p clamped to [0,1]^3), dt_out (S) (= dt, the
 *   segment a sample stands for), t_out (S) (= t_k, the distance along the ray).
 * dt > 0 (FG_OCCGRID_DEFAULT_DT). Two passes (count, exclusive prefix sum, write), rays split
 * across n_threads: the output is bit-identical for any thread count. Returns FG_ERANGE when
 * the samples exceed capacity: *n_samples is then the number needed, ray_offset and
 * ray_count are filled, x, dt_out and t_out are left untouched (retry with fewer rays or
 * more room). FG_EINVAL for bad arguments. On success *n_samples = S. */
int fg_occgrid_march(const fg_occgrid *g, int32_t n_rays, const float *rays_o,
                     const float *rays_d, float dt, int32_t max_samples_per_ray, uint64_t seed,
                     int32_t step, int32_t capacity, int32_t *ray_offset, int32_t *ray_count,
                     float *x, float *dt_out, float *t_out, int32_t *n_samples, int n_threads);

/* Reference: the same contract, single-threaded, visiting every lattice point (no DDA). */
int fg_occgrid_march_ref(const fg_occgrid *g, int32_t n_rays, const float *rays_o,
                         const float *rays_d, float dt, int32_t max_samples_per_ray,
                         uint64_t seed, int32_t step, int32_t capacity, int32_t *ray_offset,
                         int32_t *ray_count, float *x, float *dt_out, float *t_out,
                         int32_t *n_samples);

#endif
