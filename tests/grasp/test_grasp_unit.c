/* Grasp library, unit level: query points, gripper boxes, the SO(3) cover, the fast cost
 * against the double-precision reference and its gradient against finite differences, the
 * collision check, and the search on a synthetic scene where the answer is known exactly: an
 * asymmetric object and a copy of it turned by 90 degrees about z and moved, both on the
 * voxel lattice, so a demo on the first must be found again on both; and the centring of a
 * grasp along a bar. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/pose.h"
#include "field/model.h"
#include "grasp/grasp.h"
#include "grasp/plan.h"
#include "query/query.h"
#include "query/voxfeat.h"
#include "test.h"

#define HID FG_FIELD_FEATURE_HIDDEN

static uint64_t rng = 0x9e3779b97f4a7c15ull;

/* Uniform in [-1, 1) (xorshift64). */
static double urand(void) {
  rng ^= rng << 13;
  rng ^= rng >> 7;
  rng ^= rng << 17;
  return (double)(rng >> 11) * (1.0 / 9007199254740992.0) * 2.0 - 1.0;
}

static void random_quat(double q[4]) {
  double n = 0.0;
  do {
    n = 0.0;
    for (int k = 0; k < 4; k++) {
      q[k] = urand();
      n += q[k] * q[k];
    }
  } while (n < 0.01 || n > 1.0);
  for (int k = 0; k < 4; k++) q[k] /= sqrt(n);
}

static double dist_between(const double A[16], const double B[16]) {
  const double d[3] = {A[3] - B[3], A[7] - B[7], A[11] - B[11]};
  return sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
}

/* ---------------------------------------------------------------- query points */

static void test_query_points(void) {
  enum { N = 1000 };
  float *a = malloc(N * 3 * sizeof *a), *b = malloc(N * 3 * sizeof *b);
  const double mean[3] = {0.01, -0.02, 0.03};
  ASSERT_OK(fg_grasp_query_points(N, mean, 0.01, a));
  ASSERT_OK(fg_grasp_query_points(N, mean, 0.01, b));
  ASSERT(memcmp(a, b, N * 3 * sizeof *a) == 0); /* fixed stream */
  /* a prefix of a longer draw: n points are the first n of any larger n */
  ASSERT_OK(fg_grasp_query_points(100, mean, 0.01, b));
  ASSERT(memcmp(a, b, 100 * 3 * sizeof *a) == 0);
  for (int ax = 0; ax < 3; ax++) {
    double s = 0.0, s2 = 0.0;
    for (int i = 0; i < N; i++) {
      s += a[3 * i + ax];
      s2 += (a[3 * i + ax] - mean[ax]) * (a[3 * i + ax] - mean[ax]);
    }
    ASSERT_NEAR(s / N, mean[ax], 0.0015);          /* 5 sigma of the mean: 5 * 0.01 / 31.6 */
    ASSERT_NEAR(sqrt(s2 / N), 0.01, 0.0012);
  }
  ASSERT_ERR(fg_grasp_query_points(0, mean, 0.01, a), FG_EINVAL, "1..1000");
  ASSERT_ERR(fg_grasp_query_points(1001, mean, 0.01, a), FG_EINVAL, "1..1000");
  ASSERT_ERR(fg_grasp_query_points(10, mean, 0.0, a), FG_EINVAL, "std");
  ASSERT_ERR(fg_grasp_query_points(10, mean, NAN, a), FG_EINVAL, "std");
  const double bad[3] = {0, INFINITY, 0};
  ASSERT_ERR(fg_grasp_query_points(10, bad, 0.01, a), FG_EINVAL, "mean");
  free(a);
  free(b);
}

/* The box layout: a fixed sequence (the same floats for the same arguments, a prefix of any
 * longer draw), every point inside the box, spread evenly (each axis's mean at the centre,
 * each eighth of the box holding its share), and the default box between the pads. */
static void test_query_points_box(void) {
  enum { N = 1000 };
  float *a = malloc(N * 3 * sizeof *a), *b = malloc(N * 3 * sizeof *b);
  const double mean[3] = {0.01, -0.02, 0.03}, size[3] = {0.027, 0.11, 0.04};
  ASSERT_OK(fg_grasp_query_points_box(N, mean, size, a));
  ASSERT_OK(fg_grasp_query_points_box(N, mean, size, b));
  ASSERT(memcmp(a, b, N * 3 * sizeof *a) == 0);
  ASSERT_OK(fg_grasp_query_points_box(100, mean, size, b));
  ASSERT(memcmp(a, b, 100 * 3 * sizeof *a) == 0);
  int octant[8] = {0};
  for (int ax = 0; ax < 3; ax++) {
    double s = 0.0;
    for (int i = 0; i < N; i++) {
      const double u = (a[3 * i + ax] - mean[ax]) / size[ax];
      ASSERT(u > -0.5 && u < 0.5);
      s += u;
    }
    ASSERT_NEAR(s / N, 0.0, 0.005);
  }
  for (int i = 0; i < N; i++)
    octant[(a[3 * i] > mean[0]) + 2 * (a[3 * i + 1] > mean[1]) + 4 * (a[3 * i + 2] > mean[2])]++;
  for (int o = 0; o < 8; o++) ASSERT(abs(octant[o] - N / 8) <= 5);
  /* point 3 is Halton's 4th: (1/8, 4/9, 4/5) of the box */
  const double zero[3] = {0, 0, 0}, unit[3] = {1, 1, 1};
  ASSERT_OK(fg_grasp_query_points_box(4, zero, unit, b));
  ASSERT_EQ(b[9], -0.375f);
  ASSERT_EQ(b[10], (float)(4.0 / 9.0 - 0.5));
  ASSERT_EQ(b[11], 0.3f);
  ASSERT_ERR(fg_grasp_query_points_box(0, mean, size, a), FG_EINVAL, "1..1000");
  const double flat[3] = {0.01, 0.0, 0.01}, huge[3] = {0.01, 2.0, 0.01}, far[3] = {0, 0, 1.5};
  ASSERT_ERR(fg_grasp_query_points_box(10, mean, flat, a), FG_EINVAL, "size");
  ASSERT_ERR(fg_grasp_query_points_box(10, mean, huge, a), FG_EINVAL, "size");
  ASSERT_ERR(fg_grasp_query_points_box(10, far, size, a), FG_EINVAL, "mean");
  /* the default: between the pads, as wide as they are, over their height */
  for (int k = 0; k < FG_GRIPPER_N_MODELS; k++) {
    const fg_gripper_model m = (fg_gripper_model)k;
    const double w = 0.05;
    double mu[3], sz[3];
    ASSERT_OK(fg_grasp_query_box_default(m, w, mu, sz));
    fg_gripper_box g[FG_GRIPPER_N_BOXES];
    ASSERT_OK(fg_gripper_boxes(m, w, g));
    const fg_gripper_box *pad = &g[FG_GRIPPER_BOX_PAD_MINUS_Y];
    ASSERT_NEAR(sz[0], 2 * pad->half_m[0], 1e-12);
    ASSERT_NEAR(sz[1], w, 1e-12);
    ASSERT_NEAR(sz[2], 2 * pad->half_m[2], 1e-12);
    ASSERT_NEAR(mu[0], 0.0, 0.0);
    ASSERT_NEAR(mu[1], 0.0, 0.0);
    ASSERT_NEAR(mu[2], pad->centre_m[2], 1e-12);
    ASSERT_OK(fg_grasp_query_points_box(N, mu, sz, a));
    ASSERT_ERR(fg_grasp_query_box_default(m, 0.0, mu, sz), FG_EINVAL, "width");
    ASSERT_ERR(fg_grasp_query_box_default(m, 0.3, mu, sz), FG_EINVAL, "stroke");
  }
  free(a);
  free(b);
}

/* ---------------------------------------------------------------- gripper models */

static double box_lo(const fg_gripper_box *b, int a) { return b->centre_m[a] - b->half_m[a]; }
static double box_hi(const fg_gripper_box *b, int a) { return b->centre_m[a] + b->half_m[a]; }

/* The layout of every model at several widths: the parts and pad flags in FG_GRIPPER_BOX_*
 * order, the finger at -y the mirror image of the one at +y, pads' faces width / 2 from the
 * TCP, from the tip back towards the palm pad, holder and link stacked along z (the pads
 * nearest the object), the palm behind the fingers and the same at every width, the tips on
 * the linkage's arc. */
static void test_gripper(void) {
  fg_gripper_model m;
  ASSERT_OK(fg_gripper_model_parse("robotiq-2f85", &m));
  ASSERT_EQ(m, FG_GRIPPER_ROBOTIQ_2F85);
  ASSERT_ERR(fg_gripper_model_parse("suction", &m), FG_EINVAL, "panda");
  ASSERT_STREQ(fg_gripper_box_name(FG_GRIPPER_BOX_PAD_MINUS_Y), "pad_minus_y");
  ASSERT_STREQ(fg_gripper_box_name(FG_GRIPPER_BOX_LINK_PLUS_Y), "link_plus_y");
  ASSERT(fg_gripper_box_name(FG_GRIPPER_N_BOXES) == NULL);
  ASSERT_STREQ(fg_gripper_part_name(FG_GRIPPER_FINGER_MINUS_Y), "finger_minus_y");
  for (int k = 0; k < FG_GRIPPER_N_MODELS; k++) {
    const fg_gripper_model mk = (fg_gripper_model)k;
    const fg_gripper_spec *s = fg_gripper_spec_get(mk);
    fg_gripper_box palm0[1] = {{{0}}};
    double rise_prev = INFINITY;
    for (int step = 0; step <= 4; step++) {
      const double w = s->stroke_m * step / 4;
      fg_gripper_box b[FG_GRIPPER_N_BOXES];
      ASSERT_OK(fg_gripper_boxes(mk, w, b));
      ASSERT_EQ(b[FG_GRIPPER_BOX_PALM].part, FG_GRIPPER_PALM);
      ASSERT_EQ(b[FG_GRIPPER_BOX_PALM].pad, 0);
      for (int i = 1; i < FG_GRIPPER_N_BOXES; i += 2) { /* (minus, plus) pairs */
        const fg_gripper_box *mi = &b[i], *pl = &b[i + 1];
        ASSERT_EQ(mi->part, FG_GRIPPER_FINGER_MINUS_Y);
        ASSERT_EQ(pl->part, FG_GRIPPER_FINGER_PLUS_Y);
        ASSERT_EQ(mi->pad, i == FG_GRIPPER_BOX_PAD_MINUS_Y);
        ASSERT_EQ(pl->pad, mi->pad);
        ASSERT_NEAR(mi->centre_m[1], -pl->centre_m[1], 1e-15);
        for (int a = 0; a < 3; a++) {
          ASSERT(pl->half_m[a] > 0);
          ASSERT_NEAR(mi->half_m[a], pl->half_m[a], 0.0);
          if (a != 1) ASSERT_NEAR(mi->centre_m[a], pl->centre_m[a], 0.0);
        }
      }
      const fg_gripper_box *pad = &b[FG_GRIPPER_BOX_PAD_PLUS_Y],
                           *holder = &b[FG_GRIPPER_BOX_HOLDER_PLUS_Y],
                           *link = &b[FG_GRIPPER_BOX_LINK_PLUS_Y], *palm = &b[FG_GRIPPER_BOX_PALM];
      /* the pad's face and the holder's at width / 2, the link at most that far inwards */
      ASSERT_NEAR(box_lo(pad, 1), w / 2, 1e-12);
      ASSERT_NEAR(box_lo(holder, 1), w / 2, 1e-12);
      ASSERT(box_lo(link, 1) <= w / 2 + 1e-12 && box_lo(link, 1) >= 0);
      /* a thin pad, thicker parts behind it */
      ASSERT(2 * pad->half_m[1] < 0.020);
      ASSERT(holder->half_m[1] > pad->half_m[1]);
      ASSERT(box_hi(link, 1) > box_hi(holder, 1));
      /* stacked along z: the pad nearest the object, the link nearest the palm */
      const double rise = fg_gripper_tip_rise(mk, w);
      ASSERT_NEAR(box_hi(pad, 2), s->tip_beyond_tcp_m + rise, 1e-12);
      ASSERT_NEAR(box_lo(pad, 2), box_hi(holder, 2), 1e-12);
      ASSERT_NEAR(box_lo(holder, 2), box_hi(link, 2), 1e-12);
      ASSERT(box_lo(link, 2) < box_hi(link, 2));
      ASSERT(box_hi(palm, 2) < box_lo(holder, 2));
      ASSERT(palm->centre_m[2] < 0 && palm->half_m[1] >= palm->half_m[0]);
      if (step == 0)
        palm0[0] = *palm;
      else
        ASSERT(memcmp(palm, &palm0[0], sizeof *palm) == 0);
      /* the tips rise as the fingers close: not at all for a Franka finger, which slides */
      ASSERT(rise >= 0 && rise <= rise_prev);
      rise_prev = rise;
      if (step == 4) { /* fully open: the TCP lies between the pads */
        ASSERT_NEAR(rise, 0.0, 1e-12);
        ASSERT(box_lo(pad, 2) < 0 && box_hi(pad, 2) > 0);
        ASSERT_NEAR(box_lo(pad, 1), s->stroke_m / 2, 1e-12);
      }
    }
    printf("gripper %s: tips rise %.1f mm closing\n", s->name,
           1e3 * fg_gripper_tip_rise(mk, 0.0));
    ASSERT(k == FG_GRIPPER_PANDA ? fg_gripper_tip_rise(mk, 0.0) == 0.0
                                 : fg_gripper_tip_rise(mk, 0.0) > 0.010);
    fg_gripper_box b[FG_GRIPPER_N_BOXES];
    ASSERT_ERR(fg_gripper_boxes(mk, s->stroke_m + 0.001, b), FG_EINVAL, "stroke");
    ASSERT_ERR(fg_gripper_boxes(mk, -0.001, b), FG_EINVAL, "stroke");
    ASSERT_ERR(fg_gripper_boxes(mk, NAN, b), FG_EINVAL, "stroke");
  }
  ASSERT(isnan(fg_gripper_tip_rise(FG_GRIPPER_N_MODELS, 0.05)));
  ASSERT_NEAR(fg_gripper_spec_get(FG_GRIPPER_PANDA)->stroke_m, 0.08, 1e-12);
  ASSERT_NEAR(fg_gripper_spec_get(FG_GRIPPER_ROBOTIQ_2F140)->stroke_m, 0.14, 1e-12);
}

/* The ring: a handle lying flat on 2 mm voxels, its opening 20 mm across (y) and 40 mm long
 * (x), 12 mm deep, walls 18 mm thick. Every model, approaching from above 4 cm open, puts
 * its -y pad into the opening and its +y pad outside the ring: free. 6 mm either way along y,
 * the pad meets a wall. The three-box model before this one had 20 and 30 mm thick fingers
 * reaching 45 to 100 mm back from the TCP, so its Robotiq fingers could not enter. */
#define RING_VS 0.002
#define RING_NX 60
#define RING_NY 70
#define RING_NZ 20

static void test_gripper_ring(void) {
  const double mn[3] = {-0.06, -0.06, 0.0};
  const double mx[3] = {mn[0] + RING_NX * RING_VS, mn[1] + RING_NY * RING_VS,
                        mn[2] + RING_NZ * RING_VS};
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, mn, mx, RING_VS));
  const size_t N = fg_voxel_grid_count(&g);
  const int D = 8;
  float *alpha = calloc(N, sizeof *alpha), *h = calloc(N * HID, sizeof *h);
  float *W = malloc((size_t)D * HID * sizeof *W);
  ASSERT(alpha && h && W);
  /* a head of its own, leaving urand()'s stream to the tests after this one */
  for (int i = 0; i < D * HID; i++) W[i] = (float)sin(1.0 + i);
  /* the opening spans x -0.020..0.020, y -0.010..0.010 around the origin, the ring around it
   * x -0.038..0.038, y -0.028..0.028; z 0.010..0.022 */
  for (int iz = 0; iz < RING_NZ; iz++)
    for (int iy = 0; iy < RING_NY; iy++)
      for (int ix = 0; ix < RING_NX; ix++) {
        double c[3];
        fg_voxel_grid_centre(&g, ix, iy, iz, c);
        const int in_ring = fabs(c[0]) < 0.038 && fabs(c[1]) < 0.028 && c[2] > 0.010 &&
                            c[2] < 0.022;
        const int in_hole = fabs(c[0]) < 0.020 && fabs(c[1]) < 0.010;
        if (!in_ring || in_hole) continue;
        const size_t idx = ((size_t)iz * RING_NY + iy) * RING_NX + ix;
        alpha[idx] = 0.95f;
        for (int j = 0; j < HID; j++) h[idx * HID + j] = 1.0f;
      }
  fg_voxel_features *vf = NULL;
  ASSERT_OK(fg_voxel_features_from_arrays(&vf, &g, D, alpha, h, W));
  fg_grasp_field *gf = NULL;
  ASSERT_OK(fg_grasp_field_new(&gf, vf, 1));
  const double w = 0.04;
  for (int k = 0; k < FG_GRIPPER_N_MODELS; k++) {
    const fg_gripper_model mk = (fg_gripper_model)k;
    fg_gripper_box b[FG_GRIPPER_N_BOXES];
    ASSERT_OK(fg_gripper_boxes(mk, w, b));
    const fg_gripper_box *pad = &b[FG_GRIPPER_BOX_PAD_MINUS_Y];
    const double t = 2 * pad->half_m[1], tip = box_hi(pad, 2);
    /* the -y pad centred in the opening, its tip 2 mm above the ring's underside, so the
     * ring's 12 mm lie within the pad's height */
    ASSERT(2 * pad->half_m[2] > 0.012 + 0.002);
    ASSERT(2 * pad->half_m[0] < 0.040);
    double T[16] = {-1, 0, 0, 0, 0, 1, 0, w / 2 + t / 2, 0, 0, -1, 0.012 + tip, 0, 0, 0, 1};
    ASSERT_EQ(fg_grasp_collides(gf, mk, w, T, 0.5f), 0);
    for (int side = -1; side <= 1; side += 2) {
      double Ts[16];
      memcpy(Ts, T, sizeof Ts);
      Ts[7] += side * 0.006;
      ASSERT_EQ(fg_grasp_collides(gf, mk, w, Ts, 0.5f), 1);
    }
    /* the old envelope: 30 mm (Robotiq) or 20 mm (Franka) thick from the face inwards of
     * the opening's far wall at -0.010 */
    const double old_thick = k == FG_GRIPPER_PANDA ? 0.020 : 0.030;
    printf("ring, %s: a pad %.0f mm thick enters the 20 mm opening; the old %.0f mm finger "
           "%s\n", fg_gripper_spec_get(mk)->name, 1e3 * t, 1e3 * old_thick,
           T[7] - w / 2 - old_thick < -0.010 ? "did not" : "did");
    if (k != FG_GRIPPER_PANDA) ASSERT(T[7] - w / 2 - old_thick < -0.010);
  }
  fg_grasp_field_free(gf);
  fg_voxel_features_free(vf);
  free(alpha);
  free(h);
  free(W);
}

/* ---------------------------------------------------------------- SO(3) cover */

/* The spiral's largest gap: the angle from a random rotation to its nearest member, over
 * many random rotations, shrinks with n like a uniform cover. */
static void test_so3(void) {
  const int ns[3] = {8, 24, 72};
  const double max_gap_deg[3] = {140.0, 85.0, 60.0};
  for (int t = 0; t < 3; t++) {
    const int n = ns[t];
    double *q = malloc((size_t)n * 4 * sizeof *q);
    fg_so3_super_fibonacci(n, q);
    for (int i = 0; i < n; i++) {
      ASSERT_NEAR(q[4 * i] * q[4 * i] + q[4 * i + 1] * q[4 * i + 1] +
                      q[4 * i + 2] * q[4 * i + 2] + q[4 * i + 3] * q[4 * i + 3],
                  1.0, 1e-12);
      ASSERT(q[4 * i] >= 0);
    }
    double worst = 0.0;
    for (int k = 0; k < 2000; k++) {
      double r[4];
      random_quat(r);
      double best = 0.0;
      for (int i = 0; i < n; i++) {
        const double d = fabs(r[0] * q[4 * i] + r[1] * q[4 * i + 1] + r[2] * q[4 * i + 2] +
                              r[3] * q[4 * i + 3]);
        if (d > best) best = d;
      }
      const double ang = 2.0 * acos(best > 1 ? 1 : best) * 180.0 / M_PI;
      if (ang > worst) worst = ang;
    }
    printf("so3: %d rotations, largest gap %.1f degrees\n", n, worst);
    ASSERT(worst < max_gap_deg[t]);
    free(q);
  }
}

/* ---------------------------------------------------------------- cost and gradient */

static fg_voxel_features *random_cache(int D) {
  const double mn[3] = {0.0, 0.0, 0.0}, mx[3] = {0.2, 0.2, 0.12};
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, mn, mx, 1.0, D));
  fg_field *f = NULL;
  ASSERT_OK(fg_field_new(&f, &cfg, 11));
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, mn, mx, 0.01));
  fg_voxel_features *vf = NULL;
  ASSERT_OK(fg_voxel_features_build(&vf, f, &g, 2));
  fg_field_free(f);
  return vf;
}

static void test_cost(void) {
  enum { D = 40, NQ = 60 };
  fg_voxel_features *vf = random_cache(D);
  ASSERT(fg_voxel_features_n_kept(vf) > 100);
  fg_grasp_field *gf = NULL;
  ASSERT_OK(fg_grasp_field_new(&gf, vf, 2));
  float p[NQ * 3], Z[NQ * D], q[D];
  const double mean[3] = {0, 0, 0.005};
  ASSERT_OK(fg_grasp_query_points(NQ, mean, 0.012, p));
  for (int i = 0; i < NQ * D; i++) Z[i] = (float)urand();
  double qn = 0.0;
  for (int d = 0; d < D; d++) {
    q[d] = (float)urand();
    qn += (double)q[d] * q[d];
  }
  for (int d = 0; d < D; d++) q[d] /= (float)sqrt(qn);
  for (int with_q = 0; with_q < 2; with_q++) {
    fg_grasp_target t = {NQ, D, p, Z, with_q ? q : NULL};
    for (int k = 0; k < 40; k++) {
      double qu[4], T[16];
      const double pos[3] = {0.1 + 0.07 * urand(), 0.1 + 0.07 * urand(), 0.06 + 0.04 * urand()};
      random_quat(qu);
      ASSERT_OK(fg_pose_from_quat(pos, qu, T));
      double gt[3], gw[3], cosv, w;
      const double J = fg_grasp_cost(gf, &t, T, gt, gw, &cosv, &w);
      const double Jr = fg_grasp_cost_ref(vf, &t, T);
      ASSERT(isfinite(J));
      ASSERT_NEAR(J, Jr, 2e-4 * (1 + fabs(Jr)));
      if (!with_q) ASSERT_NEAR(J, -cosv, 1e-12);
      /* central differences: translation along world axes, rotation exp([w]) on the left
       * about the TCP. Trilinear interpolation has kinks on the cell faces, so a difference
       * whose interval straddles one is off: the smallest error over three step sizes counts
       * (float sums limit the smallest step). */
      for (int a = 0; a < 3; a++) {
        double err_t = INFINITY, err_w = INFINITY;
        for (double h = 1e-5; h > 5e-7; h /= 3.0) {
          double Tp[16], Tm[16];
          memcpy(Tp, T, sizeof Tp);
          memcpy(Tm, T, sizeof Tm);
          Tp[4 * a + 3] += h;
          Tm[4 * a + 3] -= h;
          const double fd = (fg_grasp_cost(gf, &t, Tp, NULL, NULL, NULL, NULL) -
                             fg_grasp_cost(gf, &t, Tm, NULL, NULL, NULL, NULL)) / (2 * h);
          err_t = fmin(err_t, fabs(gt[a] - fd) / (1 + fabs(fd)));
          const double hw = 10 * h, zero[3] = {0, 0, 0};
          double Tr[2][16];
          for (int sgn = 0; sgn < 2; sgn++) {
            double qr[4] = {cos(hw / 2), 0, 0, 0}, Rw[16];
            qr[1 + a] = (sgn ? -1 : 1) * sin(hw / 2);
            ASSERT_OK(fg_pose_from_quat(zero, qr, Rw));
            fg_pose_compose(Rw, T, Tr[sgn]);
            Tr[sgn][3] = T[3], Tr[sgn][7] = T[7], Tr[sgn][11] = T[11];
          }
          const double fdw = (fg_grasp_cost(gf, &t, Tr[0], NULL, NULL, NULL, NULL) -
                              fg_grasp_cost(gf, &t, Tr[1], NULL, NULL, NULL, NULL)) / (2 * hw);
          err_w = fmin(err_w, fabs(gw[a] - fdw) / (1 + fabs(fdw)));
        }
        ASSERT(err_t < 1e-2);
        ASSERT(err_w < 1e-2);
      }
    }
  }
  /* a pose far outside the grid sees nothing: cost 0, gradient 0 */
  {
    fg_grasp_target t = {NQ, D, p, Z, NULL};
    const double pos[3] = {5, 5, 5}, qi[4] = {1, 0, 0, 0};
    double T[16], gt[3], gw[3];
    ASSERT_OK(fg_pose_from_quat(pos, qi, T));
    ASSERT_NEAR(fg_grasp_cost(gf, &t, T, gt, gw, NULL, NULL), 0.0, 0.0);
    ASSERT_NEAR(gt[0] + gt[1] + gt[2] + gw[0] + gw[1] + gw[2], 0.0, 0.0);
    t.dim = D + 1;
    ASSERT(isnan(fg_grasp_cost(gf, &t, T, NULL, NULL, NULL, NULL)));
    fg_grasp_result r;
    ASSERT_ERR(fg_grasp_search(gf, &t, NULL, &r), FG_EINVAL, "D = 41");
  }
  fg_grasp_field_free(gf);
  fg_voxel_features_free(vf);
}

/* ---------------------------------------------------------------- plans */

/* fg_grasp_plan_run on the synthetic scene: retrieval by fg_grasp_task_similarity, the
 * language mask, the opening, the pre-grasps and a placement's missing lift, each against
 * the search run by hand. demo: the demo task (its query points p, embedding Z at T_demo);
 * q: a unit query of D. */
static void test_plan(const fg_grasp_field *gf, const fg_voxel_features *vf,
                      const fg_grasp_task *demo, const double T_demo[16], const float *q) {
  const int D = demo->dim, NQ = demo->n_points;
  const size_t N = fg_voxel_grid_count(fg_voxel_features_grid(vf));
  /* a second task sampled a few centimetres off the demo, one of another D, one of zeros */
  float *Z2 = malloc((size_t)NQ * D * sizeof *Z2), *Z0 = calloc((size_t)NQ * D, sizeof *Z0);
  double T2[16];
  memcpy(T2, T_demo, sizeof T2);
  T2[3] -= 0.03;
  ASSERT_OK(fg_grasp_sample(gf, T2, demo->p_gripper, NQ, Z2));
  fg_grasp_task tasks[4] = {{"other", 0, NQ, D, demo->p_gripper, Z2, 0.04, 0.1},
                            {"wide_d", 0, NQ, D + 1, demo->p_gripper, Z2, 0.04, 0.1},
                            {"empty", 0, NQ, D, demo->p_gripper, Z0, 0.04, 0.1}, *demo};
  fg_query query = {0};
  ASSERT_OK(fg_query_init(&query, D, q, 1, NULL, 0, 1.0f));
  fg_grasp_plan_request r = {.tasks = tasks, .n_tasks = 4, .retrieve = 1, .query = &query};
  fg_grasp_options_default(&r.opt);
  r.opt.gripper = FG_GRIPPER_ROBOTIQ_2F85;
  r.opt.top_k = 3;
  r.opt.n_threads = 2;
  fg_grasp_plan p;
  ASSERT_OK(fg_grasp_plan_run(gf, &r, &p));
  /* the two tasks of D with a defined likeness, ranked by it */
  ASSERT_EQ(p.n_retrieval, 2);
  const double s_other = fg_grasp_task_similarity(Z2, NQ, D, query.q),
               s_demo = fg_grasp_task_similarity(demo->Z, NQ, D, query.q);
  const int first = s_demo > s_other ? 3 : 0;
  ASSERT_EQ(p.task, first);
  ASSERT_EQ(p.retrieval[0].task, first);
  ASSERT_EQ(p.retrieval[1].task, 3 - first);
  ASSERT_NEAR(p.retrieval[0].score, first == 3 ? s_demo : s_other, 0.0);
  /* the search by hand: the mask where the query scores 0.5, the task's width and approach */
  const fg_grasp_task *t = &tasks[first];
  float *scores = malloc(N * sizeof *scores);
  uint8_t *mask = malloc(N);
  ASSERT_OK(fg_voxel_features_score(vf, &query, r.opt.candidate_alpha, scores, 1));
  size_t n_mask = 0;
  for (size_t i = 0; i < N; i++) n_mask += mask[i] = scores[i] >= 0.5f;
  ASSERT(n_mask > 0 && n_mask < fg_voxel_features_n_kept(vf));
  fg_grasp_options o = r.opt;
  o.candidate_mask = mask;
  o.width_m = t->width_m;
  o.approach_m = t->approach_m;
  const fg_grasp_target target = {NQ, D, t->p_gripper, t->Z, NULL};
  fg_grasp_result by_hand;
  ASSERT_OK(fg_grasp_search(gf, &target, &o, &by_hand));
  ASSERT(by_hand.n >= 1);
  ASSERT_EQ(p.result.n, by_hand.n);
  ASSERT(memcmp(p.result.poses, by_hand.poses, (size_t)by_hand.n * sizeof *by_hand.poses) == 0);
  ASSERT_NEAR(p.width_m, t->width_m, 0.0);
  for (int k = 0; k < p.result.n; k++) { /* backed off along the gripper's own -z */
    const double *T = p.result.poses[k].T_world_gripper, *P = p.T_world_pre[k];
    for (int a = 0; a < 3; a++) {
      ASSERT_NEAR(P[4 * a + 3], T[4 * a + 3] - t->approach_m * T[4 * a + 2], 1e-12);
      for (int b = 0; b < 3; b++) ASSERT_NEAR(P[4 * a + b], T[4 * a + b], 0.0);
    }
  }
  fg_grasp_result_release(&by_hand);
  fg_grasp_plan_release(&p);
  /* a named task wider than the stroke opens to the stroke; no query, no retrieval */
  fg_grasp_task wide = *demo;
  wide.width_m = 0.2;
  r = (fg_grasp_plan_request){.tasks = &wide, .n_tasks = 1, .opt = r.opt};
  ASSERT_OK(fg_grasp_plan_run(gf, &r, &p));
  ASSERT_NEAR(p.width_m, fg_gripper_spec_get(FG_GRIPPER_ROBOTIQ_2F85)->stroke_m, 0.0);
  ASSERT(p.retrieval == NULL && p.n_retrieval == 0 && p.task == 0);
  fg_grasp_plan_release(&p);
  /* under a ceiling 5 cm above the demo, a pick's 10 cm lift is refused, a placement lets go
   * where it is */
  fg_motion_limits lim = {.has_box = 1, .cone_rad = M_PI, .max_force_n = 100,
                          .max_speed_mps = 1, .max_width_m = 0.085};
  const fg_voxel_grid *g = fg_voxel_features_grid(vf);
  for (int a = 0; a < 3; a++) {
    lim.box_min_m[a] = g->min[a] - 1;
    lim.box_max_m[a] = g->max[a] + 1;
  }
  lim.box_max_m[2] = T_demo[11] + 0.05;
  fg_grasp_task pick = *demo;
  pick.approach_m = 0;
  r = (fg_grasp_plan_request){.tasks = &pick, .n_tasks = 1, .opt = r.opt};
  r.opt.limits = &lim;
  r.opt.retreat_m = 0.10;
  ASSERT_OK(fg_grasp_plan_run(gf, &r, &p));
  ASSERT_EQ(p.result.n, 0);
  ASSERT(strstr(p.result.reason, "limits") != NULL);
  fg_grasp_plan_release(&p);
  pick.place = 1;
  ASSERT_OK(fg_grasp_plan_run(gf, &r, &p));
  ASSERT(p.result.n >= 1);
  fg_grasp_plan_release(&p);
  /* nothing to retrieve; a weight without a query */
  r = (fg_grasp_plan_request){.tasks = tasks + 1, .n_tasks = 2, .retrieve = 1, .query = &query,
                              .opt = r.opt};
  ASSERT_ERR(fg_grasp_plan_run(gf, &r, &p), FG_ENOENT, "D = ");
  r.query = NULL;
  ASSERT_ERR(fg_grasp_plan_run(gf, &r, &p), FG_EINVAL, "query");
  fg_query_release(&query);
  free(scores);
  free(mask);
  free(Z2);
  free(Z0);
}

/* ---------------------------------------------------------------- synthetic scene */

#define NX 40
#define NY 30
#define NZ 14
#define VS 0.01

/* An asymmetric object of voxel offsets from its pivot: an L-shaped base with a post on one
 * arm, two materials (the post is the second). */
static const int shape[][4] = {
  /* dx, dy, dz, material */
  {0, 0, 0, 0}, {1, 0, 0, 0}, {2, 0, 0, 0}, {3, 0, 0, 0}, {0, 1, 0, 0}, {0, 2, 0, 0},
  {0, 0, 1, 0}, {1, 0, 1, 0}, {2, 0, 1, 0}, {3, 0, 1, 0}, {0, 1, 1, 0}, {0, 2, 1, 0},
  {3, 0, 2, 1}, {3, 0, 3, 1}, {3, 0, 4, 1}, {0, 2, 2, 1},
};
#define N_SHAPE ((int)(sizeof shape / sizeof shape[0]))

typedef struct synth {
  fg_voxel_grid g;
  float *alpha, *h, *W;
  int D;
} synth;

static void put_object(synth *s, const int pivot[3], int quarter_turns, const float *hmat) {
  for (int k = 0; k < N_SHAPE; k++) {
    int dx = shape[k][0], dy = shape[k][1];
    for (int q = 0; q < quarter_turns; q++) { /* +90 degrees about z */
      const int t = dx;
      dx = -dy;
      dy = t;
    }
    const int ix = pivot[0] + dx, iy = pivot[1] + dy, iz = pivot[2] + shape[k][2];
    const size_t idx = ((size_t)iz * NY + iy) * NX + ix;
    s->alpha[idx] = 0.95f;
    memcpy(s->h + idx * HID, hmat + shape[k][3] * HID, HID * sizeof(float));
  }
}

/* An empty NX x NY x NZ grid of VS voxels with D = 32 and a random feature head. */
static void synth_init(synth *s) {
  memset(s, 0, sizeof *s);
  s->D = 32;
  const double mn[3] = {0, 0, 0}, mx[3] = {NX * VS, NY * VS, NZ * VS};
  ASSERT_OK(fg_voxel_grid_init(&s->g, mn, mx, VS));
  ASSERT_EQ(fg_voxel_grid_count(&s->g), NX * NY * NZ);
  const size_t N = fg_voxel_grid_count(&s->g);
  s->alpha = calloc(N, sizeof *s->alpha);
  s->h = calloc(N * HID, sizeof *s->h);
  s->W = malloc((size_t)s->D * HID * sizeof *s->W);
  ASSERT(s->alpha && s->h && s->W);
  for (int i = 0; i < s->D * HID; i++) s->W[i] = (float)urand() * 0.2f;
}

static void synth_free(synth *s) {
  free(s->alpha);
  free(s->h);
  free(s->W);
}

static void test_search_synthetic(void) {
  synth s;
  synth_init(&s);
  const size_t N = fg_voxel_grid_count(&s.g);
  float hmat[2 * HID];
  for (int i = 0; i < 2 * HID; i++) hmat[i] = (float)urand();
  /* the demo object at pivot A; its copy at B turned by +90 degrees about z */
  const int A[3] = {8, 8, 2}, B[3] = {28, 16, 2};
  put_object(&s, A, 0, hmat);
  put_object(&s, B, 1, hmat);
  fg_voxel_features *vf = NULL;
  ASSERT_OK(fg_voxel_features_from_arrays(&vf, &s.g, s.D, s.alpha, s.h, s.W));
  ASSERT_EQ(fg_voxel_features_n_kept(vf), 2 * N_SHAPE);
  fg_grasp_field *gf = NULL;
  ASSERT_OK(fg_grasp_field_new(&gf, vf, 2));

  /* demo: TCP at the top of the post's base (voxel (3,0,2) of A), approaching from above
   * (gripper z = world -z) and closing along world y */
  double c[3];
  fg_voxel_grid_centre(&s.g, A[0] + 3, A[1], A[2] + 2, c);
  const double T_demo[16] = {-1, 0, 0, c[0], 0, 1, 0, c[1], 0, 0, -1, c[2] + 0.004, 0, 0, 0, 1};
  enum { NQ = 100 };
  float p[NQ * 3];
  const double mean[3] = {0, 0, 0};
  ASSERT_OK(fg_grasp_query_points(NQ, mean, 0.015, p));
  float *Z = malloc((size_t)NQ * s.D * sizeof *Z);
  ASSERT_OK(fg_grasp_sample(gf, T_demo, p, NQ, Z));
  fg_grasp_target t = {NQ, s.D, p, Z, NULL};
  ASSERT_NEAR(fg_grasp_cost(gf, &t, T_demo, NULL, NULL, NULL, NULL), -1.0, 1e-5);

  /* the copy's expected pose: M T_demo, M = turn by 90 degrees about z around B's pivot
   * after moving A's pivot onto it */
  double pa[3], pb[3];
  fg_voxel_grid_centre(&s.g, A[0], A[1], A[2], pa);
  fg_voxel_grid_centre(&s.g, B[0], B[1], B[2], pb);
  const double M[16] = {0, -1, 0, pb[0] + pa[1], 1, 0, 0, pb[1] - pa[0], 0, 0, 1, pb[2] - pa[2],
                        0, 0, 0, 1};
  double T_copy[16];
  fg_pose_compose(M, T_demo, T_copy);
  ASSERT_NEAR(fg_grasp_cost(gf, &t, T_copy, NULL, NULL, NULL, NULL), -1.0, 1e-4);

  fg_grasp_options o;
  fg_grasp_options_default(&o);
  o.check_collisions = 0;
  o.top_k = 4;
  o.n_threads = 2;
  fg_grasp_result r2, r1;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r2));
  ASSERT(r2.n >= 2);
  printf("synthetic: %zu candidates x %d rotations, %zu optimised, best score %.5f, %.3f s\n",
         r2.stats.candidates, r2.stats.rotations, r2.stats.poses_optimised, r2.poses[0].score,
         r2.stats.seconds);
  ASSERT_EQ(r2.stats.candidates, 2 * N_SHAPE);
  int found_demo = 0, found_copy = 0;
  for (int k = 0; k < 2; k++) {
    const double *T = r2.poses[k].T_world_gripper;
    printf("  %d: score %.5f, %.2f mm / %.2f deg from the demo, %.2f mm / %.2f deg from the "
           "copy\n", k, r2.poses[k].score, 1e3 * dist_between(T, T_demo),
           fg_pose_angle_rad(T, T_demo) * 180 / M_PI, 1e3 * dist_between(T, T_copy),
           fg_pose_angle_rad(T, T_copy) * 180 / M_PI);
    ASSERT(r2.poses[k].score > 0.99);
    found_demo |= dist_between(T, T_demo) < 0.003 && fg_pose_angle_rad(T, T_demo) < 3 * M_PI / 180;
    found_copy |= dist_between(T, T_copy) < 0.003 && fg_pose_angle_rad(T, T_copy) < 3 * M_PI / 180;
  }
  ASSERT(found_demo && found_copy);
  /* bit-identical for another thread count, different for another seed */
  o.n_threads = 1;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r1));
  ASSERT_EQ(r1.n, r2.n);
  ASSERT(memcmp(r1.poses, r2.poses, (size_t)r1.n * sizeof *r1.poses) == 0);
  fg_grasp_result_release(&r1);
  o.seed = 7;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r1));
  ASSERT(r1.n >= 1 && r1.poses[0].score > 0.99);
  ASSERT(memcmp(r1.poses, r2.poses, sizeof *r1.poses) != 0);
  fg_grasp_result_release(&r1);

  /* collisions: the demo pose with a 2F-85 open to 6 cm straddles the post; closed to 1 cm
   * its fingers cut through it; moved down 8 cm its palm comes down on the object */
  ASSERT_EQ(fg_grasp_collides(gf, FG_GRIPPER_ROBOTIQ_2F85, 0.06, T_demo, 0.5f), 0);
  ASSERT_EQ(fg_grasp_collides(gf, FG_GRIPPER_ROBOTIQ_2F85, 0.01, T_demo, 0.5f), 1);
  double T_low[16];
  memcpy(T_low, T_demo, sizeof T_low);
  T_low[11] -= 0.08;
  ASSERT_EQ(fg_grasp_collides(gf, FG_GRIPPER_ROBOTIQ_2F85, 0.06, T_low, 0.5f), 1);
  ASSERT_ERR(fg_grasp_collides(gf, FG_GRIPPER_ROBOTIQ_2F85, 0.2, T_demo, 0.5f), FG_EINVAL,
             "stroke");
  /* with collisions checked, every result is free */
  o.check_collisions = 1;
  o.gripper = FG_GRIPPER_ROBOTIQ_2F85;
  o.width_m = 0.06;
  o.seed = 0;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r1));
  ASSERT(r1.n >= 1);
  ASSERT(r1.stats.rejected_collisions > 0);
  for (int k = 0; k < r1.n; k++) {
    ASSERT_EQ(r1.poses[k].collision_free, 1);
    ASSERT_EQ(fg_grasp_collides(gf, o.gripper, o.width_m, r1.poses[k].T_world_gripper, 0.1f), 0);
  }
  fg_grasp_result_release(&r1);

  /* motion limits: only approaches within the cone, paths within the box, nothing through
   * the floor */
  fg_motion_limits lim = {.has_box = 1, .cone_rad = 30 * M_PI / 180, .max_force_n = 100,
                          .max_speed_mps = 1, .max_width_m = 0.085};
  for (int a = 0; a < 3; a++) {
    lim.box_min_m[a] = s.g.min[a] - 1;
    lim.box_max_m[a] = s.g.max[a] + 1;
  }
  o.limits = &lim;
  o.approach_m = 0.10;
  o.retreat_m = 0.10;
  o.floor_solid = 1;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r1));
  ASSERT(r1.n >= 1);
  ASSERT(r1.stats.rejected_limits > 0); /* most of the cover points elsewhere */
  fg_gripper_box boxes[FG_GRIPPER_N_BOXES];
  ASSERT_OK(fg_gripper_boxes(o.gripper, o.width_m, boxes));
  for (int k = 0; k < r1.n; k++) {
    const double *T = r1.poses[k].T_world_gripper;
    ASSERT(acos(-T[10]) <= lim.cone_rad + 1e-9);
    for (int b = 0; b < FG_GRIPPER_N_BOXES; b++) /* every corner above the grid's floor */
      for (int corner = 0; corner < 8; corner++) {
        const double pc[3] = {boxes[b].centre_m[0] + (corner & 1 ? 1 : -1) * boxes[b].half_m[0],
                              boxes[b].centre_m[1] + (corner & 2 ? 1 : -1) * boxes[b].half_m[1],
                              boxes[b].centre_m[2] + (corner & 4 ? 1 : -1) * boxes[b].half_m[2]};
        double pw[3];
        fg_pose_apply(T, pc, pw);
        ASSERT(pw[2] >= s.g.min[2] - s.g.voxel_size);
      }
  }
  fg_grasp_result_release(&r1);
  /* a box whose top lies below the approach's start: no grasp, and the reason says why */
  lim.box_max_m[2] = T_demo[11] + 0.05;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r1));
  ASSERT_EQ(r1.n, 0);
  ASSERT(strstr(r1.reason, "limits") != NULL);
  fg_grasp_result_release(&r1);
  o.approach_m = 0;
  o.retreat_m = 0;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r1));
  ASSERT(r1.n >= 1);
  for (int k = 0; k < r1.n; k++) ASSERT(r1.poses[k].T_world_gripper[11] <= lim.box_max_m[2]);
  fg_grasp_result_release(&r1);
  o.limits = NULL;
  o.floor_solid = 0;

  /* the language weight: q along the post's feature raises its poses' weight */
  float fpost[64];
  ASSERT_OK(fg_voxel_features_feature(vf, ((size_t)(A[2] + 3) * NY + A[1]) * NX + A[0] + 3,
                                      fpost));
  double nn = 0.0;
  for (int d = 0; d < s.D; d++) nn += fpost[d] * fpost[d];
  float q[64];
  for (int d = 0; d < s.D; d++) q[d] = (float)(fpost[d] / sqrt(nn));
  t.q = q;
  double cosv, w;
  const double J = fg_grasp_cost(gf, &t, T_demo, NULL, NULL, &cosv, &w);
  ASSERT(w > 0.0);
  ASSERT_NEAR(J, -w * cosv, 1e-12);
  ASSERT_NEAR(J, fg_grasp_cost_ref(vf, &t, T_demo), 1e-4 * (1 + fabs(J)));
  const fg_grasp_task demo = {"demo", 0, NQ, s.D, p, Z, 0.06, 0.08};
  test_plan(gf, vf, &demo, T_demo, q);

  /* a mask that rules out every candidate: an empty result with a reason */
  uint8_t *mask = calloc(N, 1);
  o.candidate_mask = mask;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r1));
  ASSERT_EQ(r1.n, 0);
  ASSERT(r1.reason && strstr(r1.reason, "mask"));
  fg_grasp_result_release(&r1);
  free(mask);
  /* bad options */
  fg_grasp_options_default(&o);
  o.top_k = 0;
  ASSERT_ERR(fg_grasp_search(gf, &t, &o, &r1), FG_EINVAL, "top_k");
  fg_grasp_options_default(&o);
  o.n_rotations = 4;
  ASSERT_ERR(fg_grasp_search(gf, &t, &o, &r1), FG_EINVAL, "rotations");

  fg_grasp_result_release(&r2);
  free(Z);
  fg_grasp_field_free(gf);
  fg_voxel_features_free(vf);
  synth_free(&s);
}

/* Centring: a bar 8 cm long, 3 cm wide and 3 cm tall of one material, shown grasped from
 * above across its width 2 cm off its middle. Along its length the pads meet the same two
 * faces over a stretch where the cost is flat (and, its features the same everywhere, from
 * any side), so the optimum lands anywhere on it; centred on the stretch the bar's geometry
 * shows between the pads, every grasp with the pads' width along the bar lies at its middle
 * (within half a step of 2 mm). */
static void test_search_centring(void) {
  synth s;
  synth_init(&s);
  float hmat[HID];
  for (int i = 0; i < HID; i++) hmat[i] = (float)urand();
  for (int iz = 0; iz < 3; iz++) /* x 0.10..0.18, y 0.14..0.17, z 0..0.03 */
    for (int iy = 14; iy < 17; iy++)
      for (int ix = 10; ix < 18; ix++) {
        const size_t idx = ((size_t)iz * NY + iy) * NX + ix;
        s.alpha[idx] = 0.95f;
        memcpy(s.h + idx * HID, hmat, sizeof hmat);
      }
  fg_voxel_features *vf = NULL;
  ASSERT_OK(fg_voxel_features_from_arrays(&vf, &s.g, s.D, s.alpha, s.h, s.W));
  fg_grasp_field *gf = NULL;
  ASSERT_OK(fg_grasp_field_new(&gf, vf, 2));
  const double middle = 0.14, width = 0.06;
  const double T_demo[16] = {-1, 0, 0, middle + 0.02, 0, 1, 0, 0.155, 0, 0, -1, 0.015,
                             0, 0, 0, 1};
  enum { NQ = 100 };
  float p[NQ * 3];
  double mean[3], size[3];
  ASSERT_OK(fg_grasp_query_box_default(FG_GRIPPER_ROBOTIQ_2F85, width, mean, size));
  ASSERT_OK(fg_grasp_query_points_box(NQ, mean, size, p));
  float *Z = malloc((size_t)NQ * s.D * sizeof *Z);
  ASSERT(Z);
  ASSERT_OK(fg_grasp_sample(gf, T_demo, p, NQ, Z));
  const fg_grasp_target t = {NQ, s.D, p, Z, NULL};

  fg_grasp_options o;
  for (int centred = 0; centred < 2; centred++) {
    fg_grasp_options_default(&o);
    o.gripper = FG_GRIPPER_ROBOTIQ_2F85;
    o.width_m = width;
    o.top_k = 4;
    o.n_threads = 2;
    if (!centred) o.centre_m = 0;
    fg_grasp_result r;
    ASSERT_OK(fg_grasp_search(gf, &t, &o, &r));
    ASSERT(r.n >= 1);
    int along_bar = 0;
    for (int k = 0; k < r.n; k++) {
      const double *T = r.poses[k].T_world_gripper;
      const int along = fabs(T[0]) > 0.9; /* the pads' width along the bar */
      printf("centring %s: %d: score %.4f, %.1f mm along the bar from its middle%s\n",
             centred ? "on " : "off", k, r.poses[k].score, 1e3 * (T[3] - middle),
             along ? ", the pads' width along it" : "");
      if (!along) continue;
      along_bar++;
      if (centred) ASSERT(fabs(T[3] - middle) <= 0.004);
    }
    ASSERT(along_bar >= 1);
    if (centred) ASSERT(fabs(r.poses[0].T_world_gripper[3] - middle) <= 0.004);
    fg_grasp_result_release(&r);
  }
  /* refused: a negative or huge stretch */
  fg_grasp_result r;
  o.centre_m = -0.01;
  ASSERT_ERR(fg_grasp_search(gf, &t, &o, &r), FG_EINVAL, "centre_m");
  o.centre_m = 1;
  ASSERT_ERR(fg_grasp_search(gf, &t, &o, &r), FG_EINVAL, "centre_m");
  free(Z);
  fg_grasp_field_free(gf);
  fg_voxel_features_free(vf);
  synth_free(&s);
}

int main(void) {
  test_query_points();
  test_query_points_box();
  test_gripper();
  test_gripper_ring();
  test_so3();
  test_cost();
  test_search_synthetic();
  test_search_centring();
  printf("grasp_unit: ok\n");
  return 0;
}
