/* Scans the robot drives, over HTTP, against the simulator's camera: with the camera's
 * calibration in place (here its truth, written to the state dir before the start), POST
 * /v1/scenes/{s}/scan moves the robot through 30 viewpoints around the workspace and stores
 * a frame at each; every frame's pose matches the simulator's true camera pose for that image
 * (its --camera-log) within 2 mm and 0.3 degrees. A viewpoint outside the motion limits is
 * skipped and counted, and the same job then trains the scene; an uncalibrated, a fixed and
 * an unknown camera and a bad training are refused.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "cell_util.h"
#include "robot_util.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

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

#define N_VIEWS 30 /* the scan's viewpoints */
#define STR_(x) #x
#define STR(x) STR_(x)

static h_resp *scan(const char *body) { return h_post_json("/v1/scenes/table/scan", body); }

/* Metres from a frame's robot_pose (the TCP) to its camera's centre. */
static double tcp_to_camera(json_t *frame) {
  json_t *m = json_object_get(frame, "transform_matrix");
  json_t *p = json_object_get(json_object_get(frame, "robot_pose"), "position");
  if (!p) FG_TEST_FAIL("the frame has no robot_pose");
  double d2 = 0;
  for (size_t k = 0; k < 3; k++)
    d2 += pow(json_number_value(json_array_get(json_array_get(m, k), 3)) -
                json_number_value(json_array_get(p, k)), 2);
  return sqrt(d2);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  char cam_log[PATH_MAX];
  snprintf(cam_log, sizeof cam_log, "%s/camera.log", h_tmpdir());
  simproc sim;
  const char *args[] = {"--camera", CU_SCAN_CAMERA, "--camera-mount", CU_SCAN_MOUNT,
                        "--camera-log", cam_log, NULL};
  const int cam_port = cu_sim_start(&sim, args);

  cu_calibration_truth("wrist"); /* as a calibration would have left it */

  /* timeout_ms: nothing here tests a silent robot, and a stressed sanitized run once starved
   * the simulator's Modbus thread past 500 ms in the middle of a scan */
  char conf[1024];
  snprintf(conf, sizeof conf,
           "[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = 5000\n"
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

  /* N_VIEWS viewpoints on a cap 0.45 m from the workspace's centre */
  r = scan("{\"camera\": \"wrist\", \"viewpoints\": " STR(N_VIEWS) ", \"radius_m\": 0.45, "
           "\"settle_ms\": 0}");
  ASSERT_STATUS(r, 202);
  char id[64];
  snprintf(id, sizeof id, "%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  r = wait_job(id);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "skipped")), 0);
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "frames")), N_VIEWS);
  h_resp_free(r);

  /* each frame's pose against the simulator's truth for the image it served */
  r = h_get("/v1/scenes/table/frames");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(json_object_get(r->json, "frames")), N_VIEWS);
  /* ... and its camera the calibration's: the principal point far off the image's centre
   * (318.2, 241.4 in OpenCV's count, 318.7, 241.9 from the pixels' corners), where the
   * undistortion keeps it to a pixel, at the stored size */
  json_t *f0 = json_array_get(json_object_get(r->json, "frames"), 0);
  const double s_x = 480.0 / json_integer_value(json_object_get(json_object_get(f0, "camera"), "w"));
  const double s_y = 360.0 / json_integer_value(json_object_get(json_object_get(f0, "camera"), "h"));
  const double pp_x = json_number_value(json_object_get(json_object_get(f0, "camera"), "cx")) * s_x;
  const double pp_y = json_number_value(json_object_get(json_object_get(f0, "camera"), "cy")) * s_y;
  fprintf(stderr, "stored principal point %.2f %.2f (at 480 x 360)\n", pp_x, pp_y);
  ASSERT(fabs(pp_x - 318.7) < 1.5 && fabs(pp_y - 241.9) < 1.5);
  double worst_mm, worst_deg;
  cu_frame_errors(json_object_get(r->json, "frames"), cam_log, &worst_mm, &worst_deg);
  fprintf(stderr, "%d frames: poses within %.3f mm and %.4f degrees of the truth\n", N_VIEWS,
          worst_mm, worst_deg);
  ASSERT(worst_mm < 2);
  ASSERT(worst_deg < 0.3);
  /* all in the scene's first capture, each with the TCP pose it was taken at: the camera
   * sits the mount's offset from it, |(0.035, 0.01, -0.06)| = 0.070 m */
  for (size_t i = 0; i < N_VIEWS; i++) {
    json_t *f = json_array_get(json_object_get(r->json, "frames"), i);
    ASSERT_EQ(json_integer_value(json_object_get(f, "capture")), 1);
    const double d = tcp_to_camera(f);
    if (!(d > 0.065 && d < 0.075)) FG_TEST_FAIL("frame %zu: camera %.4f m from the TCP", i, d);
  }
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
  ASSERT_EQ(moves, N_VIEWS);
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
  json_t *last = json_array_get(json_object_get(rf->json, "frames"), N_VIEWS);
  ASSERT(last);
  h_resp *rr = h_get("/v1/robot");
  json_t *tcp = json_object_get(json_object_get(rr->json, "tcp_pose"), "position");
  /* the frame keeps the TCP pose read as it came in; the camera sits the mount's offset
   * from it */
  json_t *kept = json_object_get(json_object_get(last, "robot_pose"), "position");
  for (int k = 0; k < 3; k++)
    ASSERT_NEAR(json_number_value(json_array_get(kept, (size_t)k)),
                json_number_value(json_array_get(tcp, (size_t)k)), 1e-4);
  ASSERT(fabs(tcp_to_camera(last) - 0.070) < 0.005);
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
   * the scene on its N_VIEWS + 2 frames */
  r = scan("{\"camera\": \"wrist\", \"settle_ms\": 0, "
           "\"train\": {\"steps\": 4, \"captures\": \"all\"}, "
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
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "frames")), N_VIEWS + 2);
  h_resp_free(r);
  r = h_get("/v1/scenes/table/frames");
  ASSERT_EQ(json_array_size(json_object_get(r->json, "frames")), N_VIEWS + 2);
  /* the upload joined the scan's capture, the second scan took a new one */
  json_t *fs = json_object_get(r->json, "frames");
  ASSERT_EQ(json_integer_value(json_object_get(json_array_get(fs, N_VIEWS), "capture")), 1);
  ASSERT_EQ(json_integer_value(json_object_get(json_array_get(fs, N_VIEWS + 1), "capture")), 2);
  h_resp_free(r);
  r = h_get("/v1/scenes/table");
  ASSERT(json_is_true(json_object_get(r->json, "trained")));
  h_resp_free(r);

  /* the cap's radius by default: between where the workspace (0.225 m to its bounding
   * sphere) fills 80 % of the narrower field of view (16.75 degrees half, vertically) and
   * where it fills all of it, as far out as the position box allows the most viewpoints */
  const double half = atan(180 / 598.0), far = 0.225 / sin(0.8 * half), near = 0.225 / sin(half);
  r = scan("{\"camera\": \"wrist\", \"viewpoints\": 30, \"settle_ms\": 0}");
  ASSERT_STATUS(r, 202);
  const double boxed = json_real_value(json_object_get(r->json, "radius_m"));
  ASSERT(boxed > near - 1e-6 && boxed < far + 1e-6);
  snprintf(id, sizeof id, "%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  char *job_path = h_fmt("/v1/jobs/%s", id);
  r = h_delete(job_path); /* it goes too far for the simulated arm */
  h_resp_free(r);
  free(job_path);
  h_resp_free(wait_job(id));
  /* with the arm's reach known, as close as keeps the workspace in view, where the reach
   * admits the most viewpoints; the rest are refused by the limits, not the robot */
  char reach_conf[1200];
  /* conf starts with "[robot]\n" (8 characters): the reach goes into that section */
  snprintf(reach_conf, sizeof reach_conf, "[robot]\nreach_m = 0.85\n%s", conf + 8);
  h_write_config(reach_conf);
  h_reload();
  r = scan("{\"camera\": \"wrist\", \"viewpoints\": 30, \"settle_ms\": 0}");
  ASSERT_STATUS(r, 202);
  const double radius = json_real_value(json_object_get(r->json, "radius_m"));
  fprintf(stderr, "default radius %.3f m in the box, %.3f m with a reach of 0.85 m (%.3f to "
          "%.3f)\n", boxed, radius, near, far);
  ASSERT(radius < boxed && radius > near - 1e-6);
  snprintf(id, sizeof id, "%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  r = wait_job(id);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  const json_int_t skipped = json_integer_value(json_object_get(r->json, "skipped"));
  ASSERT(skipped > 0 && skipped < 30);
  h_resp_free(r);
  r = h_get("/v1/robot/log?limit=40");
  int reach_refusals = 0;
  json_t *log = json_object_get(r->json, "entries");
  for (size_t i = 0; i < json_array_size(log); i++) {
    json_t *e = json_array_get(log, i);
    const char *rid = json_string_value(json_object_get(e, "request_id"));
    reach_refusals += rid && strcmp(rid, id) == 0 &&
                      strcmp(json_string_value(json_object_get(e, "outcome")), "refused") == 0;
  }
  ASSERT_EQ(reach_refusals, skipped);
  h_resp_free(r);

  h_stop();
  simproc_stop(&sim);
  h_done();
  printf("ok\n");
  return 0;
}
