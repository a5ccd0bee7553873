/* Scans the robot drives, over HTTP, against the simulator's camera: with the camera's
 * calibration in place (here its truth, written to the state dir before the start), POST
 * /v1/scenes/{s}/scan moves the robot through viewpoints around the workspace and stores a
 * frame at each; every frame's pose matches the simulator's true camera pose for that image
 * (its --camera-log) within 2 mm and 0.3 degrees. A viewpoint outside the motion limits is
 * skipped and counted; an uncalibrated, a fixed and an unknown camera are refused.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "cell_util.h"
#include "robot_util.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <errno.h>
#include <sys/stat.h>

#define CAMERA "600 598 318.2 241.4 480 360 -0.05 0.01 0.0005 -0.0007"
#define MOUNT "0.035 0.01 -0.06 0.99966 0.02618 0 0" /* 3 degrees about x */

/* The truth as the daemon keeps a calibration (cell/cameras.c). */
static const char *const CALIBRATION =
    "{\"intrinsics\": {\"w\": 480, \"h\": 360, \"fx\": 600, \"fy\": 598, \"cx\": 318.2, "
    "\"cy\": 241.4, \"k\": [-0.05, 0.01, 0.0005, -0.0007], \"rms_px\": 0.1, \"views\": 16, "
    "\"at_ms\": 1}, \"mount\": {\"matrix\": [[1, 0, 0, 0.035], [0, %.9f, %.9f, 0.01], "
    "[0, %.9f, %.9f, -0.06], [0, 0, 0, 1]], \"method\": \"park\", \"spread_mm\": 0.2, "
    "\"spread_deg\": 0.05, \"rms_px\": 0.15, \"views\": 14, \"at_ms\": 1}}";

/* Polls the job until it has finished; its JSON (caller frees the response). */
static h_resp *wait_job(const char *id) {
  char path[128];
  snprintf(path, sizeof path, "/v1/jobs/%s", id);
  const double deadline = h_now_s() + 120;
  for (;;) {
    h_resp *r = h_get(path);
    ASSERT_STATUS(r, 200);
    const char *st = json_string_value(json_object_get(r->json, "state"));
    if (strcmp(st, "queued") != 0 && strcmp(st, "running") != 0) return r;
    h_resp_free(r);
    if (h_now_s() > deadline) FG_TEST_FAIL("job %s did not finish within 120 s", id);
    h_sleep_ms(50);
  }
}

static h_resp *scan(const char *body) { return h_post_json("/v1/scenes/table/scan", body); }

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  char cam_log[PATH_MAX];
  snprintf(cam_log, sizeof cam_log, "%s/camera.log", h_tmpdir());
  simproc sim;
  const char *args[] = {"--camera", CAMERA, "--camera-mount", MOUNT, "--camera-log", cam_log,
                        NULL};
  const int cam_port = cu_sim_start(&sim, args);

  /* the camera's calibration, as a calibration would have left it */
  char dir[PATH_MAX], path[PATH_MAX + 16], text[1024];
  snprintf(dir, sizeof dir, "%s/cameras", h_state_dir());
  ASSERT(mkdir(h_state_dir(), 0755) == 0 || errno == EEXIST);
  ASSERT(mkdir(dir, 0755) == 0 || errno == EEXIST);
  const double a = 3 * M_PI / 180;
  snprintf(text, sizeof text, CALIBRATION, cos(a), -sin(a), sin(a), cos(a));
  snprintf(path, sizeof path, "%s/wrist.json", dir);
  FILE *f = fopen(path, "w");
  ASSERT(f && fputs(text, f) >= 0 && fclose(f) == 0);

  char conf[1024];
  snprintf(conf, sizeof conf,
           "[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = 500\n"
           "limit_min = -1 -1 0.02\nlimit_max = 1 1 1\napproach_cone_deg = 180\n"
           "[camera wrist]\nsource = http://127.0.0.1:%d/rgb.png\n"
           "[camera other]\nsource = http://127.0.0.1:%d/rgb.png\n"
           "[camera over]\nsource = http://127.0.0.1:%d/rgb.png\nmount = fixed\n"
           "[scene table]\nworkspace_min = 0.30 -0.15 0.0\nworkspace_max = 0.60 0.15 0.15\n",
           sim.port, cam_port, cam_port, cam_port);
  h_write_config(conf);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  h_resp *r = h_get("/v1/cameras/wrist");
  ASSERT(json_is_true(json_object_get(r->json, "calibrated")));
  h_resp_free(r);

  /* refused before anything moves */
  r = scan("{\"camera\": \"other\", \"viewpoints\": 4}");
  ASSERT_HTTP_ERROR(r, 409, "not_calibrated");
  h_resp_free(r);
  r = scan("{\"camera\": \"over\"}");
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  r = scan("{\"camera\": \"nothing\"}");
  ASSERT_HTTP_ERROR(r, 404, "camera_not_found");
  h_resp_free(r);
  r = scan("{\"camera\": \"wrist\", \"viewpoints\": 0}");
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);

  /* 12 viewpoints on a cap 0.45 m from the workspace's centre */
  r = scan("{\"camera\": \"wrist\", \"viewpoints\": 12, \"radius_m\": 0.45, \"settle_ms\": 0}");
  ASSERT_STATUS(r, 202);
  char id[64];
  snprintf(id, sizeof id, "%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  r = wait_job(id);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "skipped")), 0);
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "frames")), 12);
  h_resp_free(r);

  /* each frame's pose against the simulator's truth for the image it served */
  r = h_get("/v1/scenes/table/frames");
  ASSERT_STATUS(r, 200);
  json_t *frames = json_object_get(r->json, "frames");
  ASSERT_EQ(json_array_size(frames), 12);
  f = fopen(cam_log, "r");
  ASSERT(f);
  double worst_mm = 0, worst_deg = 0;
  for (size_t i = 0; i < 12; i++) {
    char kind[8];
    double t[7];
    ASSERT_EQ(fscanf(f, "%7s %lf %lf %lf %lf %lf %lf %lf", kind, &t[0], &t[1], &t[2], &t[3],
                     &t[4], &t[5], &t[6]), 8);
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
    if (dmm > worst_mm) worst_mm = dmm;
    if (deg > worst_deg) worst_deg = deg;
  }
  fclose(f);
  fprintf(stderr, "12 frames: poses within %.3f mm and %.4f degrees of the truth\n", worst_mm,
          worst_deg);
  ASSERT(worst_mm < 2);
  ASSERT(worst_deg < 0.3);
  h_resp_free(r);

  /* every motion of the scan is in the robot's audit log, as is the request that started it */
  r = h_get("/v1/robot/log?limit=100");
  ASSERT_STATUS(r, 200);
  int moves = 0, requests = 0;
  json_t *entries = json_object_get(r->json, "entries");
  for (size_t i = 0; i < json_array_size(entries); i++) {
    json_t *e = json_array_get(entries, i);
    if (!json_is_string(json_object_get(e, "route")) ||
        strcmp(json_string_value(json_object_get(e, "route")), "/v1/scenes/table/scan") != 0)
      continue;
    const char *cmd = json_string_value(json_object_get(e, "command"));
    if (cmd && strcmp(cmd, "move") == 0) {
      moves++;
      ASSERT_STREQ(json_string_value(json_object_get(e, "outcome")), "done");
      ASSERT_STREQ(json_string_value(json_object_get(e, "request_id")), id);
    }
    requests += cmd && strcmp(cmd, "scan") == 0;
  }
  ASSERT_EQ(moves, 12);
  ASSERT_EQ(requests, 5); /* four refused, one queued */
  h_resp_free(r);

  /* a frame uploaded from the robot: meta names the camera, the pose is the TCP's now */
  uint8_t *png;
  size_t png_len;
  h_png(480, 360, 3, 8, 7, 0, &png, &png_len);
  const char *meta = "{\"camera\": \"wrist\", \"robot_pose\": \"current\"}";
  r = h_upload("/v1/scenes/table/frames", png, png_len, meta, NULL, 0);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  h_resp *rf = h_get("/v1/scenes/table/frames");
  json_t *last = json_array_get(json_object_get(rf->json, "frames"), 12);
  ASSERT(last);
  json_t *m = json_object_get(last, "transform_matrix");
  h_resp *rr = h_get("/v1/robot");
  json_t *tcp = json_object_get(json_object_get(rr->json, "tcp_pose"), "position");
  /* the camera sits at the TCP plus the mount's offset turned by the tool: within 10 cm */
  double d2 = 0;
  for (int k = 0; k < 3; k++)
    d2 += pow(json_number_value(json_array_get(json_array_get(m, (size_t)k), 3)) -
                  json_number_value(json_array_get(tcp, (size_t)k)), 2);
  ASSERT(sqrt(d2) > 0.05 && sqrt(d2) < 0.08); /* |(0.035, 0.01, -0.06)| = 0.070 m */
  /* the calibration's intrinsics and distortion: undistorted on ingest */
  ASSERT(json_is_true(json_object_get(last, "undistorted")));
  ASSERT_EQ(json_integer_value(json_array_get(json_object_get(last, "source_size"), 0)), 480);
  h_resp_free(rr);
  h_resp_free(rf);
  /* refused: an unknown camera, an uncalibrated one, a pose beside a camera name */
  r = h_upload("/v1/scenes/table/frames", png, png_len, "{\"camera\": \"nothing\"}", NULL, 0);
  ASSERT_HTTP_ERROR(r, 404, "camera_not_found");
  h_resp_free(r);
  r = h_upload("/v1/scenes/table/frames", png, png_len,
               "{\"camera\": \"other\", \"robot_pose\": \"current\"}", NULL, 0);
  ASSERT_HTTP_ERROR(r, 409, "not_calibrated");
  h_resp_free(r);
  r = h_upload("/v1/scenes/table/frames", png, png_len,
               "{\"camera\": \"wrist\", \"transform_matrix\": [[1,0,0,0],[0,1,0,0],"
               "[0,0,1,0],[0,0,0,1]]}", NULL, 0);
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  free(png);

  /* a bad training in a scan: refused before anything moves */
  r = scan("{\"camera\": \"wrist\", \"train\": {\"steps\": 0}}");
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  r = scan("{\"camera\": \"wrist\", \"train\": 3}");
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);

  /* a viewpoint outside the motion limits is skipped and counted; then the same job trains
   * the scene on its 14 frames */
  r = scan("{\"camera\": \"wrist\", \"settle_ms\": 0, \"train\": {\"steps\": 4}, "
           "\"viewpoints\": [{\"position\": [0.45, -0.05, 0.40], \"quaternion\": [0, 1, 0, 0]}, "
           "{\"position\": [1.80, 0, 0.40], \"quaternion\": [0, 1, 0, 0]}]}");
  ASSERT_STATUS(r, 202);
  snprintf(id, sizeof id, "%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  r = wait_job(id);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "kind")), "scan");
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "skipped")), 1);
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "step")), 4); /* the training's */
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "frames")), 14);
  h_resp_free(r);
  r = h_get("/v1/scenes/table/frames");
  ASSERT_EQ(json_array_size(json_object_get(r->json, "frames")), 14);
  h_resp_free(r);
  r = h_get("/v1/scenes/table");
  ASSERT(json_is_true(json_object_get(r->json, "trained")));
  h_resp_free(r);

  h_stop();
  simproc_stop(&sim);
  h_done();
  printf("ok\n");
  return 0;
}
