/* Geometry library (query/geometry.h, io/ply.h), unit level: marching cubes on random grids
 * (closed, consistently oriented, vertices on their lattice edges and in the box), on a box
 * cut by the grid and on an analytic sphere (vertices on the sphere, area, outward normals,
 * Euler characteristic), solid voxel centres, and PLY files read back, refused when malformed. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "io/ply.h"
#include "query/geometry.h"
#include "test.h"

static uint64_t rng = 0x9e3779b97f4a7c15ull;

/* Uniform in [0, 1) (xorshift64). */
static float urand(void) {
  rng ^= rng << 13;
  rng ^= rng >> 7;
  rng ^= rng << 17;
  return (float)((rng >> 11) * (1.0 / 9007199254740992.0));
}

static int cmp_u64(const void *a, const void *b) {
  const uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
  return x < y ? -1 : x > y;
}

/* Asserts that m is a closed, consistently oriented surface: no triangle repeats a vertex,
 * every directed edge occurs once and its reverse once too (so every undirected edge belongs
 * to exactly two triangles that traverse it in opposite directions). Returns the number of
 * undirected edges. */
static size_t assert_closed(const fg_mesh *m) {
  const size_t ne = 3 * m->n_faces;
  uint64_t *e = malloc((ne ? ne : 1) * sizeof *e);
  ASSERT(e != NULL);
  for (size_t f = 0; f < m->n_faces; f++) {
    const uint32_t *v = m->faces + 3 * f;
    if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2])
      FG_TEST_FAIL("face %zu repeats a vertex: %u %u %u", f, v[0], v[1], v[2]);
    for (int k = 0; k < 3; k++) {
      ASSERT(v[k] < m->n_vertices);
      e[3 * f + k] = (uint64_t)v[k] << 32 | v[(k + 1) % 3];
    }
  }
  qsort(e, ne, sizeof *e, cmp_u64);
  for (size_t i = 0; i + 1 < ne; i++)
    if (e[i] == e[i + 1])
      FG_TEST_FAIL("directed edge %u -> %u occurs twice", (unsigned)(e[i] >> 32),
                   (unsigned)e[i]);
  for (size_t i = 0; i < ne; i++) {
    const uint64_t rev = (e[i] & 0xffffffffu) << 32 | e[i] >> 32;
    if (!bsearch(&rev, e, ne, sizeof *e, cmp_u64))
      FG_TEST_FAIL("edge %u -> %u has no opposite: the surface is open or flips there",
                   (unsigned)(e[i] >> 32), (unsigned)e[i]);
  }
  free(e);
  return ne / 2;
}

/* Every vertex is used by some face (welding leaves no strays). */
static void assert_all_used(const fg_mesh *m) {
  uint8_t *used = calloc(m->n_vertices ? m->n_vertices : 1, 1);
  for (size_t i = 0; i < 3 * m->n_faces; i++) used[m->faces[i]] = 1;
  for (size_t v = 0; v < m->n_vertices; v++)
    if (!used[v]) FG_TEST_FAIL("vertex %zu belongs to no face", v);
  free(used);
}

static void assert_in_box(const fg_mesh *m, const fg_voxel_grid *g) {
  for (size_t v = 0; v < m->n_vertices; v++)
    for (int a = 0; a < 3; a++) {
      const int n = a == 0 ? g->nx : a == 1 ? g->ny : g->nz;
      const double lo = g->min[a], hi = g->min[a] + n * g->voxel_size;
      const double x = m->p_world[3 * v + a];
      if (!(x >= lo - 1e-6 && x <= hi + 1e-6))
        FG_TEST_FAIL("vertex %zu axis %d at %g lies outside the box [%g, %g]", v, a, x, lo, hi);
    }
}

/* The voxel indices of p along each axis, as doubles: centres are integers. */
static void voxel_coords(const fg_voxel_grid *g, const float *p, double c[3]) {
  for (int a = 0; a < 3; a++) c[a] = (p[a] - g->min[a]) / g->voxel_size - 0.5;
}

/* Random grids: closed and oriented whatever the values, vertices on lattice edges. */
static void test_random(void) {
  const double lo[3] = {-0.3, 0.1, 0.0}, hi[3] = {0.05, 0.4, 0.45};
  for (int trial = 0; trial < 40; trial++) {
    fg_voxel_grid g;
    ASSERT_OK(fg_voxel_grid_init(&g, lo, hi, 0.05 + 0.01 * (trial % 3)));
    const size_t N = fg_voxel_grid_count(&g);
    float *alpha = malloc(N * sizeof *alpha);
    const float density = trial < 20 ? 0.5f : urand(); /* how much is solid */
    size_t solid = 0;
    for (size_t i = 0; i < N; i++) {
      alpha[i] = urand() < density ? 0.3f + 0.7f * urand() : 0.29f * urand();
      solid += alpha[i] >= 0.3f;
    }
    if (trial == 3) alpha[5] = NAN; /* NaN is empty */
    fg_mesh m;
    ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.3f, &m));
    ASSERT(m.has_faces);
    ASSERT((m.n_faces > 0) == (solid > 0));
    ASSERT(m.rgb == NULL);
    const size_t n_edges = assert_closed(&m);
    assert_all_used(&m);
    assert_in_box(&m, &g);
    /* V - E + F is even (2 - 2 genus per component) */
    ASSERT_EQ(((long long)m.n_vertices - (long long)n_edges + (long long)m.n_faces) % 2, 0);
    /* Each vertex lies on one lattice edge: two of its voxel coordinates are those of lattice
     * nodes (whole numbers for centres, -0.5 and n - 0.5 for the padding on the box). */
    for (size_t v = 0; v < m.n_vertices; v++) {
      double c[3];
      voxel_coords(&g, m.p_world + 3 * v, c);
      int on_node = 0;
      for (int a = 0; a < 3; a++) {
        const int n = a == 0 ? g.nx : a == 1 ? g.ny : g.nz;
        on_node += (fabs(c[a] - floor(c[a] + 0.5)) < 1e-4 && c[a] > -0.25 && c[a] < n - 0.75) ||
                   fabs(c[a] + 0.5) < 1e-4 || fabs(c[a] - (n - 0.5)) < 1e-4;
      }
      if (on_node < 2) FG_TEST_FAIL("vertex %zu at voxel (%g, %g, %g) is on no lattice edge", v,
                                    c[0], c[1], c[2]);
    }
    /* The same input gives the same mesh. */
    fg_mesh m2;
    ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.3f, &m2));
    ASSERT_EQ(m2.n_vertices, m.n_vertices);
    ASSERT_EQ(m2.n_faces, m.n_faces);
    /* an empty mesh has no arrays, and memcmp takes no NULL even for 0 bytes */
    ASSERT(!m.n_vertices || memcmp(m2.p_world, m.p_world, m.n_vertices * 3 * sizeof(float)) == 0);
    ASSERT(!m.n_faces || memcmp(m2.faces, m.faces, m.n_faces * 3 * sizeof(uint32_t)) == 0);
    fg_mesh_release(&m2);
    fg_mesh_release(&m);
    free(alpha);
  }
}

/* A grid solid everywhere: a closed box capped half-way between the outer centres and the
 * box's faces (alpha 1 at the centres, 0 on the faces, threshold 0.5), area known. */
static void test_full_box(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.3, 0.4, 0.5};
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, lo, hi, 0.1));
  ASSERT_EQ(g.nx, 3);
  float alpha[60];
  for (int i = 0; i < 60; i++) alpha[i] = 1.0f;
  fg_mesh m;
  ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.5f, &m));
  assert_closed(&m);
  assert_in_box(&m, &g);
  double area = 0.0;
  for (size_t f = 0; f < m.n_faces; f++) {
    const float *a = m.p_world + 3 * m.faces[3 * f], *b = m.p_world + 3 * m.faces[3 * f + 1],
                *c = m.p_world + 3 * m.faces[3 * f + 2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                         u[0] * w[1] - u[1] * w[0]};
    area += 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  }
  /* Flat faces half-way between the outer centres and the box (0.025 m out), spanning the
   * outer centres (0.2 x 0.3 x 0.4 m); each edge bevelled by a strip and each corner by a
   * triangle, both of side 0.025 sqrt(2), the cut of a cell with one solid corner or two. */
  const double ax = 0.2, ay = 0.3, az = 0.4, c = 0.025 * sqrt(2.0);
  const double exact = 2 * (ax * ay + ay * az + ax * az) + 4 * c * (ax + ay + az) +
                       8 * sqrt(3.0) / 4 * c * c;
  ASSERT_NEAR(area, exact, 1e-5);
  fg_mesh_release(&m);
  /* A single solid voxel: an octahedron. */
  for (int i = 0; i < 60; i++) alpha[i] = 0.0f;
  alpha[(1 * 4 + 2) * 3 + 1] = 1.0f;
  ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.5f, &m));
  ASSERT_EQ(m.n_vertices, 6);
  ASSERT_EQ(m.n_faces, 8);
  assert_closed(&m);
  fg_mesh_release(&m);
  /* Nothing solid: an empty mesh that is still a mesh. */
  for (int i = 0; i < 60; i++) alpha[i] = 0.2f;
  ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.5f, &m));
  ASSERT_EQ(m.n_vertices, 0);
  ASSERT_EQ(m.n_faces, 0);
  ASSERT(m.has_faces);
  fg_mesh_release(&m);
}

/* Two voxels touching at an edge only, in one slab: the ambiguous faces join them into one
 * solid, so the surface is one closed component (Euler characteristic 2) and not two. */
static void test_ambiguous_face(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.4, 0.4, 0.3};
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, lo, hi, 0.1));
  float alpha[48] = {0};
  alpha[(1 * 4 + 1) * 4 + 1] = 1.0f; /* voxel (1, 1, 1) */
  alpha[(1 * 4 + 2) * 4 + 2] = 1.0f; /* voxel (2, 2, 1): diagonal in the xy plane */
  fg_mesh m;
  ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.5f, &m));
  const size_t n_edges = assert_closed(&m);
  ASSERT_EQ((long long)m.n_vertices - (long long)n_edges + (long long)m.n_faces, 2);
  fg_mesh_release(&m);
}

/* An analytic sphere of radius R: alpha = logistic((R - r) / w), so that alpha = 0.5 exactly
 * on the sphere. */
static void test_sphere(void) {
  const double c[3] = {0.013, -0.021, 0.007}, R = 0.6, w = 0.03, vs = 0.05;
  const double lo[3] = {-1, -1, -1}, hi[3] = {1, 1, 1};
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, lo, hi, vs));
  const size_t N = fg_voxel_grid_count(&g);
  float *alpha = malloc(N * sizeof *alpha);
  size_t solid = 0;
  for (int iz = 0; iz < g.nz; iz++)
    for (int iy = 0; iy < g.ny; iy++)
      for (int ix = 0; ix < g.nx; ix++) {
        double p[3];
        fg_voxel_grid_centre(&g, ix, iy, iz, p);
        const double r = sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                              (p[2] - c[2]) * (p[2] - c[2]));
        const size_t i = ((size_t)iz * g.ny + iy) * g.nx + ix;
        alpha[i] = (float)(1.0 / (1.0 + exp(-(R - r) / w)));
        solid += alpha[i] >= 0.5f;
      }
  fg_mesh m;
  ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.5f, &m));
  const size_t n_edges = assert_closed(&m);
  assert_all_used(&m);
  ASSERT_EQ((long long)m.n_vertices - (long long)n_edges + (long long)m.n_faces, 2);
  double worst = 0.0, area = 0.0;
  for (size_t v = 0; v < m.n_vertices; v++) {
    const float *p = m.p_world + 3 * v;
    const double r = sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                          (p[2] - c[2]) * (p[2] - c[2]));
    if (fabs(r - R) > worst) worst = fabs(r - R);
  }
  for (size_t f = 0; f < m.n_faces; f++) {
    const float *a = m.p_world + 3 * m.faces[3 * f], *b = m.p_world + 3 * m.faces[3 * f + 1],
                *d = m.p_world + 3 * m.faces[3 * f + 2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double t[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
    const double n[3] = {u[1] * t[2] - u[2] * t[1], u[2] * t[0] - u[0] * t[2],
                         u[0] * t[1] - u[1] * t[0]};
    area += 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    double out = 0.0; /* the normal against the direction from the centre */
    for (int k = 0; k < 3; k++) out += n[k] * ((a[k] + b[k] + d[k]) / 3.0 - c[k]);
    if (!(out > 0.0)) FG_TEST_FAIL("face %zu points into the sphere", f);
  }
  const double exact = 4.0 * M_PI * R * R;
  printf("sphere R = %g m on %g m voxels: %zu vertices, %zu faces, worst radial error %.2g "
         "voxel, area %.4f vs %.4f (%+.2f%%)\n", R, vs, m.n_vertices, m.n_faces, worst / vs, area,
         exact, 100.0 * (area / exact - 1.0));
  ASSERT(worst <= 0.5 * vs);
  ASSERT_NEAR(area / exact, 1.0, 0.03);
  /* Vertex normals: unit, outwards, close to the radial direction. */
  float *nrm = malloc(m.n_vertices * 3 * sizeof *nrm);
  fg_mesh_vertex_normals(&m, nrm);
  for (size_t v = 0; v < m.n_vertices; v++) {
    const float *p = m.p_world + 3 * v, *n = nrm + 3 * v;
    double radial[3], len = 0.0, dot = 0.0;
    for (int k = 0; k < 3; k++) radial[k] = p[k] - c[k], len += radial[k] * radial[k];
    for (int k = 0; k < 3; k++) dot += n[k] * radial[k] / sqrt(len);
    ASSERT_NEAR(sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]), 1.0, 1e-5);
    if (!(dot > 0.98)) FG_TEST_FAIL("vertex %zu: normal at %.3f to the radius", v, dot);
  }
  free(nrm);

  /* Points: the solid voxels' centres, as many as a sphere's volume holds. */
  fg_mesh pts;
  ASSERT_OK(fg_mesh_points(&g, alpha, 0.5f, &pts));
  ASSERT(!pts.has_faces);
  ASSERT_EQ(pts.n_faces, 0);
  ASSERT(pts.faces == NULL);
  ASSERT_EQ(pts.n_vertices, solid);
  ASSERT_NEAR((double)solid * vs * vs * vs / (4.0 / 3.0 * M_PI * R * R * R), 1.0, 0.03);
  for (size_t v = 0; v < pts.n_vertices; v++) {
    double cc[3];
    voxel_coords(&g, pts.p_world + 3 * v, cc);
    for (int a = 0; a < 3; a++) ASSERT_NEAR(cc[a], floor(cc[a] + 0.5), 1e-4);
    const float *p = pts.p_world + 3 * v;
    ASSERT(sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                (p[2] - c[2]) * (p[2] - c[2])) <= R + 1e-6);
  }
  /* A higher threshold keeps fewer voxels and a smaller surface. */
  fg_mesh fewer, inner;
  ASSERT_OK(fg_mesh_points(&g, alpha, 0.9f, &fewer));
  ASSERT(fewer.n_vertices < pts.n_vertices);
  ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, 0.9f, &inner));
  ASSERT(inner.n_faces < m.n_faces);
  fg_mesh_release(&fewer);
  fg_mesh_release(&inner);

  /* Bad inputs. */
  fg_mesh bad;
  ASSERT_ERR(fg_mesh_marching_cubes(&g, alpha, 0.0f, &bad), FG_EINVAL, "threshold");
  ASSERT_ERR(fg_mesh_marching_cubes(&g, alpha, 1.5f, &bad), FG_EINVAL, "threshold");
  ASSERT_ERR(fg_mesh_marching_cubes(&g, alpha, NAN, &bad), FG_EINVAL, "threshold");
  ASSERT_ERR(fg_mesh_points(&g, NULL, 0.5f, &bad), FG_EINVAL, "NULL");
  fg_voxel_grid wrong = g;
  wrong.nx++;
  ASSERT_ERR(fg_mesh_marching_cubes(&wrong, alpha, 0.5f, &bad), FG_EINVAL, "sizes");

  /* PLY: the mesh with colours, read back the same. */
  m.rgb = malloc(m.n_vertices * 3);
  for (size_t i = 0; i < 3 * m.n_vertices; i++) m.rgb[i] = (uint8_t)(i * 7);
  uint8_t *buf;
  size_t len;
  ASSERT_OK(fg_mesh_encode_ply(&m, "fieldgrip test sphere\nsecond line dropped", &buf, &len));
  char *head = strndup((const char *)buf, 400);
  char *expect = NULL;
  ASSERT(asprintf(&expect, "ply\nformat binary_little_endian 1.0\ncomment fieldgrip test "
                  "sphere\nelement vertex %zu\nproperty float x\nproperty float y\nproperty "
                  "float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                  "element face %zu\nproperty list uchar int vertex_indices\nend_header\n",
                  m.n_vertices, m.n_faces) > 0);
  ASSERT(strncmp(head, expect, strlen(expect)) == 0);
  ASSERT_EQ(len, strlen(expect) + 15 * m.n_vertices + 13 * m.n_faces);
  fg_ply back;
  ASSERT_OK(fg_ply_decode(buf, len, &back));
  ASSERT_EQ(back.n_vertices, m.n_vertices);
  ASSERT_EQ(back.n_faces, m.n_faces);
  ASSERT(back.has_faces);
  ASSERT(memcmp(back.xyz, m.p_world, m.n_vertices * 3 * sizeof(float)) == 0);
  ASSERT(memcmp(back.rgb, m.rgb, m.n_vertices * 3) == 0);
  ASSERT(memcmp(back.faces, m.faces, m.n_faces * 3 * sizeof(uint32_t)) == 0);
  fg_ply_release(&back);

  /* Malformed files are refused with a reason. */
  ASSERT_ERR(fg_ply_decode(buf, len - 1, &back), FG_EFORMAT, "bytes follow");
  ASSERT_ERR(fg_ply_decode(buf, 100, &back), FG_EFORMAT, "end_header");
  uint8_t *mod = malloc(len);
  memcpy(mod, buf, len);
  memcpy(strstr((char *)mod, "binary_little_endian"), "binary_big_endian___", 20);
  ASSERT_ERR(fg_ply_decode(mod, len, &back), FG_EFORMAT, "binary_little_endian");
  memcpy(mod, buf, len);
  const size_t faces_at = len - 13 * m.n_faces;
  mod[faces_at] = 4;
  ASSERT_ERR(fg_ply_decode(mod, len, &back), FG_EFORMAT, "triangles");
  memcpy(mod, buf, len);
  memset(mod + faces_at + 1, 0xff, 4); /* index -1 */
  ASSERT_ERR(fg_ply_decode(mod, len, &back), FG_EFORMAT, "names vertex");
  memcpy(mod, buf, len);
  memcpy(strstr((char *)mod, "property float y"), "property float q", 16);
  ASSERT_ERR(fg_ply_decode(mod, len, &back), FG_EFORMAT, "float x");
  memcpy(mod, buf, len);
  mod[0] = 'q';
  ASSERT_ERR(fg_ply_decode(mod, len, &back), FG_EFORMAT, "not a PLY");
  free(mod);
  free(buf);
  free(head);
  free(expect);

  /* Points without colours: no face element, read back as points. */
  ASSERT_OK(fg_mesh_encode_ply(&pts, NULL, &buf, &len));
  ASSERT(memmem(buf, len, "element face", 12) == NULL);
  ASSERT(memmem(buf, len, "property uchar red", 18) == NULL);
  ASSERT_OK(fg_ply_decode(buf, len, &back));
  ASSERT(!back.has_faces);
  ASSERT(back.rgb == NULL);
  ASSERT_EQ(back.n_vertices, pts.n_vertices);
  ASSERT(memcmp(back.xyz, pts.p_world, pts.n_vertices * 3 * sizeof(float)) == 0);
  fg_ply_release(&back);
  free(buf);
  /* A face naming a vertex that does not exist is not written. */
  m.faces[4] = (uint32_t)m.n_vertices;
  ASSERT_ERR(fg_mesh_encode_ply(&m, NULL, &buf, &len), FG_EINVAL, "names vertex");

  fg_mesh_release(&pts);
  fg_mesh_release(&m);
  free(alpha);
}

int main(void) {
  test_random();
  test_full_box();
  test_ambiguous_face();
  test_sphere();
  printf("geometry unit: ok\n");
  return 0;
}
