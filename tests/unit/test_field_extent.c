/* fg_field_extent_choose (field/extent.h): the field's cube and background from what the
 * frames show: a tabletop cell keeps scale 2 without a learned background, whether its
 * cameras stand near (colour only) or 2 m away (depth on the table); cameras around an
 * object in a room (instant-ngp's fox geometry) or depth on a far wall call for a larger
 * cube and a learned background. */
#include "test.h"

#include "core/pose.h"
#include "field/extent.h"

static const double ws_min[3] = {0.10, -0.45, 0.005}, ws_max[3] = {0.80, 0.45, 0.35};

/* A 64 x 48 PINHOLE frame at eye looking at target (OpenGL convention, as fg_frame). */
static void frame_at(fg_frame *f, const double eye[3], const double target[3]) {
  memset(f, 0, sizeof *f);
  double T[16];
  fg_pose_look_at(eye, target, 0.0, T);
  for (int r = 0; r < 3; r++) { /* OpenCV's y down, z forward -> OpenGL's y up, z back */
    T[4 * r + 1] = -T[4 * r + 1];
    T[4 * r + 2] = -T[4 * r + 2];
  }
  memcpy(f->T_world_cam, T, sizeof T);
  f->cam = (fg_camera){.fl_x = 60, .fl_y = 60, .cx = 32, .cy = 24, .w = 64, .h = 48};
}

/* Gives f a depth map: each pixel's ray meets the plane n . p = d (0 where it does not, or
 * where keep() refuses the hit). */
static void depth_on_plane(fg_frame *f, const double n[3], double d,
                           int (*keep)(const double p[3])) {
  f->depth_w = f->cam.w;
  f->depth_h = f->cam.h;
  f->depth = calloc((size_t)f->cam.w * (size_t)f->cam.h, sizeof *f->depth);
  ASSERT(f->depth);
  const double *T = f->T_world_cam, eye[3] = {T[3], T[7], T[11]};
  for (int v = 0; v < f->cam.h; v++)
    for (int u = 0; u < f->cam.w; u++) {
      const double c[3] = {(u + 0.5 - f->cam.cx) / f->cam.fl_x,
                           -(v + 0.5 - f->cam.cy) / f->cam.fl_y, -1.0};
      double w[3], nw = 0, ne = 0;
      for (int k = 0; k < 3; k++) {
        w[k] = T[4 * k] * c[0] + T[4 * k + 1] * c[1] + T[4 * k + 2] * c[2];
        nw += n[k] * w[k];
        ne += n[k] * eye[k];
      }
      const double t = nw != 0 ? (d - ne) / nw : -1; /* z-depth: c's z component is -1 */
      const double p[3] = {eye[0] + t * w[0], eye[1] + t * w[1], eye[2] + t * w[2]};
      if (t > 0 && keep(p)) f->depth[(size_t)v * (size_t)f->cam.w + (size_t)u] = (float)t;
    }
}

static int on_table(const double p[3]) { return fabs(p[0] - 0.45) <= 0.6 && fabs(p[1]) <= 0.7; }
static int anywhere(const double p[3]) { (void)p; return 1; }

/* n cameras on a ring of radius r at height z around (cx, 0, 0), looking at (cx, 0, 0.1). */
static void ring(fg_frame *f, int n, double cx, double r, double z) {
  const double target[3] = {cx, 0, 0.1};
  for (int i = 0; i < n; i++) {
    const double a = 2 * M_PI * i / n, eye[3] = {cx + r * cos(a), r * sin(a), z};
    frame_at(&f[i], eye, target);
  }
}

static void free_frames(fg_frame *f, int n) {
  for (int i = 0; i < n; i++) free(f[i].depth);
}

int main(void) {
  fg_frame f[12] = {0};
  fg_field_extent e;

  /* no frames: the cell's field */
  fg_field_extent_choose(ws_min, ws_max, f, 0, &e);
  ASSERT(e.field_scale == 2.0 && !e.learn_background && e.points == 0);

  /* colour only, cameras 0.8 m around the workspace's centre (scenegen's hemisphere): the
   * cube of scale 2 (0.9 m each way) holds them */
  ring(f, 12, 0.45, 0.75, 0.6);
  fg_field_extent_choose(ws_min, ws_max, f, 12, &e);
  ASSERT(e.field_scale == 2.0 && !e.learn_background && !e.from_depth);
  ASSERT_EQ(e.points, 12);
  ASSERT(e.outside_share == 0.0);

  /* colour only, the fox's geometry: a workspace of +-1.5 m, cameras 3.8 to 5.9 m from its
   * centre on each axis at most: scale 4 (6 m each way), learned background */
  const double fmin_[3] = {-1.5, -1.5, -1.5}, fmax_[3] = {1.5, 1.5, 1.5};
  ring(f, 12, 0.0, 5.9, 2.8);
  fg_field_extent_choose(fmin_, fmax_, f, 12, &e);
  ASSERT(e.field_scale == 4.0 && e.learn_background && !e.from_depth);
  ASSERT(e.outside_share == 1.0);
  ring(f, 12, 0.0, 6.1, 0.0); /* just beyond 4's cube: 8 */
  fg_field_extent_choose(fmin_, fmax_, f, 12, &e);
  ASSERT(e.field_scale == 8.0 && e.learn_background);
  ring(f, 12, 0.0, 1e4, 0.0); /* beyond every cube: the largest */
  fg_field_extent_choose(fmin_, fmax_, f, 12, &e);
  ASSERT(e.field_scale == 64.0 && e.learn_background);

  /* RGB-D, a robot's scan 2 m away (outside the cube of scale 2) that sees the table: the
   * depth decides, the cell's field */
  ring(f, 12, 0.45, 1.8, 0.9);
  const double up[3] = {0, 0, 1};
  for (int i = 0; i < 12; i++) depth_on_plane(&f[i], up, 0.0, on_table);
  fg_field_extent_choose(ws_min, ws_max, f, 12, &e);
  ASSERT(e.field_scale == 2.0 && !e.learn_background && e.from_depth);
  printf("scan: %zu hits, %.2f outside the cube of 2\n", e.points, e.outside_share);
  ASSERT(e.points > 400);
  ASSERT(e.outside_share <= FG_FIELD_EXTENT_NEED_SHARE);
  /* ... and the same scan with frames in header only (no depth values): by the cameras */
  for (int i = 0; i < 12; i++) f[i].depth = (free(f[i].depth), NULL);
  fg_field_extent_choose(ws_min, ws_max, f, 12, &e);
  ASSERT(!e.from_depth && e.field_scale == 4.0 && e.learn_background);

  /* RGB-D looking across a room at a wall 6 m away: beyond the cube of 2, learned
   * background, and a cube that holds all but 5 % of the hits */
  const double wall_n[3] = {1, 0, 0};
  for (int i = 0; i < 4; i++) {
    const double eye[3] = {0.45, -0.3 + 0.2 * i, 0.6}, target[3] = {3.0, -0.3 + 0.2 * i, 0.6};
    frame_at(&f[i], eye, target);
    depth_on_plane(&f[i], wall_n, 6.45, anywhere);
  }
  fg_field_extent_choose(ws_min, ws_max, f, 4, &e);
  printf("wall: scale %g, learned background %d, %zu hits, %.2f outside the cube of 2\n",
         e.field_scale, e.learn_background, e.points, e.outside_share);
  ASSERT(e.from_depth && e.learn_background && e.outside_share == 1.0);
  /* every hit is at x = 6.45, 6 m from the centre: 2 * 6 / 0.9 = 13.3 -> at least 16 */
  ASSERT(e.field_scale >= 16.0 && e.field_scale <= 64.0);
  size_t inside = 0, total = 0;
  const double half = 0.5 * e.field_scale * 0.9, centre[3] = {0.45, 0, 0.1775};
  for (int i = 0; i < 4; i++) {
    const double *T = f[i].T_world_cam;
    for (int v = FG_FIELD_EXTENT_STRIDE / 2; v < f[i].depth_h; v += FG_FIELD_EXTENT_STRIDE)
      for (int u = FG_FIELD_EXTENT_STRIDE / 2; u < f[i].depth_w; u += FG_FIELD_EXTENT_STRIDE) {
        const double z = f[i].depth[(size_t)v * 64 + (size_t)u];
        const double c[3] = {z * (u + 0.5 - 32) / 60, -z * (v + 0.5 - 24) / 60, -z};
        int in = 1;
        for (int k = 0; k < 3; k++)
          in &= fabs(T[4 * k] * c[0] + T[4 * k + 1] * c[1] + T[4 * k + 2] * c[2] + T[4 * k + 3] -
                     centre[k]) <= half;
        inside += in;
        total++;
      }
  }
  ASSERT_EQ(total, e.points);
  ASSERT(inside >= (1 - FG_FIELD_EXTENT_FAR_SHARE) * total);
  const double half_smaller = 0.25 * e.field_scale * 0.9; /* and the next smaller would not */
  ASSERT(6.0 > half_smaller || e.field_scale == 2.0);
  free_frames(f, 4);
  printf("ok\n");
  return 0;
}
