/* The tests' cell helpers (cell_util.h). */
#include "cell_util.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cellreport.h"
#include "core/pose.h"
#include "grasp_util.h"
#include "harness.h"
#include "robot_util.h"
#include "trained.h"

int cu_sim_start(simproc *sim, const char *const *extra) {
  const char *src = getenv("FG_SOURCE_DIR");
  ASSERT(src);
  static char scene[PATH_MAX];
  snprintf(scene, sizeof scene, "%s/tests/sim/cells/blocks.xml", src);
  return cu_sim_start_scene(sim, scene, extra);
}

int cu_sim_start_scene(simproc *sim, const char *scene, const char *const *extra) {
  static char port_file[PATH_MAX];
  static int n_started;
  snprintf(port_file, sizeof port_file, "%s/camera%d.port", h_tmpdir(), n_started++);
  const char *args[32] = {"--scene", scene, "--time-scale", "0", "--camera-listen",
                          "127.0.0.1:0", "--camera-port-file", port_file};
  int n = 8;
  for (; extra && *extra; extra++) {
    ASSERT(n < 31);
    args[n++] = *extra;
  }
  args[n] = NULL;
  simproc_start(sim, 0, args);
  /* the camera listens before the Modbus port opens: its file is there */
  FILE *f = fopen(port_file, "r");
  ASSERT(f);
  int port = 0;
  ASSERT_EQ(fscanf(f, "%d", &port), 1);
  fclose(f);
  return port;
}

void cu_scan_cell_start(const char *scenegen, const char *time_scale, int robot_timeout_ms,
                        simproc *sim, char *report) {
  char *imports = f_dataset(scenegen);
  char cell[PATH_MAX];
  snprintf(cell, sizeof cell, "%s/cell.xml", g_dir());
  snprintf(report, PATH_MAX, "%s/physics.jsonl", h_tmpdir());
  const char *args[] = {"--camera", CU_SCAN_CAMERA, "--camera-mount", CU_SCAN_MOUNT,
                        "--camera-patch", "8", "--reach-m", "1.2", "--report", report,
                        "--time-scale", time_scale ? time_scale : "0", NULL};
  const int cam_port = cu_sim_start_scene(sim, cell, args);
  cu_calibration_truth("wrist");
  char *extra = h_fmt(
      "[gripper]\nmodel = robotiq-2f85\n\n"
      "[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = %d\n"
      "limit_min = -1 -1 -0.15\nlimit_max = 1.2 1 1.2\n\n"
      "[camera wrist]\nsource = http://127.0.0.1:%d/rgb.png\n"
      "depth_source = http://127.0.0.1:%d/depth.png\n"
      "features_source = http://127.0.0.1:%d/features.npy\n",
      sim->port, robot_timeout_ms, cam_port, cam_port, cam_port);
  g_config(imports, extra); /* [train] threads = 2 */
  f_scene("t250", "sg");    /* scenegen's poses, trained {"steps": 250} at 1 cm */
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"scan\", \"workspace\": {\"min\": [0.1, "
                          "-0.45, -0.05], \"max\": [0.8, 0.45, 0.35]}, \"voxel_size\": 0.01, "
                          "\"background\": [0.8, 0.8, 0.82]}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(extra);
  free(imports);
}

void cu_look_at(const double eye[3], const double target[3], double roll_deg, double q[4]) {
  double T[16], R[9];
  fg_pose_look_at(eye, target, roll_deg * M_PI / 180, T);
  fg_pose_get_rotmat(T, R);
  fg_quat_from_rotmat(R, q);
}

char *cu_execute_lifted(const char *scene, const char *id, const char *key,
                        const char *report_path) {
  char *path = h_fmt("/v1/scenes/%s/grasps/%s/execute", scene, id);
  h_resp *r = r_post(path, "{\"dry_run\": false}", key);
  if (r->status != 200 || strcmp(JSTR(r->json, "state"), "done") != 0)
    FG_TEST_FAIL("the pick of grasp %s did not run: %ld %s", id, r->status, r->body);
  h_resp_free(r);
  free(path);
  char *text = h_read_file(report_path, NULL);
  if (!text) FG_TEST_FAIL("no physics report at %s", report_path);
  json_t *last = cellreport_line(text, -1, report_path);
  const char *lifted = json_string_value(json_object_get(last, "lifted"));
  char *out = h_fmt("%s", lifted ? lifted : "none");
  json_decref(last);
  free(text);
  return out;
}

uint8_t *cu_unbase64(const char *s, size_t *len) {
  static const char *const abc =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  const size_t n = strlen(s);
  uint8_t *out = malloc(n / 4 * 3 + 3);
  ASSERT(out);
  uint32_t acc = 0;
  int bits = 0;
  *len = 0;
  for (size_t i = 0; i < n && s[i] != '='; i++) {
    const char *p = strchr(abc, s[i]);
    ASSERT(p && s[i]);
    acc = acc << 6 | (uint32_t)(p - abc);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out[(*len)++] = (uint8_t)(acc >> bits);
    }
  }
  return out;
}

/* The truth as the daemon keeps a calibration (cell/cameras.c). */
static const char *const CALIBRATION =
    "{\"intrinsics\": {\"w\": 480, \"h\": 360, \"fx\": 600, \"fy\": 598, \"cx\": 318.2, "
    "\"cy\": 241.4, \"k\": [-0.05, 0.01, 0.0005, -0.0007], \"rms_px\": 0.1, \"views\": 16, "
    "\"at_ms\": 1}, \"mount\": {\"matrix\": [[1, 0, 0, 0.035], [0, %.9f, %.9f, 0.01], "
    "[0, %.9f, %.9f, -0.06], [0, 0, 0, 1]], \"method\": \"park\", \"spread_mm\": 0.2, "
    "\"spread_deg\": 0.05, \"rms_px\": 0.15, \"views\": 14, \"at_ms\": 1}}";

void cu_calibration_truth(const char *name) {
  char *dir = h_fmt("%s/cameras", h_state_dir()), *path = h_fmt("%s/%s.json", dir, name);
  h_mkdirs(dir);
  const double a = 3 * M_PI / 180;
  char *text = h_fmt(CALIBRATION, cos(a), -sin(a), sin(a), cos(a));
  h_write_file(path, text, strlen(text));
  free(text);
  free(path);
  free(dir);
}

void cu_frame_errors(json_t *frames, const char *cam_log, double *worst_mm, double *worst_deg) {
  FILE *f = fopen(cam_log, "r");
  ASSERT(f);
  *worst_mm = *worst_deg = 0;
  for (size_t i = 0; i < json_array_size(frames); i++) {
    char kind[16];
    double t[7];
    do /* a frame's image: its depth and features have lines of their own */
      ASSERT_EQ(fscanf(f, "%15s %lf %lf %lf %lf %lf %lf %lf", kind, &t[0], &t[1], &t[2], &t[3],
                       &t[4], &t[5], &t[6]), 8);
    while (strcmp(kind, "rgb") != 0);
    json_t *m = json_object_get(json_array_get(frames, i), "transform_matrix");
    double M[16];
    for (int row = 0; row < 4; row++)
      for (int c = 0; c < 4; c++)
        M[4 * row + c] = json_number_value(json_array_get(json_array_get(m, (size_t)row), (size_t)c));
    /* OpenGL's camera axes to OpenCV's: y and z negated */
    for (int row = 0; row < 3; row++) {
      M[4 * row + 1] = -M[4 * row + 1];
      M[4 * row + 2] = -M[4 * row + 2];
    }
    const double dmm = sqrt(pow(M[3] - t[0], 2) + pow(M[7] - t[1], 2) + pow(M[11] - t[2], 2)) * 1e3;
    /* the truth's rotation from its quaternion, compared column by column */
    const double w = t[3], x = t[4], y = t[5], z = t[6];
    const double R[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                         2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                         2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)};
    double tr = 0; /* trace of R_truth^T R_frame */
    for (int row = 0; row < 3; row++)
      for (int c = 0; c < 3; c++) tr += R[3 * row + c] * M[4 * row + c];
    const double deg = acos(fmax(-1, fmin(1, (tr - 1) / 2))) * 180 / M_PI;
    if (dmm > *worst_mm) *worst_mm = dmm;
    if (deg > *worst_deg) *worst_deg = deg;
  }
  fclose(f);
}
