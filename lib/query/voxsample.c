/* A voxel's opacity from sub-samples (internal.h), shared by the voxel feature cache, its
 * reference scorer and fg_voxel_alpha.
 *
 * Why not the centre alone: a field trained with depth (or the distortion loss) puts a
 * surface in a shell a few millimetres thick, thinner than a voxel, and leaves the inside of
 * a solid as empty as the air in front of it (no view sees it). One density sample at a 1 cm
 * voxel's centre then misses most of the shell, and a ball of 300 voxels can come out with
 * none occupied. The mean density over the voxel times its side is the optical depth of a
 * ray crossing it (averaged over where it crosses), so a shell of optical depth tau gives the
 * voxel alpha 1 - exp(-tau) whatever its thickness, and a solid voxel keeps the alpha its
 * centre gave. The mean is taken over the centres of the voxel's S^3 sub-cells (S =
 * FG_QUERY_VOXEL_SUBSAMPLES: 2.5 mm apart in a 1 cm voxel, finer than the shells seen).
 * The voxel's features stay those of its centre: a surface's features reach a few
 * millimetres into the air (the feature field is smooth), and a trial of the densest
 * sub-sample's features put the ball's best heatmap point in the table under it.
 *
 * The renderer never samples a cell of the field's occupancy grid that is empty, so a
 * density there never shaped an image: such sub-samples count 0 and are not evaluated,
 * which also skips most of a workspace's air. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "core/error.h"
#include "field/model.h"
#include "field/occupancy.h"
#include "query/internal.h"

#define S FG_QUERY_VOXEL_SUBSAMPLES
#define S3 (S * S * S)
#define VOX_CHUNK 4096 /* voxels per density evaluation: 262144 points at most */

/* Whether the field's occupancy grid lets the renderer sample at cube point c. */
static int occupied(const fg_occgrid *occ, int N, const float c[3]) {
  int32_t idx[3];
  for (int a = 0; a < 3; a++) {
    if (!(c[a] >= 0.0f && c[a] < 1.0f)) return 0; /* outside the cube: never rendered */
    idx[a] = (int32_t)(c[a] * (float)N);
    if (idx[a] >= N) idx[a] = N - 1;
  }
  return fg_occgrid_occupied(occ, idx[0] + N * (idx[1] + N * idx[2]));
}

int fg_query_voxel_sample(const fg_field *f, const fg_voxel_grid *g, size_t i0, size_t n,
                          float *alpha, int n_threads) {
  const size_t cap = (size_t)VOX_CHUNK * S3;
  float *x = malloc(cap * 3 * sizeof *x);
  float *sigma = malloc(cap * sizeof *sigma);
  int32_t *src = malloc(cap * sizeof *src); /* each point's voxel in the chunk */
  int rc = x && sigma && src ? 0 : fg_fail(FG_ENOMEM, "voxel sampling: out of memory");
  const int N = fg_occgrid_resolution(f->occ);
  const double vs = g->voxel_size;
  const size_t nx = (size_t)g->nx, ny = (size_t)g->ny;
  for (size_t c0 = 0; rc == 0 && c0 < n; c0 += VOX_CHUNK) {
    const size_t m = n - c0 < VOX_CHUNK ? n - c0 : VOX_CHUNK;
    size_t np = 0;
    for (size_t k = 0; k < m; k++) {
      const size_t i = i0 + c0 + k;
      const size_t iv[3] = {i % nx, (i / nx) % ny, i / (nx * ny)};
      for (int s = 0; s < S3; s++) {
        const int sub[3] = {s % S, (s / S) % S, s / (S * S)};
        float *p = x + 3 * np, c[3];
        for (int a = 0; a < 3; a++)
          p[a] = (float)(g->min[a] + ((double)iv[a] + (sub[a] + 0.5) / S) * vs);
        fg_field_to_cube(f, p, 1, c);
        if (occupied(f->occ, N, c)) src[np++] = (int32_t)k;
      }
    }
    if (np) rc = fg_field_density(f, x, (int64_t)np, sigma, n_threads);
    /* the sum per voxel, in sub-sample order (the points are in voxel order) */
    for (size_t k = 0, j = 0; rc == 0 && k < m; k++) {
      double sum = 0.0;
      for (; j < np && (size_t)src[j] == k; j++)
        sum += sigma[j] > 0.0f ? sigma[j] : 0.0f; /* NaN or negative: empty */
      alpha[c0 + k] = (float)(1.0 - exp(-sum / S3 * vs));
    }
  }
  free(x);
  free(sigma);
  free(src);
  return rc;
}
