/* Unit tests of lib/calib/calibrate on synthetic views: a known camera (intrinsics, OpenCV
 * distortion) on a known mount looks at a known board from robot poses around it; the
 * corners are projected, 0.1 px of noise added, the robot's poses rounded to its registers
 * (0.1 mm, 1 mrad). The intrinsics come back within 0.5 % and 1 px, the mount within 1 mm
 * and 0.2 degrees (SPEC's tests' bounds), for a camera on the hand and a fixed one; too few
 * views and rotations about one axis are refused with what to do. */
#include "test.h"

#include <math.h>

#include "calib/calibrate.h"
#include "core/error.h"
#include "core/pose.h"
#include "core/rng.h"

static const fg_intrinsics k_true = {640, 480, 610, 605, 322.4, 236.8, {-0.08, 0.02, 0.001, -0.0015}};
static fg_charuco_board g_board;
static uint64_t g_draw;

static double uniform(double lo, double hi) { return lo + (hi - lo) * fg_rng_uniform(7, g_draw++); }

static double gauss(double sigma) {
  const double u = uniform(1e-12, 1), v = uniform(0, 1);
  return sigma * sqrt(-2 * log(u)) * cos(2 * M_PI * v);
}

static void pose(double x, double y, double z, const double axis[3], double deg, double T[16]) {
  const double n = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  const double rv[3] = {axis[0] / n * deg * M_PI / 180, axis[1] / n * deg * M_PI / 180,
                        axis[2] / n * deg * M_PI / 180};
  double R[9];
  const double p[3] = {x, y, z};
  fg_rotmat_from_rotvec(rv, R);
  fg_pose_from_rotmat(R, p, T);
}

/* A camera at eye looking at target (OpenCV: +z forward, +y down), rolled by roll degrees. */
static void look_at(const double eye[3], const double target[3], double roll, double T[16]) {
  fg_pose_look_at(eye, target, roll * M_PI / 180, T);
}

/* The corners of the board at T_cam_board as the true camera sees them, with noise; the
 * view's arrays are static per slot. */
static fg_calib_view project_view(const double T_cam_board[16], int slot) {
  static int ids[64][24];
  static double px[64][48];
  fg_calib_view v = {0, ids[slot], px[slot]};
  for (int id = 0; id < fg_charuco_corner_count(&g_board); id++) {
    double cb[3], cc[3];
    fg_charuco_corner(&g_board, id, cb);
    fg_pose_apply(T_cam_board, cb, cc);
    if (cc[2] <= 0) continue;
    const double x = cc[0] / cc[2], y = cc[1] / cc[2], r2 = x * x + y * y;
    const double *k = k_true.k, radial = 1 + k[0] * r2 + k[1] * r2 * r2;
    const double xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x);
    const double yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y;
    const double u = k_true.fx * xd + k_true.cx + gauss(0.1), w = k_true.fy * yd + k_true.cy + gauss(0.1);
    if (u < 0 || w < 0 || u > k_true.w - 1 || w > k_true.h - 1) continue;
    ids[slot][v.n] = id;
    px[slot][2 * v.n] = u;
    px[slot][2 * v.n + 1] = w;
    v.n++;
  }
  return v;
}

/* A robot pose as its registers report it: 0.1 mm and 1 mrad. */
static void registers(const double T[16], double out[16]) {
  double R[9], rv[3], p[3] = {round(T[3] * 1e4) / 1e4, round(T[7] * 1e4) / 1e4,
                              round(T[11] * 1e4) / 1e4};
  fg_pose_get_rotmat(T, R);
  fg_rotvec_from_rotmat(R, rv);
  for (int k = 0; k < 3; k++) rv[k] = round(rv[k] * 1e3) / 1e3;
  fg_rotmat_from_rotvec(rv, R);
  fg_pose_from_rotmat(R, p, out);
}

static double dist_mm(const double A[16], const double B[16]) {
  return sqrt((A[3] - B[3]) * (A[3] - B[3]) + (A[7] - B[7]) * (A[7] - B[7]) +
              (A[11] - B[11]) * (A[11] - B[11])) * 1e3;
}

#define N_VIEWS 20

/* A camera on the hand looking at a board on the table from poses on a cap above it. */
static void test_hand(void) {
  double T_tcp_cam[16], T_base_board[16], T_cam_tcp[16];
  pose(0.03, -0.02, -0.06, (double[3]){1, 0.2, 0}, 5, T_tcp_cam);
  pose(0.30, -0.22, 0, (double[3]){0, 0, 1}, 15, T_base_board);
  fg_pose_inverse(T_tcp_cam, T_cam_tcp);
  const double centre_b[3] = {0.105, 0.075, 0};
  double centre[3];
  fg_pose_apply(T_base_board, centre_b, centre);
  double T_base_tcp[N_VIEWS][16], T_reg[N_VIEWS][16], T_cb[N_VIEWS][16];
  fg_calib_view views[N_VIEWS];
  for (int i = 0; i < N_VIEWS; i++) {
    const double az = uniform(0, 2 * M_PI), el = uniform(50, 85) * M_PI / 180;
    const double r = uniform(0.28, 0.42);
    const double eye[3] = {centre[0] + r * cos(el) * cos(az), centre[1] + r * cos(el) * sin(az),
                           centre[2] + r * sin(el)};
    const double aim[3] = {centre[0] + uniform(-0.03, 0.03), centre[1] + uniform(-0.03, 0.03),
                           centre[2]};
    double T_base_cam[16], T_cam_base[16];
    look_at(eye, aim, uniform(-30, 30), T_base_cam);
    fg_pose_compose(T_base_cam, T_cam_tcp, T_base_tcp[i]);
    registers(T_base_tcp[i], T_reg[i]);
    fg_pose_inverse(T_base_cam, T_cam_base);
    double T_true_cb[16];
    fg_pose_compose(T_cam_base, T_base_board, T_true_cb);
    views[i] = project_view(T_true_cb, i);
  }
  fg_intrinsics in;
  double rms, per_view[N_VIEWS];
  ASSERT_EQ(fg_calibrate_intrinsics(&g_board, views, N_VIEWS, 640, 480, &in, &rms, per_view), 0);
  fprintf(stderr, "intrinsics: fx %.2f fy %.2f cx %.2f cy %.2f k %.4f %.4f %.5f %.5f rms %.3f\n",
          in.fx, in.fy, in.cx, in.cy, in.k[0], in.k[1], in.k[2], in.k[3], rms);
  ASSERT(fabs(in.fx / k_true.fx - 1) < 0.005 && fabs(in.fy / k_true.fy - 1) < 0.005);
  ASSERT(fabs(in.cx - k_true.cx) < 1 && fabs(in.cy - k_true.cy) < 1);
  ASSERT(rms > 0.05 && rms < 0.2); /* the noise's 0.1 px, per coordinate */
  for (int i = 0; i < N_VIEWS; i++) ASSERT(isnan(per_view[i]) || per_view[i] < 0.3);

  int n = 0;
  double T_base_tcp_used[N_VIEWS * 16], T_cb_used[N_VIEWS * 16];
  for (int i = 0; i < N_VIEWS; i++) {
    double e;
    if (fg_calib_board_pose(&g_board, &views[i], &in, T_cb[i], &e) != 0) continue;
    memcpy(T_base_tcp_used + 16 * n, T_reg[i], sizeof T_reg[i]);
    memcpy(T_cb_used + 16 * n, T_cb[i], sizeof T_cb[i]);
    n++;
  }
  ASSERT(n >= 16);
  fg_hand_eye_result res[FG_HAND_EYE_METHODS];
  int best = -1;
  ASSERT_EQ(fg_calibrate_hand_eye(T_base_tcp_used, T_cb_used, n, 0, res, &best), 0);
  for (int m = 0; m < FG_HAND_EYE_METHODS; m++)
    if (res[m].ok)
      fprintf(stderr, "  %-10s %.3f mm %.4f deg from the mount; the board's pose spread %.3f mm "
              "%.4f deg\n", fg_hand_eye_method_name(m), dist_mm(res[m].T, T_tcp_cam),
              fg_pose_angle_rad(res[m].T, T_tcp_cam) * 180 / M_PI, res[m].spread_mm,
              res[m].spread_deg);
  ASSERT(best >= 0 && res[best].ok);
  ASSERT(dist_mm(res[best].T, T_tcp_cam) < 3);
  ASSERT(res[best].spread_mm < 2);

  /* refined on every corner, the intrinsics with it: within SPEC's bounds */
  fg_calib_view used_views[N_VIEWS];
  for (int i = 0, u = 0; i < N_VIEWS; i++) {
    double e, T[16];
    if (fg_calib_board_pose(&g_board, &views[i], &in, T, &e) == 0) used_views[u++] = views[i];
  }
  double X[16], B[16], rms_ref;
  memcpy(X, res[best].T, sizeof X);
  memcpy(B, res[best].T_fixed, sizeof B);
  ASSERT_EQ(fg_calibrate_hand_eye_refine(&g_board, used_views, T_base_tcp_used, n, 0, 1, &in, X,
                                         B, &rms_ref), 0);
  fprintf(stderr, "refined: %.3f mm %.4f deg from the mount, fx %.2f fy %.2f cx %.2f cy %.2f, "
          "rms %.3f px\n", dist_mm(X, T_tcp_cam), fg_pose_angle_rad(X, T_tcp_cam) * 180 / M_PI,
          in.fx, in.fy, in.cx, in.cy, rms_ref);
  ASSERT(dist_mm(X, T_tcp_cam) < 1);
  ASSERT(fg_pose_angle_rad(X, T_tcp_cam) * 180 / M_PI < 0.2);
  ASSERT(dist_mm(B, T_base_board) < 1);
  ASSERT(fabs(in.fx / k_true.fx - 1) < 0.005 && fabs(in.cx - k_true.cx) < 1);
  ASSERT(rms_ref < 0.25);

  /* too few poses; rotations about one axis only */
  ASSERT_EQ(fg_calibrate_hand_eye(T_base_tcp_used, T_cb_used, 7, 0, res, &best), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "needs 8"));
  double T_one[8 * 16], T_one_cb[8 * 16];
  for (int i = 0; i < 8; i++) {
    pose(0.4 + 0.01 * i, 0, 0.3, (double[3]){1, 0, 0}, 180 - 4 * i, T_one + 16 * i);
    memcpy(T_one_cb + 16 * i, T_cb_used, sizeof T_cb[0]);
  }
  ASSERT_EQ(fg_calibrate_hand_eye(T_one, T_one_cb, 8, 0, res, &best), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "about one axis"));
  /* too few views for intrinsics */
  ASSERT_EQ(fg_calibrate_intrinsics(&g_board, views, 3, 640, 480, &in, &rms, NULL), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "need 4"));

  /* a view whose corners lie on one line (a whole row of the board, 6 corners) is left out
   * of the intrinsics, and gives no board pose; OpenCV would throw on it */
  const int per_row = g_board.squares_x - 1;
  static int row_ids[8];
  static double row_px[16];
  fg_calib_view all[N_VIEWS + 1], row = {0, row_ids, row_px};
  for (int i = 0; i < N_VIEWS && row.n < per_row; i++) {
    row.n = 0;
    for (int k = 0; k < views[i].n; k++)
      if (views[i].ids[k] / per_row == 1) {
        row_ids[row.n] = views[i].ids[k];
        row_px[2 * row.n] = views[i].px[2 * k];
        row_px[2 * row.n + 1] = views[i].px[2 * k + 1];
        row.n++;
      }
  }
  ASSERT_EQ(row.n, per_row);
  memcpy(all, views, sizeof views);
  all[N_VIEWS] = row;
  double per_all[N_VIEWS + 1];
  ASSERT_EQ(fg_calibrate_intrinsics(&g_board, all, N_VIEWS + 1, 640, 480, &in, &rms, per_all), 0);
  ASSERT(isnan(per_all[N_VIEWS]));
  double T_row[16], e;
  ASSERT_EQ(fg_calib_board_pose(&g_board, &row, &in, T_row, &e), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "one line"));
}

static fg_calib_view g_fixed_views[12];

/* A fixed camera watching a board the tool holds. */
static void test_fixed(void) {
  double T_base_cam[16], T_tcp_board[16], T_cam_base[16];
  const double eye[3] = {0.9, 0.4, 0.6}, at[3] = {0.4, 0, 0.25};
  look_at(eye, at, 3, T_base_cam);
  pose(0.0, -0.105, 0.02, (double[3]){0, 1, 0}, 180, T_tcp_board); /* face down the tool */
  fg_pose_inverse(T_base_cam, T_cam_base);
  double T_reg[12 * 16], T_cb[12 * 16];
  int n = 0;
  for (int i = 0; i < 12; i++) {
    /* the tool shows the board to the camera: its -z towards it, tilted about varied axes */
    double T_face[16], T_tilt[16], T_base_tcp[16], T_cb_true[16], T_tmp[16];
    look_at((double[3]){0.4 + uniform(-0.08, 0.08), uniform(-0.08, 0.08), 0.25 + uniform(-0.05, 0.05)},
            eye, uniform(-40, 40), T_face); /* a frame whose +z looks at the camera */
    pose(0, 0, 0, (double[3]){uniform(-1, 1), uniform(-1, 1), 0}, uniform(5, 20), T_tilt);
    fg_pose_compose(T_face, T_tilt, T_tmp);
    double T_board_tcp[16], T_flip[16];
    /* the board's face (its -z, charuco.h) towards the camera: board z away from it */
    pose(0, 0, 0, (double[3]){1, 0, 0}, 180, T_flip);
    double T_base_board[16];
    fg_pose_compose(T_tmp, T_flip, T_base_board);
    if (fg_charuco_face_z(&g_board) > 0) memcpy(T_base_board, T_tmp, sizeof T_tmp);
    fg_pose_inverse(T_tcp_board, T_board_tcp);
    fg_pose_compose(T_base_board, T_board_tcp, T_base_tcp);
    registers(T_base_tcp, T_reg + 16 * n);
    fg_pose_compose(T_cam_base, T_base_board, T_cb_true);
    fg_calib_view v = project_view(T_cb_true, 40 + i);
    double e;
    if (fg_calib_board_pose(&g_board, &v, &k_true, T_cb + 16 * n, &e) == 0) g_fixed_views[n++] = v;
  }
  ASSERT(n >= 10);
  fg_hand_eye_result res[FG_HAND_EYE_METHODS];
  int best = -1;
  ASSERT_EQ(fg_calibrate_hand_eye(T_reg, T_cb, n, 1, res, &best), 0);
  fprintf(stderr, "fixed: %s %.3f mm %.4f deg; the held board's pose spread %.3f mm\n",
          fg_hand_eye_method_name(best), dist_mm(res[best].T, T_base_cam),
          fg_pose_angle_rad(res[best].T, T_base_cam) * 180 / M_PI, res[best].spread_mm);
  ASSERT(dist_mm(res[best].T, T_base_cam) < 10);
  double X[16], B[16], rms_ref;
  fg_intrinsics in = k_true;
  memcpy(X, res[best].T, sizeof X);
  memcpy(B, res[best].T_fixed, sizeof B);
  ASSERT_EQ(fg_calibrate_hand_eye_refine(&g_board, g_fixed_views, T_reg, n, 1, 0, &in, X, B,
                                         &rms_ref), 0);
  fprintf(stderr, "refined: %.3f mm %.4f deg, rms %.3f px\n", dist_mm(X, T_base_cam),
          fg_pose_angle_rad(X, T_base_cam) * 180 / M_PI, rms_ref);
  ASSERT(dist_mm(X, T_base_cam) < 1);
  ASSERT(fg_pose_angle_rad(X, T_base_cam) * 180 / M_PI < 0.2);
  ASSERT(dist_mm(B, T_tcp_board) < 1);
}

int main(void) {
  g_board = (fg_charuco_board){7, 5, 0.03, 0.022, 0};
  ASSERT_EQ(fg_charuco_dictionary_parse("DICT_5X5_100", &g_board.dictionary), 0);
  test_hand();
  test_fixed();
  printf("calibrate: ok\n");
  return 0;
}
