/* A scan's time in the simulator: bench_scan FIELDGRIPD FIELDGRIP-SIM [VIEWPOINTS [SETTLE_MS]].
 * fieldgrip-sim (physics, its camera on the tool: tests/integration/cell_util.h) and
 * fieldgripd with the camera's calibration in place; POST /v1/scenes/{s}/scan of VIEWPOINTS
 * (default 30) on a cap 0.45 m from the workspace's centre (the default radius, where the
 * workspace fills 80 % of this camera's view, is about 1 m: out of the simulated arm's reach)
 * with settle_ms SETTLE_MS (default 300, the API's default)
 * timed from the request to the job's end, polled every 20 ms. Prints one line:
 *   bench=scan viewpoints=N settle_ms=S seconds=T per_view_s=T/N stored=N skipped=N
 *   worst_mm=E worst_deg=E pass=yes|no
 * (the worst frame pose error against the simulator's truth; pass: every viewpoint stored,
 * at most 1 s a viewpoint, 2 mm and 0.3 degrees). */
#include "cell_util.h"
#include "robot_util.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SIM [VIEWPOINTS [SETTLE_MS]]",
                             argv[0]);
  const int n = argc > 3 ? atoi(argv[3]) : 30, settle = argc > 4 ? atoi(argv[4]) : 300;
  if (n < 1 || n > 200 || settle < 0) FG_TEST_FAIL("1 to 200 viewpoints, settle_ms >= 0");
  simproc_init(argv[2], h_tmpdir());
  char cam_log[PATH_MAX];
  snprintf(cam_log, sizeof cam_log, "%s/camera.log", h_tmpdir());
  simproc sim;
  const char *args[] = {"--camera", CU_SCAN_CAMERA, "--camera-mount", CU_SCAN_MOUNT,
                        "--camera-log", cam_log, NULL};
  const int cam_port = cu_sim_start(&sim, args);
  cu_calibration_truth("wrist");
  char *conf = h_fmt("[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\n"
                     "limit_min = -1 -1 0.02\nlimit_max = 1 1 1\napproach_cone_deg = 180\n"
                     "[camera wrist]\nsource = http://127.0.0.1:%d/rgb.png\n"
                     "[scene table]\nworkspace_min = 0.30 -0.15 0.0\n"
                     "workspace_max = 0.60 0.15 0.15\n", sim.port, cam_port);
  h_write_config(conf);
  free(conf);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));

  char *body = h_fmt("{\"camera\": \"wrist\", \"viewpoints\": %d, \"radius_m\": 0.45, "
                     "\"settle_ms\": %d}", n, settle);
  const double t0 = h_now_s();
  h_resp *r = h_post_json("/v1/scenes/table/scan", body);
  ASSERT_STATUS(r, 202);
  char *path = h_fmt("/v1/jobs/%s", json_string_value(json_object_get(r->json, "job")));
  h_resp_free(r);
  for (;;) {
    r = h_get(path);
    const char *st = json_string_value(json_object_get(r->json, "state"));
    if (strcmp(st, "queued") != 0 && strcmp(st, "running") != 0) break;
    h_resp_free(r);
    if (h_now_s() - t0 > 600) FG_TEST_FAIL("the scan did not end within 600 s");
    h_sleep_ms(20);
  }
  const double secs = h_now_s() - t0;
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  const long long stored = json_integer_value(json_object_get(r->json, "frames"));
  const long long skipped = json_integer_value(json_object_get(r->json, "skipped"));
  h_resp_free(r);
  r = h_get("/v1/scenes/table/frames");
  double worst_mm, worst_deg;
  cu_frame_errors(json_object_get(r->json, "frames"), cam_log, &worst_mm, &worst_deg);
  h_resp_free(r);
  const int pass = stored == n && secs / n <= 1.0 && worst_mm <= 2 && worst_deg <= 0.3;
  printf("bench=scan viewpoints=%d settle_ms=%d seconds=%.2f per_view_s=%.3f stored=%lld "
         "skipped=%lld worst_mm=%.3f worst_deg=%.4f pass=%s\n", n, settle, secs, secs / n, stored,
         skipped, worst_mm, worst_deg, pass ? "yes" : "no");
  h_stop();
  simproc_stop(&sim);
  free(path);
  free(body);
  h_done();
  return 0;
}
