/* Private parts shared by the files of lib/grasp. */
#ifndef FG_GRASP_INTERNAL_H
#define FG_GRASP_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "field/model.h"
#include "grasp/grasp.h"

#define FG_GRASP_HIDDEN FG_FIELD_FEATURE_HIDDEN

struct fg_grasp_field {
  const fg_voxel_features *vf; /* the caller's; outlives the grasp field */
  fg_voxel_grid grid;
  int dim;                     /* D */
  const float *alpha;          /* (nz, ny, nx), vf's */
  size_t n_vox, n_kept;
  int32_t *slot;               /* (nz, ny, nx): row of y, or -1 for a voxel without features */
  float *y;                    /* (n_kept, 64): alpha_v R h_v */
  float *Q;                    /* (D, 64): W = Q R */
};

/* One corner of a trilinear cell that keeps features: its row of y, its weight and the
 * weight's gradient in the world frame (per metre). */
typedef struct fg_grasp_corner {
  int32_t slot;
  float w;
  float dw[3];
} fg_grasp_corner;

/* The corners of the cell around x (world, metres) that keep features into c; returns how
 * many (0..8). */
int fg_grasp_corners(const fg_voxel_grid *g, const int32_t *slot, const float x[3],
                     fg_grasp_corner c[8]);

/* A target resolved against a field: C (n, 64) = Z_i projected by Q^T, cq (64) = Q^T q. */
typedef struct fg_grasp_prepared {
  int n;
  const float *p; /* (n, 3), the target's */
  float *C;       /* owned */
  double z_norm;  /* |Z| */
  int has_q;
  float cq[FG_GRASP_HIDDEN];
} fg_grasp_prepared;

int fg_grasp_prepare(const fg_grasp_field *gf, const fg_grasp_target *t, fg_grasp_prepared *p);
void fg_grasp_prepared_release(fg_grasp_prepared *p);

/* Per-thread buffers of one cost evaluation for n query points. */
typedef struct fg_grasp_scratch {
  float *x;             /* (n, 3) */
  float *u;             /* (n, 64) */
  fg_grasp_corner *c;   /* (n, 8) */
  int *m;               /* (n) */
  float *nrm;           /* (n) |u_i| */
} fg_grasp_scratch;

int fg_grasp_scratch_init(fg_grasp_scratch *s, int n);
void fg_grasp_scratch_release(fg_grasp_scratch *s);

/* fg_grasp_cost over a prepared target with the caller's scratch (no allocation). */
double fg_grasp_cost_fast(const fg_grasp_field *gf, const fg_grasp_prepared *p,
                          const double T[16], double d_t[3], double d_w[3], double *cos_out,
                          double *weight_out, fg_grasp_scratch *s);

#endif
