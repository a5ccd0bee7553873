/* Time to first grasp (issue 39): from the last frame of a robot-driven RGB-D scan to the first
 * grasp fieldgripd answers, every phase timed.
 *
 * fieldgrip-sim plays the grasp tests' scenegen layout in physics with its camera on the tool
 * (RGB, z-depth and the layout's patch features, as test_scan_grasp); fieldgripd scans it (30
 * viewpoints, settle 0) and the same job trains the scan for STEPS steps (default 500, where
 * the quality test's depth layouts meet their geometry); the box's task, shown on the
 * fixture's scene sg as a user shows it (the gripper open, 0.085 m, and the query points a
 * user gets: none named, the box between the 2F-85's pads), is then asked for a grasp on the scan (top_k 1), twice: the first request
 * builds the voxel cache and the grasp field, the second finds them built. The first grasp is
 * then executed through fieldgripd in the simulator's physics cell, whose report says what
 * was lifted: a first grasp counts only if it picks the box up.
 *
 * Phases, from the job's phase as polled every 20 ms (its changes are seen within that):
 *   scan      the request until the job leaves "scanning" (the robot's motions and captures)
 *   load      "loading": the frames read back
 *   train     "training": STEPS steps
 *   save      "saving": the checkpoint written and the field installed
 *   grasp     the first grasp request: voxel cache (its build_seconds, from GET the scene),
 *             grasp field and search
 *   search    the second request, the search alone
 * first_grasp_s = load + train + save + grasp: the last frame to the first grasp.
 * grasp_error_mm: the first grasp's distance from the box's ground-truth grasp; lifted: what
 * physics lifted with it ("none" when nothing). pass: within target_s and the box lifted.
 *
 * Usage: bench_first_grasp FIELDGRIPD FIELDGRIP-SCENEGEN FIELDGRIP-SIM [STEPS]
 * ([train] threads = 2, the cell PC's cores.) Output, one line:
 *   bench=first_grasp steps=.. frames=.. scan_s=.. load_s=.. train_s=.. save_s=..
 *   grasp_s=.. voxel_cache_s=.. search_s=.. first_grasp_s=.. grasp_error_mm=.. lifted=..
 *   target_s=60 pass=yes|no */
#include "cell_util.h"
#include "grasp_util.h"
#include "robot_util.h"
#include "trained.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define TARGET_S 60.0

/* One grasp request for the box's task on the scan: its wall time, the grasp's id (in id,
 * when not NULL) and its distance from the box's ground-truth grasp (metres). */
static double grasp_s(char id[64], double *err_m) {
  const double t0 = h_now_s();
  h_resp *r = g_post("/v1/scenes/scan/grasps", "{\"task\": \"box\", \"top_k\": 1, \"seed\": 0}");
  const double s = h_now_s() - t0;
  json_t *g = r->status == 200 ? JGET(r->json, "grasps.0") : NULL;
  if (!g) FG_TEST_FAIL("no grasp on the scan: %ld %s", r->status, r->body);
  *err_m = g_grasp_error(g, "box");
  if (id) snprintf(id, 64, "%s", JSTR(g, "id"));
  h_resp_free(r);
  return s;
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 4)
    FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN FIELDGRIP-SIM [STEPS]", argv[0]);
  const int steps = argc > 4 ? atoi(argv[4]) : 500;
  if (steps < 1) FG_TEST_FAIL("STEPS is a whole number >= 1");
  h_set_log_level("info");
  simproc_init(argv[3], h_tmpdir());
  simproc sim;
  char report[PATH_MAX];
  cu_scan_cell_start(argv[2], NULL, 5000, &sim, report);
  char *demo = g_demo_body_open("sg", "box"); /* as a user shows it */
  h_resp *r = g_post("/v1/tasks/box/demos", demo);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(demo);

  char *body = h_fmt("{\"camera\": \"wrist\", \"viewpoints\": 30, \"radius_m\": 0.6, "
                     "\"settle_ms\": 0, \"train\": {\"steps\": %d}}", steps);
  const double t0 = h_now_s();
  r = h_post_json("/v1/scenes/scan/scan", body);
  ASSERT_STATUS(r, 202);
  char *path = h_fmt("/v1/jobs/%s", JSTR(r->json, "job"));
  h_resp_free(r);
  /* the time each phase was first seen */
  static const char *const phases[] = {"scanning", "loading", "features", "training", "saving"};
  double seen[5] = {t0, 0, 0, 0, 0}, end = 0;
  long long frames = 0;
  for (;;) {
    r = h_get(path);
    const double now = h_now_s();
    const char *st = JSTR(r->json, "state"), *ph = json_string_value(JGET(r->json, "phase"));
    for (int i = 1; ph && i < 5; i++)
      if (!seen[i] && strcmp(ph, phases[i]) == 0) seen[i] = now;
    if (strcmp(st, "queued") != 0 && strcmp(st, "running") != 0) {
      if (strcmp(st, "done") != 0) FG_TEST_FAIL("the scan ended %s: %s", st, r->body);
      frames = JINT(r->json, "frames");
      end = now;
      h_resp_free(r);
      break;
    }
    h_resp_free(r);
    if (now - t0 > 1800) FG_TEST_FAIL("the scan and its training took over 1800 s");
    h_sleep_ms(20);
  }
  /* a phase never seen (too short for the poll) ends where the next one starts */
  for (int i = 4; i >= 1; i--)
    if (!seen[i]) seen[i] = i < 4 ? seen[i + 1] : end;
  const double scan = seen[1] - seen[0], load = seen[3] - seen[1], train = seen[4] - seen[3],
               save = end - seen[4];
  char id[64];
  double err, err2;
  const double first = grasp_s(id, &err), second = grasp_s(NULL, &err2);
  r = h_get("/v1/scenes/scan");
  const double voxel = JNUM(r->json, "voxel_cache.build_seconds");
  h_resp_free(r);
  char *lifted = cu_execute_lifted("scan", id, "first-grasp", report);
  const double total = load + train + save + first;
  const int pass = total <= TARGET_S && strcmp(lifted, "box") == 0;
  printf("bench=first_grasp steps=%d frames=%lld scan_s=%.2f load_s=%.2f "
         "train_s=%.2f save_s=%.2f grasp_s=%.2f voxel_cache_s=%.2f search_s=%.2f "
         "first_grasp_s=%.2f grasp_error_mm=%.1f lifted=%s target_s=%.0f pass=%s\n", steps,
         frames, scan, load, train, save, first, voxel, second, total, err * 1e3, lifted,
         TARGET_S, pass ? "yes" : "no");
  free(lifted);
  h_stop();
  simproc_stop(&sim);
  free(path);
  free(body);
  h_done();
  return 0;
}
