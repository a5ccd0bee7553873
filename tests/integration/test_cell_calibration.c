/* Calibration from a bare cell, over HTTP, against the simulator's camera: a mount, intrinsics
 * and distortion that fieldgripd is not told, a ChArUco board on the table. The robot is moved
 * (POST /v1/robot/commands) through views of the board; each capture with
 * "calibration_view" keeps its corners, and so does each view uploaded with its robot pose
 * (POST /v1/cameras/{c}/views; every other view comes that way, and a view upload's bad
 * requests are refused with nothing kept); the intrinsics come back within 0.5 % (focal) and
 * 1 px (principal point), the mount within 1 mm and 0.2 degrees; a capture then gives the
 * camera's pose. Refusals: no views, too few, a degenerate motion (SPEC's bad input). Then the
 * eye-to-hand case: a fixed camera, the board held by the tool, T_base_cam within the same
 * bounds, from views the test moves and captures, then from views the robot takes itself
 * ("drive": the tool shows the camera the board).
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "cell_util.h"
#include "robot_util.h"
#include "training.h"

#include "core/pose.h"
#include "core/rng.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The truth, on the simulator's command line only. */
#define CAMERA "612 607 324.3 236.1 640 480 -0.09 0.03 0.0008 -0.0012"
static const double K_TRUE[4] = {612, 607, 324.3, 236.1};
/* 4 cm to the side of the TCP, 7 cm back along the tool, turned 4 degrees about x and 3
 * about y: (qw qx qy qz) of that turn */
#define MOUNT "0.04 -0.015 -0.07 0.9989 0.0349 0.0262 0.0009"
static const double MOUNT_P[3] = {0.04, -0.015, -0.07};
static const double MOUNT_Q[4] = {0.9989, 0.0349, 0.0262, 0.0009};
#define BOARD "7 5 0.03 0.022 DICT_5X5_100 0.32 -0.20 0.0 15"

/* ---------------------------------------------------------------- aiming */

/* The TCP pose that puts the camera (true mount) at eye looking at target, rolled. */
static void tcp_for_view(const double eye[3], const double target[3], double roll_deg,
                         double p[3], double q[4]) {
  double q_cam[4], T_bc[16], T_tc[16], T_ct[16], T_bt[16];
  cu_look_at(eye, target, roll_deg, q_cam);
  ASSERT_EQ(fg_pose_from_quat(eye, q_cam, T_bc), 0);
  ASSERT_EQ(fg_pose_from_quat(MOUNT_P, MOUNT_Q, T_tc), 0);
  fg_pose_inverse(T_tc, T_ct);
  fg_pose_compose(T_bc, T_ct, T_bt); /* T_base_tcp = T_base_cam * inverse(T_tcp_cam) */
  fg_pose_to_quat(T_bt, p, q);
}

/* ---------------------------------------------------------------- requests */

static void move_to(const double p[3], const double q[4]) {
  char body[512];
  snprintf(body, sizeof body, "{\"command\": \"move\", \"pose\": {\"position\": [%.5f, %.5f, "
           "%.5f], \"quaternion\": [%.7f, %.7f, %.7f, %.7f]}, \"approach\": 0}",
           p[0], p[1], p[2], q[0], q[1], q[2], q[3]);
  h_resp *r = r_post("/v1/robot/commands", body, NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  h_resp_free(r);
}

static const char *g_cam = "wrist"; /* the camera the helpers below use */

/* Starts fieldgripd on the simulator at sim_port with the board of BOARD and the cameras of
 * the text cameras, and waits for the robot. */
static void start_daemon(int sim_port, const char *cameras) {
  char *conf = h_fmt("[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = 5000\n"
                     "limit_min = -1 -1 0.02\nlimit_max = 1 1 1\napproach_cone_deg = 180\n"
                     "[calibration]\nsquares_x = 7\nsquares_y = 5\nsquare_m = 0.03\n"
                     "marker_m = 0.022\ndictionary = DICT_5X5_100\n%s",
                     sim_port, cameras);
  h_write_config(conf);
  free(conf);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
}

/* Keeps a calibration view and returns the board corners it shows: every other one as
 * fieldgripd captures it ("calibration_view"), the others as a robot stack that moves the
 * robot itself would give it: captured plainly, then uploaded to POST /v1/cameras/{c}/views
 * with the TCP pose read with it. */
static int capture_view(void) {
  static int n;
  char path[128];
  snprintf(path, sizeof path, "/v1/cameras/%s/capture", g_cam);
  const int upload = n++ % 2;
  h_resp *r = h_post_json(path, upload ? "" : "{\"calibration_view\": true}");
  ASSERT_STATUS(r, 200);
  if (!upload) {
    const int corners = (int)json_integer_value(json_object_get(r->json, "board_corners"));
    h_resp_free(r);
    return corners;
  }
  size_t len;
  uint8_t *png = cu_unbase64(json_string_value(json_object_get(r->json, "image")), &len);
  char *pose = json_dumps(json_object_get(r->json, "robot_pose"), JSON_COMPACT);
  char *meta = h_fmt("{\"robot_pose\": %s}", pose);
  h_resp_free(r);
  snprintf(path, sizeof path, "/v1/cameras/%s/views", g_cam);
  r = h_upload(path, png, len, meta, NULL, 0);
  int corners = 0;
  if (r->status == 422) {
    ASSERT_HTTP_ERROR(r, 422, "board_not_found");
  } else {
    ASSERT_STATUS(r, 201);
    corners = (int)json_integer_value(json_object_get(r->json, "board_corners"));
  }
  h_resp_free(r);
  free(meta), free(pose), free(png);
  return corners;
}

/* A view upload's bad requests: each refused, nothing kept. */
static void bad_view_uploads(void) {
  h_resp *r = h_get("/v1/cameras/wrist");
  const json_int_t before = json_integer_value(json_object_get(r->json, "views_kept"));
  h_resp_free(r);
  static const char pose[] = "{\"robot_pose\": {\"position\": [0.3, 0, 0.4], "
                             "\"quaternion\": [0, 1, 0, 0]}}";
  uint8_t *noise;
  size_t noise_len;
  h_png(64, 48, 3, 8, 7, 1, &noise, &noise_len);
  r = h_upload("/v1/cameras/wrist/views", noise, noise_len, NULL, NULL, 0);
  ASSERT_HTTP_ERROR(r, 400, "missing_part");
  h_resp_free(r);
  r = h_upload("/v1/cameras/wrist/views", noise, noise_len, "{\"robot_pose\": [1, 2]}", NULL, 0);
  ASSERT_HTTP_ERROR(r, 400, "invalid_pose");
  h_resp_free(r);
  r = h_upload("/v1/cameras/wrist/views", noise, noise_len, "{\"pose\": 1}", NULL, 0);
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  r = h_upload("/v1/cameras/wrist/views", "not an image", 12, pose, NULL, 0);
  ASSERT_HTTP_ERROR(r, 400, "invalid_image");
  h_resp_free(r);
  r = h_upload("/v1/cameras/wrist/views", noise, noise_len, pose, NULL, 0);
  ASSERT_HTTP_ERROR(r, 422, "board_not_found");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "shows 0 of the board's corners");
  h_resp_free(r);
  r = h_upload("/v1/cameras/nocam/views", noise, noise_len, pose, NULL, 0);
  ASSERT_HTTP_ERROR(r, 404, "camera_not_found");
  h_resp_free(r);
  r = h_get("/v1/cameras/wrist");
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "views_kept")), before);
  h_resp_free(r);
  free(noise);
}

static h_resp *calibrate(const char *kind) {
  char body[64], path[128];
  snprintf(body, sizeof body, "{\"kind\": \"%s\"}", kind);
  snprintf(path, sizeof path, "/v1/cameras/%s/calibrate", g_cam);
  return h_post_json(path, body);
}

/* How far a pose's view ({"position", "quaternion"}) is from the truth p, q: mm, degrees. */
static void pose_error(json_t *pose, const double p[3], const double q[4], double *mm,
                       double *deg) {
  json_t *mp = json_object_get(pose, "position"), *mq = json_object_get(pose, "quaternion");
  double dp = 0, got_q[4];
  for (int k = 0; k < 3; k++) dp += pow(json_real_value(json_array_get(mp, (size_t)k)) - p[k], 2);
  for (int k = 0; k < 4; k++) got_q[k] = json_real_value(json_array_get(mq, (size_t)k));
  *mm = sqrt(dp) * 1e3;
  *deg = fg_quat_angle_rad(got_q, q) * 180 / M_PI;
}

static double num(json_t *o, const char *k) { return json_number_value(json_object_get(o, k)); }

static void fixed_camera(void);
static void audit_count(const char *route, const char *id, int *moves, int *requests);

/* A camera on the hand, the board on the table. */
static void hand_camera(void) {
  simproc sim;
  const char *args[] = {"--camera", CAMERA, "--camera-mount", MOUNT, "--board", BOARD, NULL};
  char *cameras = h_fmt("[camera wrist]\nsource = http://127.0.0.1:%d/rgb.png\n",
                        cu_sim_start(&sim, args));
  start_daemon(sim.port, cameras);
  free(cameras);

  /* nothing kept yet */
  h_resp *r = calibrate("intrinsics");
  ASSERT_HTTP_ERROR(r, 400, "not_enough_views");
  h_resp_free(r);
  bad_view_uploads();

  /* the board's centre: its frame at (0.32, -0.20) turned 15 degrees, 0.21 x 0.15 m */
  const double yaw = 15 * M_PI / 180, bx = 0.105, by = 0.075;
  /* the board's y runs one way or the other with OpenCV's convention: aim at the middle of
   * both candidates' centres, 7.5 cm either side, which keeps the board in view */
  const double centre[3] = {0.32 + bx * cos(yaw), -0.20 + bx * sin(yaw), 0};
  (void)by;
  int kept = 0;
  for (int i = 0; i < 16; i++) {
    const double az = 2 * M_PI * i / 16 + 0.3 * (i % 3), el = (55 + 25 * ((i * 7) % 5) / 4.0) * M_PI / 180;
    const double dist = 0.30 + 0.08 * ((i * 3) % 4) / 3.0, roll = -30 + 60 * ((i * 5) % 7) / 6.0;
    const double eye[3] = {centre[0] + dist * cos(el) * cos(az), centre[1] + dist * cos(el) * sin(az),
                           dist * sin(el)};
    double p[3], q[4];
    tcp_for_view(eye, centre, roll, p, q);
    move_to(p, q);
    kept += capture_view() >= 6;
  }
  fprintf(stderr, "%d of 16 views show the board\n", kept);
  ASSERT(kept >= 12);

  /* hand-eye before the intrinsics: refused, the views stay */
  r = calibrate("hand_eye");
  ASSERT_HTTP_ERROR(r, 409, "not_calibrated");
  h_resp_free(r);

  r = calibrate("intrinsics");
  ASSERT_STATUS(r, 200);
  json_t *in = json_object_get(json_object_get(r->json, "camera"), "intrinsics");
  fprintf(stderr, "intrinsics: fx %.2f fy %.2f cx %.2f cy %.2f (truth %g %g %g %g)\n",
          num(in, "fl_x"), num(in, "fl_y"), num(in, "cx"), num(in, "cy"), K_TRUE[0], K_TRUE[1],
          K_TRUE[2], K_TRUE[3]);
  ASSERT(fabs(num(in, "fl_x") / K_TRUE[0] - 1) < 0.005);
  ASSERT(fabs(num(in, "fl_y") / K_TRUE[1] - 1) < 0.005);
  ASSERT(fabs(num(in, "cx") - K_TRUE[2]) < 1 && fabs(num(in, "cy") - K_TRUE[3]) < 1);
  h_resp_free(r);
  r = h_get("/v1/cameras/wrist");
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "views_kept")), 0); /* consumed */
  h_resp_free(r);

  /* the mount: a second round of views */
  kept = 0;
  for (int i = 0; i < 14; i++) {
    const double az = 2 * M_PI * i / 14 + 0.2, el = (50 + 30 * ((i * 3) % 5) / 4.0) * M_PI / 180;
    const double dist = 0.32 + 0.06 * (i % 3) / 2.0, roll = -35 + 70 * ((i * 4) % 7) / 6.0;
    const double eye[3] = {centre[0] + dist * cos(el) * cos(az), centre[1] + dist * cos(el) * sin(az),
                           dist * sin(el)};
    double p[3], q[4];
    tcp_for_view(eye, centre, roll, p, q);
    move_to(p, q);
    kept += capture_view() >= 6;
  }
  ASSERT(kept >= 10);
  r = calibrate("hand_eye");
  ASSERT_STATUS(r, 200);
  json_t *cam = json_object_get(r->json, "camera");
  ASSERT(json_is_true(json_object_get(cam, "calibrated")));
  double err_mm, err_deg;
  pose_error(json_object_get(cam, "T_tcp_cam"), MOUNT_P, MOUNT_Q, &err_mm, &err_deg);
  json_t *cal = json_object_get(json_object_get(cam, "calibration"), "mount");
  fprintf(stderr, "mount: %.3f mm, %.4f deg from the truth; spread %.3f mm %.4f deg, rms %.3f "
          "px (%s)\n", err_mm, err_deg, num(cal, "spread_mm"), num(cal, "spread_deg"),
          num(cal, "rms_px"), json_string_value(json_object_get(r->json, "refined_from")));
  ASSERT(err_mm < 1);
  ASSERT(err_deg < 0.2);
  ASSERT_EQ(json_array_size(json_object_get(r->json, "methods")), 5);
  h_resp_free(r);

  /* a capture now gives the camera's pose: the TCP's times the mount */
  r = h_post_json("/v1/cameras/wrist/capture", "");
  ASSERT_STATUS(r, 200);
  ASSERT(json_is_object(json_object_get(r->json, "camera_pose")));
  ASSERT(json_is_object(json_object_get(r->json, "intrinsics")));
  h_resp_free(r);

  /* bad input: too few views; rotations about one axis only */
  for (int i = 0; i < 3; i++) {
    double eye[3] = {centre[0] + 0.05 * i, centre[1] - 0.08, 0.35}, p[3], q[4];
    tcp_for_view(eye, centre, 0, p, q);
    move_to(p, q);
    capture_view();
  }
  r = calibrate("hand_eye");
  ASSERT_HTTP_ERROR(r, 400, "not_enough_views");
  h_resp_free(r);
  r = h_delete("/v1/cameras/wrist/views");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  for (int i = 0; i < 9; i++) { /* the camera rolled about its own axis, nothing else */
    const double eye[3] = {centre[0], centre[1] - 0.05, 0.33};
    double p[3], q[4];
    tcp_for_view(eye, centre, -40 + 10 * i, p, q);
    move_to(p, q);
    capture_view();
  }
  r = calibrate("hand_eye");
  ASSERT_HTTP_ERROR(r, 400, "degenerate_motion");
  ASSERT(strstr(json_string_value(json_object_get(json_object_get(r->json, "error"), "message")),
                "one axis"));
  h_resp_free(r);
  r = h_get("/v1/cameras/wrist"); /* the good calibration stays */
  ASSERT(json_is_true(json_object_get(r->json, "calibrated")));
  h_resp_free(r);

  h_stop();
  simproc_stop(&sim);
}

static void driven(void);

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  hand_camera();
  driven();
  fixed_camera();
  h_done();
  printf("ok\n");
  return 0;
}

/* ---------------------------------------------------------------- eye to hand */

/* A camera standing still, looking at where the robot shows it the board the tool holds. */
#define FIXED_EYE 0.80, 0.25, 0.48
#define FIXED_AT 0.45, 0.0, 0.25
/* the board 2 cm beyond the TCP, its printed face (its -z: OpenCV 4.6) along the tool's +z,
 * its centre on the tool's axis: half a turn about x */
#define BOARD_ON_TOOL "7 5 0.03 0.022 DICT_5X5_100 -0.105 0.075 0.02 0 1 0 0"

/* A TCP pose at p with the tool's +z towards the camera, tilted by tilt degrees about an axis
 * at angle phi across it, rolled by roll degrees. */
static void show_board(const double p[3], double tilt, double phi, double roll, double q[4]) {
  const double eye[3] = {FIXED_EYE};
  double q0[4], t[4];
  cu_look_at(p, eye, roll, q0);
  const double a = tilt * M_PI / 360;
  const double tq[4] = {cos(a), sin(a) * cos(phi), sin(a) * sin(phi), 0};
  fg_quat_multiply(q0, tq, t);
  const double n = sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2] + t[3] * t[3]);
  for (int k = 0; k < 4; k++) q[k] = t[k] / n;
}

static void fixed_camera(void) {
  const double eye[3] = {FIXED_EYE}, at[3] = {FIXED_AT};
  double qc[4];
  cu_look_at(eye, at, 0, qc);
  const double dist = sqrt(pow(at[0] - eye[0], 2) + pow(at[1] - eye[1], 2) + pow(at[2] - eye[2], 2));
  char cam_pose[128];
  snprintf(cam_pose, sizeof cam_pose, "%.6f %.6f %.6f %.9f %.9f %.9f %.9f", eye[0], eye[1],
           eye[2], qc[0], qc[1], qc[2], qc[3]);
  simproc sim;
  const char *args[] = {"--camera", CAMERA, "--camera-fixed", cam_pose, "--board-on-tool",
                        BOARD_ON_TOOL, NULL};
  char *cameras = h_fmt("[camera over]\nsource = http://127.0.0.1:%d/rgb.png\nmount = fixed\n",
                        cu_sim_start(&sim, args));
  start_daemon(sim.port, cameras);
  free(cameras);
  g_cam = "over";
  int kept = 0;
  for (int round = 0; round < 2; round++) {
    for (int i = 0; i < 16; i++) {
      /* from 0.28 to 0.55 m in front of the camera, up to 8 cm off its axis */
      const double d = 0.28 + 0.27 * ((i * 5 + round) % 8) / 7.0;
      double p[3];
      for (int k = 0; k < 3; k++) p[k] = eye[k] + d * (at[k] - eye[k]) / dist;
      p[0] += 0.06 * cos(i * 2.4);
      p[1] += 0.06 * sin(i * 2.4);
      p[2] += 0.04 * sin(i * 1.3 + round);
      double q[4];
      show_board(p, 15 + 30 * ((i * 7 + round) % 5) / 4.0, i * 2.1 + round,
                 -40 + 80 * ((i * 3) % 7) / 6.0, q);
      move_to(p, q);
      kept += capture_view() >= 6;
    }
    h_resp *r = calibrate(round == 0 ? "intrinsics" : "hand_eye");
    if (r->status != 200) FG_TEST_FAIL("round %d: %ld %s", round, r->status, r->body);
    if (round == 0) {
      json_t *in = json_object_get(json_object_get(r->json, "camera"), "intrinsics");
      fprintf(stderr, "fixed camera: intrinsics fx %.2f fy %.2f cx %.2f cy %.2f\n",
              num(in, "fl_x"), num(in, "fl_y"), num(in, "cx"), num(in, "cy"));
    }
    if (round == 1) {
      json_t *cam = json_object_get(r->json, "camera");
      double err_mm, err_deg;
      pose_error(json_object_get(cam, "T_base_cam"), eye, qc, &err_mm, &err_deg);
      fprintf(stderr, "fixed camera: %d views kept; T_base_cam %.3f mm, %.4f deg from the "
              "truth\n", kept, err_mm, err_deg);
      ASSERT(err_mm < 1);
      ASSERT(err_deg < 0.2);
    }
    h_resp_free(r);
  }
  ASSERT(kept >= 24);

  /* The same, driven: the robot shows the camera the board itself, aimed with the camera's
   * position as a ruler gives it (2 cm off) and the board's centre taken at the TCP (it is 2
   * cm beyond), both calibrated again from the views it takes. */
  char body[256];
  snprintf(body, sizeof body, "{\"kind\": \"both\", \"drive\": {\"target\": [%.2f, %.2f, %.2f], "
           "\"viewpoints\": 20, \"camera_position\": [%.2f, %.2f, %.2f]}}", at[0], at[1], at[2],
           eye[0] + 0.02, eye[1] - 0.01, eye[2] + 0.01);
  static const char *const bad[] = {
    "{\"kind\": \"both\", \"drive\": {\"target\": [0.45, 0, 0.25], \"elevations_deg\": [40, 60]}}",
    "{\"kind\": \"both\", \"drive\": {\"target\": [0.8, 0.25, 0.48], \"camera_position\": [0.8, "
    "0.25, 0.48]}}",
    "{\"kind\": \"both\", \"drive\": {\"target\": [0.45, 0, 0.25], \"tilt_deg\": [50, 20]}}",
    "{\"kind\": \"both\", \"drive\": {\"target\": [0.45, 0, 0.25], \"camera_position\": [0.8]}}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    h_resp *r = h_post_json("/v1/cameras/over/calibrate", bad[i]);
    ASSERT_HTTP_ERROR(r, 400, "invalid_request");
    h_resp_free(r);
  }
  h_resp *r = h_post_json("/v1/cameras/over/calibrate", body);
  ASSERT_STATUS(r, 202);
  char id[64];
  snprintf(id, sizeof id, "%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  json_t *job = t_wait_job(id, "done", 300);
  const json_int_t shown = json_integer_value(json_object_get(job, "frames"));
  fprintf(stderr, "fixed camera, driven: %lld of 20 views showed the board, %lld skipped\n",
          (long long)shown, (long long)json_integer_value(json_object_get(job, "skipped")));
  ASSERT(shown >= 16);
  json_decref(job);
  int moves, requests;
  audit_count("/v1/cameras/over/calibrate", id, &moves, &requests);
  ASSERT_EQ(moves, 20);
  r = h_get("/v1/cameras/over");
  ASSERT_STATUS(r, 200);
  json_t *in = json_object_get(r->json, "intrinsics");
  fprintf(stderr, "fixed camera, driven: fx %.2f fy %.2f cx %.2f cy %.2f\n", num(in, "fl_x"),
          num(in, "fl_y"), num(in, "cx"), num(in, "cy"));
  ASSERT(fabs(num(in, "fl_x") / K_TRUE[0] - 1) < 0.005);
  ASSERT(fabs(num(in, "fl_y") / K_TRUE[1] - 1) < 0.005);
  ASSERT(fabs(num(in, "cx") - K_TRUE[2]) < 1 && fabs(num(in, "cy") - K_TRUE[3]) < 1);
  double err_mm, err_deg;
  pose_error(json_object_get(r->json, "T_base_cam"), eye, qc, &err_mm, &err_deg);
  fprintf(stderr, "fixed camera, driven: T_base_cam %.3f mm, %.4f deg from the truth\n", err_mm,
          err_deg);
  ASSERT(err_mm < 1);
  ASSERT(err_deg < 0.2);
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

/* ---------------------------------------------------------------- the robot drives */

/* Counts the audit log's lines of route: its motions (each done, of job id) and requests. */
static void audit_count(const char *route, const char *id, int *moves, int *requests) {
  h_resp *r = h_get("/v1/robot/log?limit=200");
  ASSERT_STATUS(r, 200);
  *moves = *requests = 0;
  json_t *entries = json_object_get(r->json, "entries");
  for (size_t i = 0; i < json_array_size(entries); i++) {
    json_t *e = json_array_get(entries, i);
    const char *rt = json_string_value(json_object_get(e, "route"));
    const char *cmd = json_string_value(json_object_get(e, "command"));
    if (!rt || strcmp(rt, route) != 0 || !cmd) continue;
    if (strcmp(cmd, "move") == 0) {
      (*moves)++;
      ASSERT_STREQ(json_string_value(json_object_get(e, "request_id")), id);
      ASSERT_STREQ(json_string_value(json_object_get(e, "client")), "calibration job");
    }
    *requests += strcmp(cmd, "calibrate") == 0;
  }
  h_resp_free(r);
}

/* A hand camera whose intrinsics, distortion and mount the test draws at random (seed
 * FG_TEST_SEED, default 38), calibrated by one request: the robot takes the views itself
 * ("drive"), aimed with the mount as a ruler gives it (to the centimetre, no angle). */
static void driven(void) {
  const char *env = getenv("FG_TEST_SEED");
  const uint64_t seed = env ? strtoull(env, NULL, 10) : 38;
  double u[12];
  for (int i = 0; i < 12; i++) u[i] = fg_rng_uniform(seed, (uint64_t)i);
  const double fx = 560 + 80 * u[0], fy = fx * (0.99 + 0.02 * u[1]);
  const double cx = 310 + 20 * u[2], cy = 230 + 20 * u[3], k1 = -0.12 + 0.09 * u[4];
  const double mp[3] = {-0.03 + 0.06 * u[5], -0.03 + 0.06 * u[6], -0.04 - 0.05 * u[7]};
  /* up to 5 degrees about an axis across the optical one */
  const double ang = 5 * u[8] * M_PI / 180, phi = 2 * M_PI * u[9];
  const double rv[3] = {ang * cos(phi), ang * sin(phi), 0};
  double mq[4];
  fg_quat_from_rotvec(rv, mq);
  char camera[160], mount[160];
  snprintf(camera, sizeof camera, "%.3f %.3f %.2f %.2f 640 480 %.4f 0.02 0.0004 -0.0006", fx,
           fy, cx, cy, k1);
  snprintf(mount, sizeof mount, "%.5f %.5f %.5f %.8f %.8f %.8f %.8f", mp[0], mp[1], mp[2],
           mq[0], mq[1], mq[2], mq[3]);
  fprintf(stderr, "driven (seed %llu): camera %s, mount %s\n", (unsigned long long)seed, camera,
          mount);
  simproc sim;
  const char *args[] = {"--camera", camera, "--camera-mount", mount, "--board", BOARD, NULL};
  const int cam_port = cu_sim_start(&sim, args);
  char *cameras = h_fmt("[camera arm]\nsource = http://127.0.0.1:%d/rgb.png\n"
                        "[camera top]\nsource = http://127.0.0.1:%d/rgb.png\nmount = fixed\n",
                        cam_port, cam_port);
  start_daemon(sim.port, cameras);
  free(cameras);

  /* where the board lies, as in hand_camera; the mount to the centimetre */
  const double yaw = 15 * M_PI / 180;
  const double target[3] = {0.32 + 0.105 * cos(yaw), -0.20 + 0.105 * sin(yaw), 0};
  char body[512];
  snprintf(body, sizeof body, "{\"kind\": \"both\", \"drive\": {\"target\": [%.4f, %.4f, 0], "
           "\"mount\": {\"position\": [%.2f, %.2f, %.2f], \"quaternion\": [1, 0, 0, 0]}}}",
           target[0], target[1], mp[0], mp[1], mp[2]);

  /* bad requests: nothing queued, nothing moved */
  static const struct {
    const char *path, *body;
    long status;
    const char *code;
  } bad[] = {
    {"/v1/cameras/arm/calibrate", "{\"kind\": \"both\", \"drive\": {}}", 400, "invalid_request"},
    {"/v1/cameras/arm/calibrate", "{\"kind\": \"both\", \"drive\": {\"target\": [0.4, 0, 0], "
     "\"viewpoints\": 2}}", 400, "invalid_request"},
    {"/v1/cameras/arm/calibrate", "{\"kind\": \"both\", \"drive\": {\"target\": [0.4, 0, 0], "
     "\"distance_m\": [0.5, 0.3]}}", 400, "invalid_request"},
    {"/v1/cameras/arm/calibrate", "{\"kind\": \"both\", \"drive\": {\"target\": [0.4, 0, 0], "
     "\"mount\": [1]}}", 400, "invalid_pose"},
    {"/v1/cameras/arm/calibrate", "{\"kind\": \"all\", \"drive\": {\"target\": [0.4, 0, 0]}}",
     400, "invalid_request"},
    {"/v1/cameras/arm/calibrate", "{\"kind\": \"hand_eye\", \"drive\": {\"target\": [0.4, 0, "
     "0]}}", 409, "not_calibrated"},
    {"/v1/cameras/top/calibrate", "{\"kind\": \"both\", \"drive\": {\"target\": [0.4, 0, 0]}}",
     400, "invalid_request"}, /* a fixed camera: where it stands is not known */
    {"/v1/cameras/arm/calibrate", "{\"kind\": \"both\", \"drive\": {\"target\": [0.4, 0, 0], "
     "\"camera_position\": [0.8, 0.2, 0.5]}}", 400, "invalid_request"}, /* for a fixed one */
    {"/v1/cameras/none/calibrate", "{\"kind\": \"both\", \"drive\": {\"target\": [0.4, 0, 0]}}",
     404, "camera_not_found"},
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    h_resp *r = h_post_json(bad[i].path, bad[i].body);
    ASSERT_HTTP_ERROR(r, bad[i].status, bad[i].code);
    h_resp_free(r);
  }
  int moves, requests;
  audit_count("/v1/cameras/arm/calibrate", "", &moves, &requests);
  ASSERT_EQ(moves, 0);
  ASSERT_EQ(requests, 7); /* each refusal on this route recorded */

  h_resp *r = h_post_json("/v1/cameras/arm/calibrate", body);
  ASSERT_STATUS(r, 202);
  char id[64];
  snprintf(id, sizeof id, "%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  /* one driving job per camera: a second is refused while the first runs */
  r = h_post_json("/v1/cameras/arm/calibrate", body);
  if (r->status != 202) ASSERT_HTTP_ERROR(r, 409, "job_in_progress");
  else FG_TEST_FAIL("a second driven calibration was queued beside %s", id);
  h_resp_free(r);
  json_t *job = t_wait_job(id, "done", 300);
  ASSERT_STREQ(json_string_value(json_object_get(job, "kind")), "calibrate");
  ASSERT_STREQ(json_string_value(json_object_get(job, "camera")), "arm");
  ASSERT(json_is_null(json_object_get(job, "scene")));
  ASSERT_EQ(json_integer_value(json_object_get(job, "step")), 30); /* the default */
  const json_int_t kept = json_integer_value(json_object_get(job, "frames"));
  fprintf(stderr, "driven: %lld of 30 views showed the board, %lld skipped\n", (long long)kept,
          (long long)json_integer_value(json_object_get(job, "skipped")));
  ASSERT(kept >= 20);
  json_decref(job);
  audit_count("/v1/cameras/arm/calibrate", id, &moves, &requests);
  ASSERT_EQ(moves, 30);
  ASSERT_EQ(requests, 9); /* the refusals, the job's request and the busy one */

  r = h_get("/v1/cameras/arm");
  ASSERT_STATUS(r, 200);
  ASSERT(json_is_true(json_object_get(r->json, "calibrated")));
  json_t *in = json_object_get(r->json, "intrinsics");
  fprintf(stderr, "driven: fx %.2f fy %.2f cx %.2f cy %.2f (truth %.2f %.2f %.2f %.2f)\n",
          num(in, "fl_x"), num(in, "fl_y"), num(in, "cx"), num(in, "cy"), fx, fy, cx, cy);
  ASSERT(fabs(num(in, "fl_x") / fx - 1) < 0.005);
  ASSERT(fabs(num(in, "fl_y") / fy - 1) < 0.005);
  ASSERT(fabs(num(in, "cx") - cx) < 1 && fabs(num(in, "cy") - cy) < 1);
  double err_mm, err_deg;
  pose_error(json_object_get(r->json, "T_tcp_cam"), mp, mq, &err_mm, &err_deg);
  fprintf(stderr, "driven: mount %.3f mm, %.4f deg from the truth\n", err_mm, err_deg);
  ASSERT(err_mm < 1);
  ASSERT(err_deg < 0.2);
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}
