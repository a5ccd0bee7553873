/* Marching cubes, solid voxel centres, vertex normals and colours of the geometry of a trained
 * field (geometry.h). */
#include "query/geometry.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "field/model.h"
#include "io/ply.h"
#include "query/internal.h"

/* ---------------------------------------------------------------- the case table */

/* Corner i of a cell sits at (CX[i], CY[i], CZ[i]) voxel steps from its lowest corner. */
static const int CX[8] = {0, 1, 1, 0, 0, 1, 1, 0};
static const int CY[8] = {0, 0, 1, 1, 0, 0, 1, 1};
static const int CZ[8] = {0, 0, 0, 0, 1, 1, 1, 1};
/* Edge e joins corners EDGE[e][0] and EDGE[e][1]. */
static const int EDGE[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
/* The six faces' corners, counter-clockwise seen from outside the cell. */
static const int FACE[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 4, 7, 3},
                               {1, 2, 6, 5}, {0, 1, 5, 4}, {3, 7, 6, 2}};

#define MAX_CASE_TRIANGLES 12

typedef struct mc_case {
  uint8_t n;                           /* triangles */
  uint8_t edge[MAX_CASE_TRIANGLES][3]; /* their vertices, as edges of the cell */
} mc_case;

static mc_case mc_table[256];
static pthread_once_t mc_once = PTHREAD_ONCE_INIT;

static int edge_of(int a, int b) {
  for (int e = 0; e < 12; e++)
    if ((EDGE[e][0] == a && EDGE[e][1] == b) || (EDGE[e][0] == b && EDGE[e][1] == a)) return e;
  return -1; /* not reached: FACE only pairs neighbours */
}

/* Whether cell edges e and f lie on a common face of the cell (they meet at a corner or face
 * each other across one). */
static int share_face(int e, int f) {
  for (int q = 0; q < 6; q++) {
    int has_e = 0, has_f = 0;
    for (int k = 0; k < 4; k++) {
      const int a = FACE[q][k], b = FACE[q][(k + 1) & 3];
      has_e |= edge_of(a, b) == e;
      has_f |= edge_of(a, b) == f;
    }
    if (has_e && has_f) return 1;
  }
  return 0;
}

/* The first position in loop (len edges) from which a fan's diagonals join only edges on no
 * common face; 0 when there is none (never, for the loops mc_build_case makes). */
static int mc_apex(const int *loop, int len) {
  for (int a = 0; a < len; a++) {
    int ok = 1;
    for (int k = 2; k + 1 < len && ok; k++) ok = !share_face(loop[a], loop[(a + k) % len]);
    if (ok) return a;
  }
  return 0;
}

/* The triangles of case m (bit i: corner i solid), by the rule of geometry.h. Walking a face
 * counter-clockwise from outside, its crossed edges alternate between entering the solid
 * (empty corner, then solid) and leaving it. Each entering edge starts a segment of the
 * surface's boundary on that face; it ends at the leaving edge before it on the walk, which
 * for one run of solid corners is the run's other end, and for two runs is the other run's:
 * the cut then goes around the empty corners and the solid ones stay joined. Followed from
 * start to end, the segments turn counter-clockwise seen from the empty side (corner 0 alone
 * gives edges 0 -> 3 -> 8: the triangle faces (1,1,1), away from the corner). */
static void mc_build_case(int m, mc_case *out) {
  int next[12];
  for (int e = 0; e < 12; e++) next[e] = -1;
  for (int f = 0; f < 6; f++) {
    int cross[4], entering[4], n = 0;
    for (int k = 0; k < 4; k++) {
      const int a = FACE[f][k], b = FACE[f][(k + 1) & 3];
      const int sa = (m >> a) & 1, sb = (m >> b) & 1;
      if (sa != sb) {
        cross[n] = edge_of(a, b);
        entering[n++] = sb;
      }
    }
    for (int k = 0; k < n; k++)
      if (entering[k]) next[cross[k]] = cross[(k + n - 1) % n];
  }
  out->n = 0;
  int done[12] = {0};
  for (int e0 = 0; e0 < 12; e0++) {
    if (next[e0] < 0 || done[e0]) continue;
    int loop[12], len = 0;
    for (int e = e0; !done[e]; e = next[e]) {
      done[e] = 1;
      loop[len++] = e;
    }
    /* The fan's apex: the first vertex whose diagonals all cross the cell's inside. A
     * diagonal between two edges of one face would lie in that face, where the neighbouring
     * cell may draw it too, and four triangles would then share it. Every loop of the 256
     * cases has such an apex (the closed-surface checks of tests/query/test_geometry.c
     * would fail otherwise). */
    const int a = mc_apex(loop, len);
    for (int k = 1; k + 1 < len; k++) {
      uint8_t *t = out->edge[out->n++];
      t[0] = (uint8_t)loop[a], t[1] = (uint8_t)loop[(a + k) % len];
      t[2] = (uint8_t)loop[(a + k + 1) % len];
    }
  }
}

static void mc_build_table(void) {
  for (int m = 0; m < 256; m++) mc_build_case(m, &mc_table[m]);
}

/* ---------------------------------------------------------------- growing arrays */

typedef struct mesh_buf {
  fg_mesh *m;
  size_t cap_v, cap_f;
} mesh_buf;

static int add_vertex(mesh_buf *b, double x, double y, double z, uint32_t *index) {
  fg_mesh *m = b->m;
  if (m->n_vertices == b->cap_v) {
    size_t cap = b->cap_v ? 2 * b->cap_v : 4096;
    float *p = realloc(m->p_world, cap * 3 * sizeof *p);
    if (!p) return fg_fail(FG_ENOMEM, "mesh: out of memory for %zu vertices", cap);
    m->p_world = p, b->cap_v = cap;
  }
  float *p = m->p_world + 3 * m->n_vertices;
  p[0] = (float)x, p[1] = (float)y, p[2] = (float)z;
  *index = (uint32_t)m->n_vertices++;
  return 0;
}

static int add_face(mesh_buf *b, uint32_t v0, uint32_t v1, uint32_t v2) {
  fg_mesh *m = b->m;
  if (m->n_faces == b->cap_f) {
    size_t cap = b->cap_f ? 2 * b->cap_f : 8192;
    uint32_t *f = realloc(m->faces, cap * 3 * sizeof *f);
    if (!f) return fg_fail(FG_ENOMEM, "mesh: out of memory for %zu faces", cap);
    m->faces = f, b->cap_f = cap;
  }
  uint32_t *f = m->faces + 3 * m->n_faces++;
  f[0] = v0, f[1] = v1, f[2] = v2;
  return 0;
}

/* Gives back the unused tails of the arrays; keeps them when realloc fails (they stay valid). */
static void shrink(fg_mesh *m) {
  if (m->n_vertices) {
    float *p = realloc(m->p_world, m->n_vertices * 3 * sizeof *p);
    if (p) m->p_world = p;
  } else {
    free(m->p_world);
    m->p_world = NULL;
  }
  if (m->n_faces) {
    uint32_t *f = realloc(m->faces, m->n_faces * 3 * sizeof *f);
    if (f) m->faces = f;
  } else {
    free(m->faces);
    m->faces = NULL;
  }
}

void fg_mesh_release(fg_mesh *m) {
  if (!m) return;
  free(m->p_world);
  free(m->rgb);
  free(m->faces);
  memset(m, 0, sizeof *m);
}

/* ---------------------------------------------------------------- marching cubes */

static int check_grid(const fg_voxel_grid *g, const float *alpha, float threshold) {
  if (!g || !alpha) return fg_fail(FG_EINVAL, "geometry: NULL grid or alpha");
  if (!(threshold > 0.0f && threshold <= 1.0f))
    return fg_fail(FG_EINVAL, "geometry: the alpha threshold must be in (0, 1], got %g",
                   (double)threshold);
  fg_voxel_grid chk;
  FG_TRY(fg_voxel_grid_init(&chk, g->min, g->max, g->voxel_size));
  if (chk.nx != g->nx || chk.ny != g->ny || chk.nz != g->nz)
    return fg_fail(FG_EINVAL, "geometry: the grid's sizes do not match its workspace");
  return 0;
}

/* Lattice node positions along one axis of n voxels: node 0 and node n + 1 are the padding,
 * on the faces of the grid's box; node i in 1..n is the centre of voxel i - 1. pos (n + 2). */
static void lattice_axis(double min, double vs, int n, double *pos) {
  pos[0] = min;
  for (int i = 1; i <= n; i++) pos[i] = min + (i - 0.5) * vs;
  pos[n + 1] = min + n * vs;
}

/* The alpha of node layer k (0..nz+1) into layer (NX * NY), padding 0; NaN counts as 0. */
static void load_layer(const fg_voxel_grid *g, const float *alpha, int k, float *layer) {
  const int NX = g->nx + 2, NY = g->ny + 2;
  memset(layer, 0, (size_t)NX * NY * sizeof *layer);
  if (k < 1 || k > g->nz) return;
  for (int j = 1; j <= g->ny; j++) {
    const float *row = alpha + ((size_t)(k - 1) * g->ny + (size_t)(j - 1)) * g->nx;
    float *out = layer + (size_t)j * NX + 1;
    for (int i = 0; i < g->nx; i++) out[i] = row[i] == row[i] ? row[i] : 0.0f;
  }
}

/* The scratch of one marching-cubes pass: two node layers of alpha and the vertex index of
 * every lattice edge of the slab between them (UINT32_MAX until made). */
typedef struct mc_slab {
  int NX, NY;
  float *val[2];     /* (NY, NX) alpha of the bottom and top node layers */
  uint32_t *xe[2];   /* (NY, NX - 1) x edges of each layer */
  uint32_t *ye[2];   /* (NY - 1, NX) y edges of each layer */
  uint32_t *ze;      /* (NY, NX) z edges between the layers */
  const double *px, *py, *pz;
  double zb, zt;     /* heights of the two layers */
  float threshold;
} mc_slab;

/* The vertex on edge e of cell (i, j) of the slab, made when first asked for. */
static int edge_vertex(mc_slab *s, mesh_buf *b, int i, int j, int e, uint32_t *out) {
  int a = EDGE[e][0], c = EDGE[e][1];
  if (CX[a] + CY[a] + CZ[a] > CX[c] + CY[c] + CZ[c]) { /* a: the end nearer the origin */
    const int t = a;
    a = c, c = t;
  }
  const int ia = i + CX[a], ja = j + CY[a], la = CZ[a];
  uint32_t *slot = CX[c] != CX[a]   ? &s->xe[la][(size_t)ja * (s->NX - 1) + ia]
                   : CY[c] != CY[a] ? &s->ye[la][(size_t)ja * s->NX + ia]
                                    : &s->ze[(size_t)ja * s->NX + ia];
  if (*slot == UINT32_MAX) {
    const int ic = i + CX[c], jc = j + CY[c], lc = CZ[c];
    const double va = s->val[la][(size_t)ja * s->NX + ia];
    const double vc = s->val[lc][(size_t)jc * s->NX + ic];
    const double t = (s->threshold - va) / (vc - va); /* one end solid, the other not */
    const double xa = s->px[ia], ya = s->py[ja], za = la ? s->zt : s->zb;
    const double xc = s->px[ic], yc = s->py[jc], zc = lc ? s->zt : s->zb;
    FG_TRY(add_vertex(b, xa + t * (xc - xa), ya + t * (yc - ya), za + t * (zc - za), slot));
  }
  *out = *slot;
  return 0;
}

int fg_mesh_marching_cubes(const fg_voxel_grid *g, const float *alpha, float threshold,
                           fg_mesh *out) {
  if (!out) return fg_fail(FG_EINVAL, "geometry: NULL mesh");
  memset(out, 0, sizeof *out);
  FG_TRY(check_grid(g, alpha, threshold));
  pthread_once(&mc_once, mc_build_table);
  const int NX = g->nx + 2, NY = g->ny + 2, NZ = g->nz + 2;
  const size_t layer = (size_t)NX * NY;
  mc_slab s = {.NX = NX, .NY = NY, .threshold = threshold};
  double *pos = malloc((size_t)(NX + NY + NZ) * sizeof *pos);
  void *mem = malloc(layer * (2 * sizeof(float) + 5 * sizeof(uint32_t)));
  mesh_buf b = {.m = out};
  int rc = 0;
  if (!pos || !mem) {
    rc = fg_fail(FG_ENOMEM, "mesh: out of memory for a grid of %dx%dx%d", g->nx, g->ny, g->nz);
    goto out;
  }
  lattice_axis(g->min[0], g->voxel_size, g->nx, pos);
  lattice_axis(g->min[1], g->voxel_size, g->ny, pos + NX);
  lattice_axis(g->min[2], g->voxel_size, g->nz, pos + NX + NY);
  s.px = pos, s.py = pos + NX, s.pz = pos + NX + NY;
  s.val[0] = mem, s.val[1] = s.val[0] + layer;
  s.xe[0] = (uint32_t *)(s.val[1] + layer), s.xe[1] = s.xe[0] + layer;
  s.ye[0] = s.xe[1] + layer, s.ye[1] = s.ye[0] + layer, s.ze = s.ye[1] + layer;
  load_layer(g, alpha, 0, s.val[0]);
  memset(s.xe[0], 0xff, layer * sizeof(uint32_t));
  memset(s.ye[0], 0xff, layer * sizeof(uint32_t));
  const float thr = threshold;
  for (int k = 0; k + 1 < NZ && rc == 0; k++) {
    /* The slab between node layers k (bottom, index 0) and k + 1 (top, index 1). */
    load_layer(g, alpha, k + 1, s.val[1]);
    memset(s.xe[1], 0xff, layer * sizeof(uint32_t));
    memset(s.ye[1], 0xff, layer * sizeof(uint32_t));
    memset(s.ze, 0xff, layer * sizeof(uint32_t));
    s.zb = s.pz[k], s.zt = s.pz[k + 1];
    for (int j = 0; j + 1 < NY && rc == 0; j++)
      for (int i = 0; i + 1 < NX && rc == 0; i++) {
        int m = 0;
        for (int c = 0; c < 8; c++)
          m |= (s.val[CZ[c]][(size_t)(j + CY[c]) * NX + i + CX[c]] >= thr) << c;
        const mc_case *mc = &mc_table[m];
        for (int t = 0; t < mc->n && rc == 0; t++) {
          uint32_t v[3];
          for (int q = 0; q < 3 && rc == 0; q++)
            rc = edge_vertex(&s, &b, i, j, mc->edge[t][q], &v[q]);
          if (rc == 0) rc = add_face(&b, v[0], v[1], v[2]);
        }
      }
    /* The top layer becomes the next slab's bottom. */
    float *tv = s.val[0];
    s.val[0] = s.val[1], s.val[1] = tv;
    uint32_t *tx = s.xe[0], *ty = s.ye[0];
    s.xe[0] = s.xe[1], s.xe[1] = tx;
    s.ye[0] = s.ye[1], s.ye[1] = ty;
  }
out:
  free(pos);
  free(mem);
  if (rc != 0) {
    fg_mesh_release(out);
    return rc;
  }
  shrink(out);
  out->has_faces = 1;
  return 0;
}

/* ---------------------------------------------------------------- points and normals */

int fg_mesh_points(const fg_voxel_grid *g, const float *alpha, float threshold, fg_mesh *out) {
  if (!out) return fg_fail(FG_EINVAL, "geometry: NULL mesh");
  memset(out, 0, sizeof *out);
  FG_TRY(check_grid(g, alpha, threshold));
  const size_t N = fg_voxel_grid_count(g);
  size_t n = 0;
  for (size_t i = 0; i < N; i++) n += alpha[i] >= threshold;
  out->p_world = malloc((n ? n : 1) * 3 * sizeof *out->p_world);
  if (!out->p_world) return fg_fail(FG_ENOMEM, "points: out of memory for %zu points", n);
  size_t k = 0;
  for (size_t i = 0; i < N; i++)
    if (alpha[i] >= threshold) fg_query_grid_centres_range(g, i, 1, out->p_world + 3 * k++);
  out->n_vertices = n;
  return 0;
}

void fg_mesh_vertex_normals(const fg_mesh *m, float *normals) {
  memset(normals, 0, m->n_vertices * 3 * sizeof *normals);
  for (size_t f = 0; f < m->n_faces; f++) {
    const uint32_t *v = m->faces + 3 * f;
    const float *a = m->p_world + 3 * (size_t)v[0], *b = m->p_world + 3 * (size_t)v[1],
                *c = m->p_world + 3 * (size_t)v[2];
    const float u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const float w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const float n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                        u[0] * w[1] - u[1] * w[0]}; /* twice the area, outwards */
    for (int q = 0; q < 3; q++)
      for (int k = 0; k < 3; k++) normals[3 * (size_t)v[q] + k] += n[k];
  }
  for (size_t i = 0; i < m->n_vertices; i++) {
    float *n = normals + 3 * i;
    const double len = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
    for (int k = 0; k < 3; k++) n[k] = len > 0 ? (float)(n[k] / len) : 0.0f;
  }
}

/* ---------------------------------------------------------------- colours */

int fg_mesh_colour(fg_mesh *m, const fg_field *f, float inset_m, int n_threads) {
  if (!m || !f) return fg_fail(FG_EINVAL, "mesh colour: NULL argument");
  free(m->rgb);
  m->rgb = NULL;
  const size_t n = m->n_vertices;
  float *x = malloc((n ? n : 1) * 3 * sizeof *x);  /* (n, 3) where each colour is taken */
  float *d = malloc((n ? n : 1) * 3 * sizeof *d);  /* (n, 3) looking along */
  float *c = malloc((n ? n : 1) * 3 * sizeof *c);  /* (n, 3) colours */
  uint8_t *rgb = malloc((n ? n : 1) * 3);
  int rc = x && d && c && rgb ? 0 : fg_fail(FG_ENOMEM, "mesh colour: out of memory");
  if (rc == 0) {
    fg_mesh_vertex_normals(m, d); /* all zero for points */
    for (size_t i = 0; i < n; i++) {
      float *di = d + 3 * i;
      const int has_normal = di[0] != 0.0f || di[1] != 0.0f || di[2] != 0.0f;
      for (int k = 0; k < 3; k++) {
        x[3 * i + k] = m->p_world[3 * i + k] - (has_normal ? inset_m * di[k] : 0.0f);
        di[k] = has_normal ? -di[k] : (k == 2 ? -1.0f : 0.0f);
      }
    }
    rc = fg_field_colour(f, x, d, (int64_t)n, c, n_threads);
  }
  if (rc == 0) {
    for (size_t i = 0; i < 3 * n; i++) {
      const float v = c[i] > 0.0f ? (c[i] < 1.0f ? c[i] : 1.0f) : 0.0f; /* NaN goes to 0 */
      rgb[i] = (uint8_t)lrintf(v * 255.0f);
    }
    m->rgb = rgb;
    rgb = NULL;
  }
  free(x);
  free(d);
  free(c);
  free(rgb);
  return rc;
}

/* ---------------------------------------------------------------- field sampling and PLY */

int fg_voxel_alpha(const fg_field *f, const fg_voxel_grid *g, float *alpha, int n_threads) {
  if (!f || !g || !alpha) return fg_fail(FG_EINVAL, "voxel alpha: NULL argument");
  fg_voxel_grid chk;
  FG_TRY(fg_voxel_grid_init(&chk, g->min, g->max, g->voxel_size));
  if (chk.nx != g->nx || chk.ny != g->ny || chk.nz != g->nz)
    return fg_fail(FG_EINVAL, "voxel alpha: the grid's sizes do not match its workspace");
  return fg_query_voxel_sample(f, g, 0, fg_voxel_grid_count(g), alpha, n_threads);
}

int fg_mesh_encode_ply(const fg_mesh *m, const char *comment, uint8_t **out, size_t *out_len) {
  if (!m) return fg_fail(FG_EINVAL, "mesh ply: NULL mesh");
  const fg_ply p = {.n_vertices = m->n_vertices, .n_faces = m->n_faces, .xyz = m->p_world,
                    .rgb = m->rgb, .faces = m->faces, .has_faces = m->has_faces};
  return fg_ply_encode(&p, comment, out, out_len);
}
