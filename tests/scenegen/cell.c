/* The MJCF cell of a fieldgrip-scenegen layout (cell.h): convex parts per object, their
 * mass properties, and the XML text. */
#include "cell.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/pose.h"

/* ---------------------------------------------------------------- materials */

/* Everyday objects of these sizes: a ceramic mug (0.30 kg) and bowl (0.25 kg), a filled
 * cardboard box (0.15 kg), a hollow rubber ball (0.05 kg, a tennis ball's weight). */
static const sg_cell_material materials[] = {
    [SG_SHAPE_MUG] = {"ceramic", 0.30, 0.6},
    [SG_SHAPE_BOWL] = {"ceramic", 0.25, 0.6},
    [SG_SHAPE_BOX] = {"cardboard", 0.15, 0.5},
    [SG_SHAPE_BALL] = {"rubber", 0.05, 0.9},
};

const sg_cell_material *sg_cell_material_of(sg_shape_type t) {
  if ((unsigned)t >= sizeof materials / sizeof materials[0]) t = SG_SHAPE_BOX;
  return &materials[t];
}

/* ---------------------------------------------------------------- parts */

/* How finely the curved solids are cut. 24 wall boxes keep the mug's polygons within 0.2 mm
 * of its circles; 10 handle capsules leave their chords 0.3 mm inside the arc; bowl bands of
 * at most 12 degrees with up to 24 segments keep the boxes' faces within 0.5 mm of the
 * spheres. */
enum {
  MUG_WALL_BOXES = 24,
  MUG_HANDLE_CAPSULES = 10,
  BOWL_SEGMENTS_MAX = 24,
  BOWL_SEGMENTS_MIN = 6,
  MAX_PARTS = 256,
};
#define BOWL_BAND_MAX_RAD (12.0 * M_PI / 180)
/* The bowl's shell boxes start this far from the bottom pole; below it the foot's top, flat
 * at the inner sphere's lowest point, is within 0.3 mm of the sphere. */
#define BOWL_LINER_START_RAD (5.0 * M_PI / 180)
/* Grid of the mass integration (metres). */
#define INERTIA_GRID_M 0.001

typedef enum part_type { PART_BOX, PART_CYLINDER, PART_CAPSULE, PART_SPHERE } part_type;

static const char *const part_type_names[] = {"box", "cylinder", "capsule", "sphere"};

typedef struct part {
  part_type type;
  char name[32];      /* the geom is "<object>/<name>" */
  double pos_obj[3];  /* centre, object frame, metres */
  double quat_obj[4]; /* w, x, y, z: the part's axes in the object frame */
  double size[3];     /* MuJoCo's: box half edges; cylinder and capsule radius, half length
                       * along the part's z; sphere radius (unused entries 0) */
} part;

typedef struct part_list {
  part *p; /* (cap) */
  int n, cap;
} part_list;

/* A new zeroed part with an identity rotation, or NULL when the list is full. */
static part *part_add(part_list *l, part_type type, const char *name) {
  if (l->n >= l->cap) return NULL;
  part *p = &l->p[l->n++];
  memset(p, 0, sizeof *p);
  p->type = type;
  snprintf(p->name, sizeof p->name, "%s", name);
  p->quat_obj[0] = 1;
  return p;
}

/* Appends a part named by a printf format, or returns FG_ERANGE from the caller. */
#define PART_ADD(var, list, type, ...)                                                   \
  do {                                                                                   \
    char part_name_[32];                                                                 \
    snprintf(part_name_, sizeof part_name_, __VA_ARGS__);                                \
    (var) = part_add((list), (type), part_name_);                                        \
    if (!(var)) return fg_fail(FG_ERANGE, "more than %d parts in an object", MAX_PARTS); \
  } while (0)

static void set3(double v[3], double x, double y, double z) {
  v[0] = x, v[1] = y, v[2] = z;
}

static double dot3(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The rotation whose columns are the part's x, y and z axes (object frame), as w, x, y, z. */
static void quat_from_axes(const double x[3], const double y[3], const double z[3],
                           double q[4]) {
  const double T[16] = {x[0], y[0], z[0], 0, x[1], y[1], z[1], 0,
                        x[2], y[2], z[2], 0, 0,    0,    0,    1};
  double p[3];
  fg_pose_to_quat(T, p, q);
}

/* A yaw about the object's z axis. */
static void quat_yaw(double yaw_rad, double q[4]) {
  q[0] = cos(yaw_rad / 2), q[1] = 0, q[2] = 0, q[3] = sin(yaw_rad / 2);
}

/* Distance from the centre of a plane that cuts a circle (or sphere) of radius R so that the
 * plane's points up to angle theta from its nearest one, cos_theta given, stray from the
 * circle as far outside at that angle as inside at the nearest point: R (1 - c) / (1 + c). */
static double secant_distance(double R, double cos_theta) {
  return 2 * R * cos_theta / (1 + cos_theta);
}

/* A flat round bottom from z0 up to z1 of radius R: the cylinder that shapes it and the box
 * inscribed in it that lets it stand (cell.h). */
static int add_bottom(part_list *l, const char *cyl_name, double R, double z0, double z1) {
  part *p;
  PART_ADD(p, l, PART_CYLINDER, "%s", cyl_name);
  set3(p->pos_obj, 0, 0, (z0 + z1) / 2);
  set3(p->size, R, (z1 - z0) / 2, 0);
  PART_ADD(p, l, PART_BOX, "%s_box", cyl_name);
  set3(p->pos_obj, 0, 0, (z0 + z1) / 2);
  /* A hair inside the cylinder, so that it never shows. */
  double half = R * M_SQRT1_2 * (1 - 1e-3);
  set3(p->size, half, half, (z1 - z0) / 2);
  return 0;
}

/* The mug (shapes.h): floor, wall ring, handle. */
static int mug_parts(const sg_shape *s, part_list *l) {
  const double h2 = s->height / 2, z_floor = -h2 + s->bottom;
  const double R = s->outer_radius, r = s->inner_radius;
  FG_TRY(add_bottom(l, "bottom", R, -h2, z_floor));
  /* Box i spans the ring radially and, tangentially, its sector at its outer face: the outer
   * corners of neighbours meet, so the outer surface has no gap. Each face lies on a secant
   * of its circle, straying as far inside it at the middle as outside at the corners. */
  const double half_angle = M_PI / MUG_WALL_BOXES;
  const double t_out = secant_distance(R, cos(half_angle));
  const double t_in = secant_distance(r, cos(half_angle));
  for (int i = 0; i < MUG_WALL_BOXES; i++) {
    part *p;
    PART_ADD(p, l, PART_BOX, "wall%02d", i);
    double yaw = 2 * M_PI * i / MUG_WALL_BOXES, rc = (t_in + t_out) / 2;
    set3(p->pos_obj, rc * cos(yaw), rc * sin(yaw), (z_floor + h2) / 2);
    quat_yaw(yaw, p->quat_obj);
    set3(p->size, (t_out - t_in) / 2, t_out * tan(half_angle), (h2 - z_floor) / 2);
  }
  /* The handle is the union of balls of radius handle_minor centred on its ring (x-z plane):
   * capsules along chords of the ring stay inside it. The arc runs from its lowest to its
   * highest point through the outermost one, and stops where a cap would reach into the
   * cavity (r < inner_radius); beyond that the tube is inside the wall. */
  const double *c = s->handle_center;
  const double Rm = s->handle_major, rt = s->handle_minor;
  double cos_end = (r + rt - c[0]) / Rm;
  if (cos_end >= 1) return 0;
  double phi_end = acos(cos_end < -1 ? -1 : cos_end);
  for (int k = 0; k < MUG_HANDLE_CAPSULES; k++) {
    double f0 = -phi_end + 2 * phi_end * k / MUG_HANDLE_CAPSULES;
    double f1 = -phi_end + 2 * phi_end * (k + 1) / MUG_HANDLE_CAPSULES;
    double a[3] = {c[0] + Rm * cos(f0), c[1], c[2] + Rm * sin(f0)};
    double b[3] = {c[0] + Rm * cos(f1), c[1], c[2] + Rm * sin(f1)};
    double u[3] = {b[0] - a[0], 0, b[2] - a[2]};
    double len = sqrt(dot3(u, u));
    part *p;
    PART_ADD(p, l, PART_CAPSULE, "handle%02d", k);
    set3(p->pos_obj, (a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2);
    /* A turn about y takes the capsule's z axis onto the chord. */
    double theta = atan2(u[0], u[2]);
    p->quat_obj[0] = cos(theta / 2), p->quat_obj[2] = sin(theta / 2);
    set3(p->size, rt, len / 2, 0);
  }
  return 0;
}

/* Unit direction from the bowl's sphere centre at polar angle a (from straight down) and
 * azimuth b. */
static void sphere_dir(double a, double b, double d[3]) {
  set3(d, sin(a) * cos(b), sin(a) * sin(b), -cos(a));
}

/* The box for the shell patch a0..a1 (polar) x b0..b1 (azimuth), lowest point not below
 * z_min (object frame). Its axes: x along the azimuth, y towards the rim, z outwards (n, the
 * patch centre's direction). Its inner and outer faces lie on planes normal to n that cut the
 * inner and the outer sphere (secant_distance over the patch's widest angle), so that they
 * stray as far inside the spheres as outside; no point of it enters the hollow by more. Its
 * extent covers the patch's central projection onto the outer plane (sampled along the
 * patch's edges), so that neighbouring boxes close the outer surface. Near the foot the outer
 * face moves in until the lowest corner clears z_min. */
static int shell_box(const sg_shape *s, double a0, double a1, double b0, double b1,
                     double z_min, part *p) {
  const double R = s->outer_radius, r = s->inner_radius, cz = s->sphere_center_z;
  const double ac = (a0 + a1) / 2, bc = (b0 + b1) / 2;
  double n[3], e1[3] = {-sin(bc), cos(bc), 0}, e2[3] = {cos(ac) * cos(bc), cos(ac) * sin(bc),
                                                       sin(ac)};
  sphere_dir(ac, bc, n);
  enum { EDGE_SAMPLES = 16, SAMPLES = 4 * (EDGE_SAMPLES + 1) };
  double d[SAMPLES][3], cos_max = 1;
  for (int edge = 0, i = 0; edge < 4; edge++)
    for (int k = 0; k <= EDGE_SAMPLES; k++, i++) {
      double f = (double)k / EDGE_SAMPLES, a, b;
      switch (edge) {
      case 0: a = a0, b = b0 + f * (b1 - b0); break;
      case 1: a = a1, b = b0 + f * (b1 - b0); break;
      case 2: a = a0 + f * (a1 - a0), b = b0; break;
      default: a = a0 + f * (a1 - a0), b = b1; break;
      }
      sphere_dir(a, b, d[i]);
      if (dot3(d[i], n) < cos_max) cos_max = dot3(d[i], n);
    }
  double t_in = secant_distance(r, cos_max), t_out = secant_distance(R, cos_max);
  double half1 = 0, lo2 = INFINITY, hi2 = -INFINITY;
  for (int i = 0; i < SAMPLES; i++) {
    double dn = dot3(d[i], n), g1 = t_out * dot3(d[i], e1) / dn, g2 = t_out * dot3(d[i], e2) / dn;
    if (fabs(g1) > half1) half1 = fabs(g1);
    if (g2 < lo2) lo2 = g2;
    if (g2 > hi2) hi2 = g2;
  }
  /* Overlap neighbours by 10 micrometres, so rounding leaves no crack. */
  const double overlap = 1e-5;
  half1 += overlap, lo2 -= overlap, hi2 += overlap;
  /* e1 is horizontal, e2 rises and n falls: the lowest corner is outer, on the low edge. */
  double z_low = cz - t_out * cos(ac) + lo2 * sin(ac);
  if (z_low < z_min) t_out = (cz + lo2 * sin(ac) - z_min) / cos(ac);
  if (t_out - t_in < 0.001)
    return fg_fail(FG_ERANGE, "the bowl's shell is too thin near its foot for a part");
  double tc = (t_in + t_out) / 2, uc = (lo2 + hi2) / 2;
  for (int i = 0; i < 3; i++) p->pos_obj[i] = tc * n[i] + uc * e2[i];
  p->pos_obj[2] += cz;
  quat_from_axes(e1, e2, n, p->quat_obj);
  set3(p->size, half1, (hi2 - lo2) / 2, (t_out - t_in) / 2);
  return 0;
}

/* The bowl (shapes.h): the foot, then bands of boxes from near the bottom pole to the rim. */
static int bowl_parts(const sg_shape *s, part_list *l) {
  const double h2 = s->height / 2, cz = s->sphere_center_z;
  const double R = s->outer_radius, r = s->inner_radius;
  const double drop = cz + h2; /* the sphere centre above the foot plane */
  if (drop <= r || drop >= R)
    return fg_fail(FG_ERANGE, "the bowl's bottom cut misses its shell");
  /* The flat foot: up to the hollow's lowest point, exactly the solid's there. */
  FG_TRY(add_bottom(l, "foot", sqrt(R * R - drop * drop), -h2, cz - r));
  const double z_min = -h2 + SG_CELL_CLEARANCE_M;
  const double a_foot = acos(drop / R);
  double c_rim = (cz - h2) / R;
  const double a_rim = acos(c_rim < -1 ? -1 : c_rim > 1 ? 1 : c_rim);
  /* Bands: a liner over the floor's inside up to where the foot ends (the foot's flat top
   * would be too low there), then equal bands up to the rim. */
  double edges[16];
  int n_edges = 0;
  if (a_foot > BOWL_LINER_START_RAD + 0.01) edges[n_edges++] = BOWL_LINER_START_RAD;
  edges[n_edges++] = a_foot;
  int n_bands = (int)ceil((a_rim - a_foot) / BOWL_BAND_MAX_RAD - 1e-9);
  if (n_bands < 1 || n_bands > 12) return fg_fail(FG_ERANGE, "the bowl's rim is out of range");
  for (int k = 1; k <= n_bands; k++) edges[n_edges++] = a_foot + (a_rim - a_foot) * k / n_bands;
  for (int band = 0; band + 1 < n_edges; band++) {
    double a0 = edges[band], a1 = edges[band + 1];
    int segs = (int)ceil(BOWL_SEGMENTS_MAX * sin(a1) - 1e-9);
    if (segs < BOWL_SEGMENTS_MIN) segs = BOWL_SEGMENTS_MIN;
    for (int j = 0; j < segs; j++) {
      part *p;
      PART_ADD(p, l, PART_BOX, "shell_%02d_%02d", band, j);
      double b0 = 2 * M_PI * (j - 0.5) / segs, b1 = 2 * M_PI * (j + 0.5) / segs;
      FG_TRY(shell_box(s, a0, a1, b0, b1, z_min, p));
    }
  }
  return 0;
}

static int object_parts(const sg_shape *s, part_list *l) {
  part *p;
  switch (s->type) {
  case SG_SHAPE_MUG: return mug_parts(s, l);
  case SG_SHAPE_BOWL: return bowl_parts(s, l);
  case SG_SHAPE_BOX:
    PART_ADD(p, l, PART_BOX, "solid");
    set3(p->size, s->size[0] / 2, s->size[1] / 2, s->size[2] / 2);
    return 0;
  case SG_SHAPE_BALL:
    PART_ADD(p, l, PART_SPHERE, "solid");
    p->size[0] = s->radius;
    return 0;
  }
  return fg_fail(FG_EINVAL, "unknown shape type %d", (int)s->type);
}

/* ---------------------------------------------------------------- mass properties */

/* Centre of mass (object frame) and inertia about it (object axes: Ixx, Iyy, Izz, Ixy, Ixz,
 * Iyz, as MJCF's fullinertia) of the analytic solid with mass_kg spread uniformly over it:
 * sums over the centres of a grid of about INERTIA_GRID_M cells in the solid's bounds, in a
 * fixed order. */
static void solid_inertia(const sg_shape *s, double mass_kg, double com[3], double I[6]) {
  double lo[3], hi[3], step[3];
  int n[3];
  sg_shape_local_bounds(s, lo, hi);
  for (int i = 0; i < 3; i++) {
    n[i] = (int)ceil((hi[i] - lo[i]) / INERTIA_GRID_M);
    if (n[i] < 1) n[i] = 1;
    step[i] = (hi[i] - lo[i]) / n[i];
  }
  /* Offsets from the bounds' centre keep the second moments free of cancellation. */
  double mid[3] = {(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2};
  double count = 0, s1[3] = {0, 0, 0}, s2[6] = {0, 0, 0, 0, 0, 0}; /* xx yy zz xy xz yz */
  for (int iz = 0; iz < n[2]; iz++)
    for (int iy = 0; iy < n[1]; iy++)
      for (int ix = 0; ix < n[0]; ix++) {
        double p[3] = {lo[0] + (ix + 0.5) * step[0], lo[1] + (iy + 0.5) * step[1],
                       lo[2] + (iz + 0.5) * step[2]};
        double pw[3];
        sg_xform_point(s->T_world_obj, p, pw);
        if (!sg_shape_inside(s, pw)) continue;
        double q[3] = {p[0] - mid[0], p[1] - mid[1], p[2] - mid[2]};
        count += 1;
        for (int i = 0; i < 3; i++) s1[i] += q[i];
        s2[0] += q[0] * q[0], s2[1] += q[1] * q[1], s2[2] += q[2] * q[2];
        s2[3] += q[0] * q[1], s2[4] += q[0] * q[2], s2[5] += q[1] * q[2];
      }
  double m[3], c[6];
  for (int i = 0; i < 3; i++) m[i] = s1[i] / count;
  c[0] = s2[0] / count - m[0] * m[0], c[1] = s2[1] / count - m[1] * m[1];
  c[2] = s2[2] / count - m[2] * m[2], c[3] = s2[3] / count - m[0] * m[1];
  c[4] = s2[4] / count - m[0] * m[2], c[5] = s2[5] / count - m[1] * m[2];
  for (int i = 0; i < 3; i++) com[i] = mid[i] + m[i];
  I[0] = mass_kg * (c[1] + c[2]);
  I[1] = mass_kg * (c[0] + c[2]);
  I[2] = mass_kg * (c[0] + c[1]);
  I[3] = -mass_kg * c[3], I[4] = -mass_kg * c[4], I[5] = -mass_kg * c[5];
  /* A symmetric solid's products of inertia are zero up to rounding: write them as zero. */
  double big = fmax(I[0], fmax(I[1], I[2]));
  for (int i = 3; i < 6; i++)
    if (fabs(I[i]) < 1e-6 * big) I[i] = 0;
}

/* ---------------------------------------------------------------- XML */

/* Rounding residue printed as 0.000000, never -0.000000. */
static double tidy(double v) { return fabs(v) < 5e-7 ? 0.0 : v; }

static void print3(FILE *f, const double v[3]) {
  fprintf(f, "%.6f %.6f %.6f", tidy(v[0]), tidy(v[1]), tidy(v[2]));
}

static void print_quat(FILE *f, const double q[4]) {
  fprintf(f, "%.6f %.6f %.6f %.6f", tidy(q[0]), tidy(q[1]), tidy(q[2]), tidy(q[3]));
}

static void print_part(FILE *f, const char *object, const part *p,
                       const sg_cell_material *mat, const double rgb[3]) {
  static const int n_size[] = {[PART_BOX] = 3, [PART_CYLINDER] = 2, [PART_CAPSULE] = 2,
                               [PART_SPHERE] = 1};
  fprintf(f, "      <geom name=\"%s/%s\" type=\"%s\" pos=\"", object, p->name,
          part_type_names[p->type]);
  print3(f, p->pos_obj);
  fputs("\" quat=\"", f);
  print_quat(f, p->quat_obj);
  fputs("\" size=\"", f);
  for (int i = 0; i < n_size[p->type]; i++) fprintf(f, i ? " %.6f" : "%.6f", p->size[i]);
  fprintf(f, "\" condim=\"4\" friction=\"%.2f 0.005 0.0001\" rgba=\"%.3f %.3f %.3f 1\"/>\n",
          mat->friction, rgb[0], rgb[1], rgb[2]);
}

static int print_object(FILE *f, const sg_object *ob, part_list *l) {
  const sg_shape *s = &ob->shape;
  const sg_cell_material *mat = sg_cell_material_of(s->type);
  l->n = 0;
  FG_TRY(object_parts(s, l));
  double p[3], q[4], com[3], I[6];
  fg_pose_to_quat(s->T_world_obj, p, q);
  solid_inertia(s, mat->mass_kg, com, I);
  fprintf(f, "    <body name=\"%s\" pos=\"", ob->name);
  print3(f, p);
  fputs("\" quat=\"", f);
  print_quat(f, q);
  fprintf(f, "\">\n      <freejoint name=\"%s\"/>\n      <inertial pos=\"", ob->name);
  print3(f, com);
  fprintf(f, "\" mass=\"%.6f\" fullinertia=\"%.6e %.6e %.6e %.6e %.6e %.6e\"/>\n", mat->mass_kg,
          I[0], I[1], I[2], I[3], I[4], I[5]);
  for (int i = 0; i < l->n; i++) print_part(f, ob->name, &l->p[i], mat, ob->albedo);
  fputs("    </body>\n", f);
  return 0;
}

/* Each class's feature vector (gt.json's embedding, without the views' noise) as a custom
 * numeric "feature:NAME", NAME the class: what a simulator's camera serves per patch for the
 * geoms named NAME or NAME/PART ("table", "mug/wall03"), and for rays that meet nothing
 * ("background"). */
static void print_features(FILE *f, const sg_scene *sc) {
  fputs("  <custom>\n", f);
  for (int c = 0; c < SG_N_CLASSES; c++) {
    fprintf(f, "    <numeric name=\"feature:%s\" data=\"", sg_class_names[c]);
    for (int k = 0; k < sc->cfg.dim; k++)
      fprintf(f, k ? " %.6f" : "%.6f", tidy(sc->embeddings[(size_t)c * sc->cfg.dim + k]));
    fputs("\"/>\n", f);
  }
  fputs("  </custom>\n", f);
}

static int print_cell(FILE *f, const sg_scene *sc, part_list *l) {
  fprintf(f, "<mujoco model=\"fieldgrip-scenegen seed %llu\">\n",
          (unsigned long long)sc->cfg.seed);
  fputs("  <!-- fieldgrip-scenegen's tabletop as a physics cell: the world frame of its\n"
        "       gt.json (metres, +z up, table top at z = 0), each object a body at its gt pose\n"
        "       holding convex parts in the object frame (origin at half its height).\n", f);
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    if (!sc->objects[k].present) continue;
    const sg_cell_material *m = sg_cell_material_of(sc->objects[k].shape.type);
    fprintf(f, "       %s: %s, %.2f kg, friction %.2f\n", sc->objects[k].name, m->what,
            m->mass_kg, m->friction);
  }
  fprintf(f, "       table: friction %.2f. No option element: the simulator sets its own. -->\n",
          SG_CELL_TABLE_FRICTION);
  fputs("  <compiler angle=\"radian\"/>\n  <worldbody>\n", f);
  /* The table's top as a plane over the slab: MuJoCo 2.2's box-box collider gives a box
   * resting face to face on a table box phantom contacts as deep as the table is wide now
   * and then (seeds 103 and 118 at load), which throw the box off; its plane colliders do
   * not. A plane is infinite for collisions and drawn over the slab. */
  double c[3], h[3];
  for (int i = 0; i < 2; i++) {
    c[i] = (sc->table_min[i] + sc->table_max[i]) / 2;
    h[i] = (sc->table_max[i] - sc->table_min[i]) / 2;
  }
  c[2] = sc->table_max[2];
  h[2] = SG_CELL_TABLE_GRID_M;
  fputs("    <geom name=\"table\" type=\"plane\" pos=\"", f);
  print3(f, c);
  fputs("\" size=\"", f);
  print3(f, h);
  fprintf(f, "\" friction=\"%.2f 0.005 0.0001\" rgba=\"0.550 0.400 0.250 1\"/>\n",
          SG_CELL_TABLE_FRICTION);
  for (int k = 0; k < SG_N_OBJECTS; k++)
    if (sc->objects[k].present) FG_TRY(print_object(f, &sc->objects[k], l));
  fputs("  </worldbody>\n", f);
  print_features(f, sc);
  fputs("</mujoco>\n", f);
  return 0;
}

int sg_cell_xml(const sg_scene *sc, char **xml, size_t *len) {
  *xml = NULL;
  *len = 0;
  part_list l = {malloc(MAX_PARTS * sizeof(part)), 0, MAX_PARTS};
  char *buf = NULL;
  size_t n = 0;
  FILE *f = l.p ? open_memstream(&buf, &n) : NULL;
  if (!f) {
    free(l.p);
    return fg_fail(FG_ENOMEM, "out of memory for the cell");
  }
  int rc = print_cell(f, sc, &l);
  free(l.p);
  if (fclose(f) != 0 && rc == 0) rc = fg_fail(FG_ENOMEM, "out of memory for the cell");
  if (rc != 0) {
    free(buf);
    return rc;
  }
  *xml = buf;
  *len = n;
  return 0;
}
