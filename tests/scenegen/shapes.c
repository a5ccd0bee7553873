/* Ray casting and inside tests for the scene generator's solids (shapes.h).
 *
 * Every solid is a convex set A minus at most one convex set B (the mug's cavity, the bowl's
 * hollow), plus, for the mug, a clipped torus. A ray meets a convex set in one span
 * [t0, t1] with the outward normals at both ends; the first entry into A \ B follows from the
 * two spans. The torus has no closed form worth its numerical trouble: its handle is found
 * by sphere tracing its exact signed distance inside the handle's bounding box. */
#include "shapes.h"

#include <math.h>
#include <string.h>

/* ---------------------------------------------------------------- small vector helpers */

static double dot3(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void set3(double out[3], double x, double y, double z) {
  out[0] = x;
  out[1] = y;
  out[2] = z;
}

void sg_xform_point(const double T[16], const double p[3], double out[3]) {
  for (int i = 0; i < 3; i++)
    out[i] = T[4 * i] * p[0] + T[4 * i + 1] * p[1] + T[4 * i + 2] * p[2] + T[4 * i + 3];
}

void sg_xform_dir(const double T[16], const double d[3], double out[3]) {
  for (int i = 0; i < 3; i++) out[i] = T[4 * i] * d[0] + T[4 * i + 1] * d[1] + T[4 * i + 2] * d[2];
}

const char *sg_shape_type_name(sg_shape_type t) {
  switch (t) {
  case SG_SHAPE_MUG: return "mug";
  case SG_SHAPE_BOWL: return "bowl";
  case SG_SHAPE_BOX: return "box";
  case SG_SHAPE_BALL: return "ball";
  }
  return "unknown";
}

void sg_shape_finish(sg_shape *s) {
  const double *T = s->T_world_obj;
  double *I = s->T_obj_world;
  memset(I, 0, 16 * sizeof(double));
  /* Rigid inverse: R^T and -R^T t. */
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) I[4 * i + j] = T[4 * j + i];
    I[4 * i + 3] = -(T[i] * T[3] + T[4 + i] * T[7] + T[8 + i] * T[11]);
  }
  I[15] = 1;
  double lo[3], hi[3], c[3], r2 = 0;
  sg_shape_local_bounds(s, lo, hi);
  for (int i = 0; i < 3; i++) {
    c[i] = (lo[i] + hi[i]) / 2;
    r2 += (hi[i] - lo[i]) * (hi[i] - lo[i]) / 4;
  }
  sg_xform_point(T, c, s->bound_center_world);
  /* A hair larger, so rounding never culls a grazing hit. */
  s->bound_radius = sqrt(r2) * (1 + 1e-9) + 1e-9;
}

/* ---------------------------------------------------------------- spans */

/* The part of a ray inside a convex set: [t0, t1] with outward normals n0 at entry and n1 at
 * exit (object frame). Empty when t0 > t1. */
typedef struct span {
  double t0, t1;
  double n0[3], n1[3];
} span;

static span span_all(void) {
  span s = {.t0 = -INFINITY, .t1 = INFINITY};
  return s;
}

static span span_empty(void) {
  span s = {.t0 = INFINITY, .t1 = -INFINITY};
  return s;
}

static int span_is_empty(const span *s) { return !(s->t0 <= s->t1); }

static span span_and(span a, span b) {
  if (span_is_empty(&a) || span_is_empty(&b)) return span_empty();
  span r = a;
  if (b.t0 > a.t0) {
    r.t0 = b.t0;
    memcpy(r.n0, b.n0, sizeof r.n0);
  }
  if (b.t1 < a.t1) {
    r.t1 = b.t1;
    memcpy(r.n1, b.n1, sizeof r.n1);
  }
  if (span_is_empty(&r)) return span_empty();
  return r;
}

/* lo <= o[k] + t d[k] <= hi. */
static span span_slab(const double o[3], const double d[3], int k, double lo, double hi) {
  if (fabs(d[k]) < 1e-300) return (o[k] >= lo && o[k] <= hi) ? span_all() : span_empty();
  span s = {0};
  double ta = (lo - o[k]) / d[k], tb = (hi - o[k]) / d[k];
  if (ta < tb) {
    s.t0 = ta, s.t1 = tb;
    s.n0[k] = -1, s.n1[k] = 1;
  } else {
    s.t0 = tb, s.t1 = ta;
    s.n0[k] = 1, s.n1[k] = -1;
  }
  return s;
}

static span span_box(const double o[3], const double d[3], const double lo[3],
                     const double hi[3]) {
  span s = span_slab(o, d, 0, lo[0], hi[0]);
  s = span_and(s, span_slab(o, d, 1, lo[1], hi[1]));
  return span_and(s, span_slab(o, d, 2, lo[2], hi[2]));
}

/* x^2 + y^2 <= R^2 (infinite along z). */
static span span_cylinder_z(const double o[3], const double d[3], double R) {
  double a = d[0] * d[0] + d[1] * d[1];
  double b = o[0] * d[0] + o[1] * d[1];
  double c = o[0] * o[0] + o[1] * o[1] - R * R;
  if (a < 1e-24) return c <= 0 ? span_all() : span_empty();
  double disc = b * b - a * c;
  if (disc < 0) return span_empty();
  double sq = sqrt(disc);
  span s;
  s.t0 = (-b - sq) / a;
  s.t1 = (-b + sq) / a;
  set3(s.n0, (o[0] + s.t0 * d[0]) / R, (o[1] + s.t0 * d[1]) / R, 0);
  set3(s.n1, (o[0] + s.t1 * d[0]) / R, (o[1] + s.t1 * d[1]) / R, 0);
  return s;
}

/* |p - c| <= R, d unit. */
static span span_sphere(const double o[3], const double d[3], const double c[3], double R) {
  double oc[3] = {o[0] - c[0], o[1] - c[1], o[2] - c[2]};
  double b = dot3(oc, d);
  double disc = b * b - (dot3(oc, oc) - R * R);
  if (disc < 0) return span_empty();
  double sq = sqrt(disc);
  span s;
  s.t0 = -b - sq;
  s.t1 = -b + sq;
  for (int i = 0; i < 3; i++) {
    s.n0[i] = (oc[i] + s.t0 * d[i]) / R;
    s.n1[i] = (oc[i] + s.t1 * d[i]) / R;
  }
  return s;
}

/* The first entry into A \ B within (t_min, t_max). The difference splits A's span into the
 * part before B and the part after it; the second part is entered through B's exit, where
 * the solid's outward normal is the opposite of B's. */
static int diff_first_hit(const span *A, const span *B, double t_min, double t_max, double *t,
                          double n[3]) {
  if (span_is_empty(A)) return 0;
  if (span_is_empty(B) || B->t0 >= A->t1 || B->t1 <= A->t0) {
    if (A->t0 > t_min && A->t0 < t_max) {
      *t = A->t0;
      memcpy(n, A->n0, 3 * sizeof(double));
      return 1;
    }
    return 0;
  }
  /* Before B: [A.t0, B.t0], non-empty when B starts after A. */
  if (B->t0 > A->t0 && A->t0 > t_min && A->t0 < t_max) {
    *t = A->t0;
    memcpy(n, A->n0, 3 * sizeof(double));
    return 1;
  }
  /* After B: [B.t1, A.t1]. */
  if (B->t1 < A->t1 && B->t1 > t_min && B->t1 < t_max) {
    *t = B->t1;
    set3(n, -B->n1[0], -B->n1[1], -B->n1[2]);
    return 1;
  }
  return 0;
}

/* ---------------------------------------------------------------- the mug's handle */

double sg_mug_handle_sdf(const sg_shape *s, const double p[3]) {
  const double *c = s->handle_center;
  double qx = p[0] - c[0], qz = p[2] - c[2];
  double ring = sqrt(qx * qx + qz * qz) - s->handle_major;
  double dy = p[1] - c[1];
  return sqrt(ring * ring + dy * dy) - s->handle_minor;
}

/* Distance bound of the handle solid: torus intersected with r >= clip radius. Both terms are
 * exact distances, so their maximum never overshoots the surface. */
static double handle_solid_sdf(const sg_shape *s, const double p[3], int *torus_active) {
  double torus = sg_mug_handle_sdf(s, p);
  double clip = s->handle_clip_radius - sqrt(p[0] * p[0] + p[1] * p[1]);
  *torus_active = torus >= clip;
  return torus >= clip ? torus : clip;
}

static void handle_box(const sg_shape *s, double lo[3], double hi[3]) {
  const double *c = s->handle_center;
  double ext = s->handle_major + s->handle_minor;
  set3(lo, c[0] - ext, c[1] - s->handle_minor, c[2] - ext);
  set3(hi, c[0] + ext, c[1] + s->handle_minor, c[2] + ext);
}

static int handle_hit(const sg_shape *s, const double o[3], const double d[3], double t_min,
                      double t_max, double *t_out, double n[3]) {
  double lo[3], hi[3];
  handle_box(s, lo, hi);
  /* Pad the box so the march starts a little outside the surface. */
  for (int i = 0; i < 3; i++) lo[i] -= 1e-4, hi[i] += 1e-4;
  span b = span_box(o, d, lo, hi);
  if (span_is_empty(&b)) return 0;
  double t = b.t0 > t_min ? b.t0 : t_min;
  double t_end = b.t1 < t_max ? b.t1 : t_max;
  for (int it = 0; it < 256 && t <= t_end; it++) {
    double p[3] = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
    int torus_active;
    double dist = handle_solid_sdf(s, p, &torus_active);
    if (dist < 1e-7) {
      if (torus_active) {
        const double *c = s->handle_center;
        double qx = p[0] - c[0], qz = p[2] - c[2];
        double q = sqrt(qx * qx + qz * qz);
        double ring[3] = {c[0] + s->handle_major * qx / q, c[1], c[2] + s->handle_major * qz / q};
        double v[3] = {p[0] - ring[0], p[1] - ring[1], p[2] - ring[2]};
        double len = sqrt(dot3(v, v));
        set3(n, v[0] / len, v[1] / len, v[2] / len);
      } else {
        double r = sqrt(p[0] * p[0] + p[1] * p[1]);
        set3(n, -p[0] / r, -p[1] / r, 0);
      }
      *t_out = t;
      return 1;
    }
    t += dist;
  }
  return 0;
}

/* ---------------------------------------------------------------- intersection */

static int local_hit(const sg_shape *s, const double o[3], const double d[3], double t_min,
                     double t_max, double *t, double n[3]) {
  switch (s->type) {
  case SG_SHAPE_MUG: {
    double h2 = s->height / 2;
    span A = span_and(span_cylinder_z(o, d, s->outer_radius), span_slab(o, d, 2, -h2, h2));
    /* The cavity reaches above the rim so that the mug is open at the top. */
    span B = span_and(span_cylinder_z(o, d, s->inner_radius),
                      span_slab(o, d, 2, -h2 + s->bottom, h2 + 1.0));
    double tb, nb[3], th, nh[3];
    int body = diff_first_hit(&A, &B, t_min, t_max, &tb, nb);
    int handle = handle_hit(s, o, d, t_min, body ? tb : t_max, &th, nh);
    if (handle) {
      *t = th;
      memcpy(n, nh, sizeof nh);
      return 1;
    }
    if (body) {
      *t = tb;
      memcpy(n, nb, sizeof nb);
      return 1;
    }
    return 0;
  }
  case SG_SHAPE_BOWL: {
    double h2 = s->height / 2;
    double c[3] = {0, 0, s->sphere_center_z};
    span A = span_and(span_sphere(o, d, c, s->outer_radius), span_slab(o, d, 2, -h2, h2));
    span B = span_sphere(o, d, c, s->inner_radius);
    return diff_first_hit(&A, &B, t_min, t_max, t, n);
  }
  case SG_SHAPE_BOX: {
    double lo[3] = {-s->size[0] / 2, -s->size[1] / 2, -s->size[2] / 2};
    double hi[3] = {s->size[0] / 2, s->size[1] / 2, s->size[2] / 2};
    span A = span_box(o, d, lo, hi);
    span B = span_empty();
    return diff_first_hit(&A, &B, t_min, t_max, t, n);
  }
  case SG_SHAPE_BALL: {
    double c[3] = {0, 0, 0};
    span A = span_sphere(o, d, c, s->radius);
    span B = span_empty();
    return diff_first_hit(&A, &B, t_min, t_max, t, n);
  }
  }
  return 0;
}

int sg_shape_intersect(const sg_shape *s, const double o_world[3], const double d_world[3],
                       double t_min, double t_max, sg_hit *hit) {
  /* Most rays miss most objects: the bounding sphere culls them cheaply. */
  const double *bc = s->bound_center_world;
  double oc[3] = {o_world[0] - bc[0], o_world[1] - bc[1], o_world[2] - bc[2]};
  double b = dot3(oc, d_world), disc = b * b - (dot3(oc, oc) - s->bound_radius * s->bound_radius);
  if (disc < 0) return 0;
  double sq = sqrt(disc);
  if (-b - sq >= t_max || -b + sq <= t_min) return 0;
  /* A rigid transform keeps the direction unit and t in metres. */
  double o[3], d[3], n[3], t;
  sg_xform_point(s->T_obj_world, o_world, o);
  sg_xform_dir(s->T_obj_world, d_world, d);
  if (!local_hit(s, o, d, t_min, t_max, &t, n)) return 0;
  hit->t = t;
  sg_xform_dir(s->T_world_obj, n, hit->n_world);
  return 1;
}

/* ---------------------------------------------------------------- inside tests */

int sg_shape_inside(const sg_shape *s, const double p_world[3]) {
  double p[3];
  sg_xform_point(s->T_obj_world, p_world, p);
  double r2 = p[0] * p[0] + p[1] * p[1];
  switch (s->type) {
  case SG_SHAPE_MUG: {
    double h2 = s->height / 2;
    int body = r2 <= s->outer_radius * s->outer_radius && fabs(p[2]) <= h2;
    int cavity = r2 < s->inner_radius * s->inner_radius && p[2] > -h2 + s->bottom;
    if (body && !cavity) return 1;
    return sg_mug_handle_sdf(s, p) <= 0 && r2 >= s->handle_clip_radius * s->handle_clip_radius;
  }
  case SG_SHAPE_BOWL: {
    double h2 = s->height / 2;
    double dz = p[2] - s->sphere_center_z;
    double q2 = r2 + dz * dz;
    return fabs(p[2]) <= h2 && q2 <= s->outer_radius * s->outer_radius &&
           q2 >= s->inner_radius * s->inner_radius;
  }
  case SG_SHAPE_BOX:
    return fabs(p[0]) <= s->size[0] / 2 && fabs(p[1]) <= s->size[1] / 2 &&
           fabs(p[2]) <= s->size[2] / 2;
  case SG_SHAPE_BALL: return r2 + p[2] * p[2] <= s->radius * s->radius;
  }
  return 0;
}

/* ---------------------------------------------------------------- bounds */

void sg_shape_local_bounds(const sg_shape *s, double lo[3], double hi[3]) {
  switch (s->type) {
  case SG_SHAPE_MUG: {
    double R = s->outer_radius;
    set3(lo, -R, -R, -s->height / 2);
    set3(hi, s->handle_center[0] + s->handle_major + s->handle_minor, R, s->height / 2);
    return;
  }
  case SG_SHAPE_BOWL: {
    double R = s->outer_radius;
    set3(lo, -R, -R, -s->height / 2);
    set3(hi, R, R, s->height / 2);
    return;
  }
  case SG_SHAPE_BOX:
    for (int i = 0; i < 3; i++) lo[i] = -s->size[i] / 2, hi[i] = s->size[i] / 2;
    return;
  case SG_SHAPE_BALL:
    for (int i = 0; i < 3; i++) lo[i] = -s->radius, hi[i] = s->radius;
    return;
  }
}

static void aabb_add_box(const double T[16], const double lo[3], const double hi[3],
                         double mn[3], double mx[3]) {
  for (int c = 0; c < 8; c++) {
    double p[3] = {(c & 1) ? hi[0] : lo[0], (c & 2) ? hi[1] : lo[1], (c & 4) ? hi[2] : lo[2]};
    double q[3];
    sg_xform_point(T, p, q);
    for (int i = 0; i < 3; i++) {
      if (q[i] < mn[i]) mn[i] = q[i];
      if (q[i] > mx[i]) mx[i] = q[i];
    }
  }
}

void sg_shape_world_aabb(const sg_shape *s, double mn[3], double mx[3]) {
  const double *T = s->T_world_obj;
  for (int i = 0; i < 3; i++) mn[i] = INFINITY, mx[i] = -INFINITY;
  if (s->type == SG_SHAPE_BOX) {
    double lo[3], hi[3];
    sg_shape_local_bounds(s, lo, hi);
    aabb_add_box(T, lo, hi, mn, mx);
    return;
  }
  /* Bodies of revolution about the object's z axis, which stays vertical in the world. */
  double R = s->type == SG_SHAPE_BALL ? s->radius : s->outer_radius;
  double h2 = s->type == SG_SHAPE_BALL ? s->radius : s->height / 2;
  set3(mn, T[3] - R, T[7] - R, T[11] - h2);
  set3(mx, T[3] + R, T[7] + R, T[11] + h2);
  if (s->type == SG_SHAPE_MUG) {
    double lo[3], hi[3];
    handle_box(s, lo, hi);
    aabb_add_box(T, lo, hi, mn, mx);
  }
}
