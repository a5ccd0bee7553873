/* The web viewer in a real browser: Debian's Chromium, headless with software WebGL, driven
 * over the DevTools protocol (cdp.h) against fieldgripd with a token, a robot configured but
 * not running, and the trained fixture's scenegen tabletop (trained.h) twice: "new", imported
 * but not trained, and "sg", trained 60 steps at 2 cm:
 *   - the page loads without the token and asks for it; from the page, the data endpoints
 *     answer 401 without it; the token typed into the form is used from then on;
 *   - a training of "new" started from the page reports its progress (its job's events, read
 *     with the token) to the end, after which the page shows the field as a point cloud and
 *     runs the deep link's query;
 *   - the deep link to "sg" (same tab, token kept) draws its cloud and runs the query (the
 *     mug's class embedding): the best voxel lies in the mug's box, and in a screenshot the
 *     heatmap's hot colours (turbo) lie where the mug's box projects through the page's
 *     camera, which the deep link fixed and the test recomputes; the time from navigation to
 *     that is reported;
 *   - a click on a camera's frustum, and selectFrame, show the frame's photo and the field's
 *     render from that camera;
 *   - a task's grasps are drawn as gripper boxes where they are; a dry run shows the register
 *     words; a real execute asks for confirmation and shows the daemon's error (the robot is
 *     not there) in the banner; &task= in a deep link finds them at load;
 *   - nothing was logged to the console as an error or exception, and the only failed
 *     requests were the expected ones.
 * Skips (77) only when Chromium cannot start.
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include <math.h>

#include "cdp.h"
#include "core/error.h"
#include "grasp/gripper.h"
#include "grasp_util.h"
#include "io/image.h"
#include "query/colormap.h"
#include "trained.h"

#define TOKEN "browser-test-token"
#define STR_(x) #x
#define STR(x) STR_(x)
#define PAGE_W 1200
#define PAGE_H 800

#define STEPS 60 /* trained from the page: the fewest that leave solid voxels */
#define ALPHA "0.1" /* the deep link's drawing threshold */

/* The deep link's view: from the front (-y) and above, onto the table's middle. */
static const double EYE[3] = {0.45, -0.75, 0.6}, TARGET[3] = {0.45, 0.0, 0.03};
#define FOV_DEG 45.0

static char *g_session;

/* ---------------------------------------------------------------- the page */

static json_t *eval(const char *expr, double timeout_s) {
  return cdp_eval(g_session, expr, timeout_s);
}

/* Waits (on the page's own change notifications) until the JavaScript condition holds;
 * returns fgViewer.status() then. */
static json_t *wait_page(const char *cond, double timeout_s) {
  char *e = h_fmt("fgViewer.waitFor(() => { const s = fgViewer.status(); return %s; }, %.0f)",
                  cond, timeout_s * 1e3);
  json_t *s = eval(e, timeout_s + 30);
  free(e);
  return s;
}

static void run_js(const char *stmt) {
  char *e = h_fmt("(() => { %s; return true; })()", stmt);
  json_decref(eval(e, 60));
  free(e);
}

static void dump_status(const char *what, json_t *s) {
  char *t = json_dumps(s, JSON_COMPACT);
  printf("%s: %s\n", what, t ? t : "?");
  free(t);
}

/* ---------------------------------------------------------------- projection */

typedef struct view {
  double eye[3], right[3], up[3], fwd[3];
  double tan_half, aspect;
  double left, top, width, height; /* the canvas on the page, CSS pixels = screenshot pixels */
} view;

static void normalize(double v[3]) {
  const double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (int k = 0; k < 3; k++) v[k] /= n;
}

static void cross(const double a[3], const double b[3], double out[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

/* A pinhole looking from eye at target with +z up and a vertical field of view, as three's
 * PerspectiveCamera after lookAt. */
static view view_make(json_t *canvas) {
  view v;
  memcpy(v.eye, EYE, sizeof v.eye);
  for (int k = 0; k < 3; k++) v.fwd[k] = TARGET[k] - EYE[k];
  normalize(v.fwd);
  const double z_up[3] = {0, 0, 1};
  cross(v.fwd, z_up, v.right);
  normalize(v.right);
  cross(v.right, v.fwd, v.up);
  v.tan_half = tan(FOV_DEG * M_PI / 360.0);
  v.left = JNUM(canvas, "left");
  v.top = JNUM(canvas, "top");
  v.width = JNUM(canvas, "width");
  v.height = JNUM(canvas, "height");
  v.aspect = v.width / v.height;
  return v;
}

/* World point p (metres) to page pixels; 0 when it lies behind the camera. */
static int view_project(const view *v, const double p[3], double *px, double *py) {
  double d[3] = {p[0] - v->eye[0], p[1] - v->eye[1], p[2] - v->eye[2]};
  const double x = d[0] * v->right[0] + d[1] * v->right[1] + d[2] * v->right[2];
  const double y = d[0] * v->up[0] + d[1] * v->up[1] + d[2] * v->up[2];
  const double z = d[0] * v->fwd[0] + d[1] * v->fwd[1] + d[2] * v->fwd[2];
  if (z <= 0) return 0;
  const double nx = x / (z * v->tan_half * v->aspect), ny = y / (z * v->tan_half);
  *px = v->left + (nx + 1) / 2 * v->width;
  *py = v->top + (1 - ny) / 2 * v->height;
  return 1;
}

/* The page-pixel box of an object's world box (gt.json aabb), grown by margin pixels. */
static void object_box(const view *v, json_t *obj, double margin, double box[4]) {
  box[0] = box[1] = INFINITY;
  box[2] = box[3] = -INFINITY;
  for (int c = 0; c < 8; c++) {
    double p[3];
    for (int a = 0; a < 3; a++) {
      char key[16];
      snprintf(key, sizeof key, "%d", a);
      p[a] = JNUM(JGET(obj, (c >> a) & 1 ? "aabb.max" : "aabb.min"), key);
    }
    double x, y;
    ASSERT(view_project(v, p, &x, &y));
    box[0] = fmin(box[0], x - margin), box[1] = fmin(box[1], y - margin);
    box[2] = fmax(box[2], x + margin), box[3] = fmax(box[3], y + margin);
  }
}

/* ---------------------------------------------------------------- screenshots */

typedef struct shot {
  int w, h;
  uint8_t *rgb; /* (h, w, 3) */
} shot;

static shot screenshot(const char *save_as) {
  uint8_t *png;
  size_t len;
  cdp_screenshot(g_session, &png, &len);
  if (save_as) {
    char *p = h_fmt("%s/%s", h_tmpdir(), save_as);
    h_write_file(p, png, len);
    free(p);
  }
  fg_image img;
  const float bg[3] = {0, 0, 0};
  ASSERT_OK(fg_image_decode(png, len, bg, &img));
  shot s = {img.w, img.h, malloc((size_t)img.w * img.h * 3)};
  for (size_t i = 0; i < (size_t)img.w * img.h * 3; i++)
    s.rgb[i] = (uint8_t)lrintf(img.rgb[i] * 255.0f);
  fg_image_release(&img);
  free(png);
  return s;
}

/* A heatmap's hot colour: turbo's upper quarter (t >= 0.75), the daemon's colours of the
 * best-scoring voxels, which the page draws as they are (within a level or two of
 * rounding). */
static int is_hot(const uint8_t *px) {
  for (int i = 192; i < 256; i++) {
    const uint8_t *t = fg_turbo_rgb[i];
    if (abs(px[0] - t[0]) <= 2 && abs(px[1] - t[1]) <= 2 && abs(px[2] - t[2]) <= 2) return 1;
  }
  return 0;
}

/* The selected grasp's colour, #ffd24a, give or take the lines' antialiasing. */
static int is_selected_yellow(const uint8_t *px) {
  return px[0] >= 200 && px[1] >= 160 && px[1] <= 235 && px[2] <= 120;
}

static int in_box(const double b[4], int x, int y) {
  return x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3];
}

/* ---------------------------------------------------------------- console */

/* Fails on exceptions, console.error and non-network error entries; failed requests are
 * allowed only for the paths the test made fail on purpose. */
static void check_console(void) {
  static const char *const expected_fail[] = {"/v1/scenes", "/v1/scenes/sg/points",
                                              "/v1/scenes/sg/frames/0/image", "/execute"};
  json_t *ev = cdp_events();
  int network_errors = 0;
  for (size_t i = 0; i < json_array_size(ev); i++) {
    json_t *e = json_array_get(ev, i);
    const char *m = json_string_value(json_object_get(e, "method"));
    json_t *p = json_object_get(e, "params");
    char *text = json_dumps(p, JSON_COMPACT);
    if (strcmp(m, "Runtime.exceptionThrown") == 0)
      FG_TEST_FAIL("the page threw: %s", text);
    if (strcmp(m, "Runtime.consoleAPICalled") == 0) {
      const char *type = json_string_value(json_object_get(p, "type"));
      if (strcmp(type, "error") == 0 || strcmp(type, "assert") == 0)
        FG_TEST_FAIL("the page logged an error: %s", text);
    }
    if (strcmp(m, "Log.entryAdded") == 0) {
      json_t *entry = json_object_get(p, "entry");
      const char *level = json_string_value(json_object_get(entry, "level"));
      const char *source = json_string_value(json_object_get(entry, "source"));
      if (strcmp(level, "error") == 0) {
        if (strcmp(source, "network") != 0) FG_TEST_FAIL("console error: %s", text);
        const char *url = json_string_value(json_object_get(entry, "url"));
        const char *path = url ? strchr(strstr(url, "//") ? strstr(url, "//") + 2 : url, '/')
                               : NULL;
        int ok = 0;
        for (size_t k = 0; path && k < sizeof expected_fail / sizeof expected_fail[0]; k++)
          ok |= expected_fail[k][1] == 'e' ? strstr(path, expected_fail[k]) != NULL
                                           : strcmp(path, expected_fail[k]) == 0;
        if (!ok) FG_TEST_FAIL("a request the test did not expect to fail failed: %s", text);
        network_errors++;
      }
    }
    free(text);
  }
  printf("console: %zu events, %d failed requests (all expected), no error\n",
         json_array_size(ev), network_errors);
}

/* ---------------------------------------------------------------- steps */

static char *g_url, *g_train_url; /* the deep link to "sg", the same to "new" */

/* The page before the token: it asks for it; the data needs it, the files do not. */
static void test_token(void) {
  json_t *s = wait_page("s.phase === 'need-token' && s.busy === 0", 60);
  json_decref(s);
  json_t *st = eval("Promise.all(['/v1/scenes', '/v1/scenes/sg/points', "
                    "'/v1/scenes/sg/frames/0/image', '/viewer/viewer.js', '/v1/health']"
                    ".map((p) => fetch(p).then((r) => r.status)))", 60);
  static const int want[] = {401, 401, 401, 200, 200};
  for (size_t i = 0; i < 5; i++) ASSERT_EQ(json_integer_value(json_array_get(st, i)), want[i]);
  json_decref(st);
  run_js("document.getElementById('token-input').value = '" TOKEN "';"
         "document.getElementById('token-form').requestSubmit()");
  s = wait_page("s.phase === 'ready' && s.busy === 0", 120);
  ASSERT(json_is_false(JGET(s, "trained")));
  ASSERT_EQ(JINT(s, "frames"), G_VIEWS);
  ASSERT_EQ(JINT(s, "points"), 0);
  ASSERT(json_is_null(JGET(s, "banner")));
  json_decref(s);
}

/* Training from the page, followed through its events to the end; then the cloud and the
 * deep link's query. */
static void test_training(void) {
  const double t0 = t_now();
  run_js("document.getElementById('train-steps').value = '" STR(STEPS) "';"
         "document.getElementById('train').click()");
  json_t *s = wait_page("s.job && s.job.state === 'done' && s.busy === 0 && s.heatmap && s.drawn",
                        600);
  dump_status("after training", s);
  ASSERT_EQ(JINT(s, "job.step"), STEPS);
  ASSERT(JINT(s, "progressEvents") >= 3);
  ASSERT(json_is_true(JGET(s, "trained")));
  ASSERT(JINT(s, "points") > 0);
  ASSERT(json_is_null(JGET(s, "banner")));
  printf("training of %d steps from the page: %.1f s, %lld events\n", STEPS, t_now() - t0,
         JINT(s, "progressEvents"));
  json_decref(s);
}

/* Chooses value in the page's select id (its change handler runs at once) and waits until
 * the page is idle again. */
static void choose(const char *id, const char *value) {
  char *js = h_fmt("const e = document.getElementById('%s'); e.value = '%s';"
                   "e.dispatchEvent(new Event('change'))", id, value);
  run_js(js);
  free(js);
  json_decref(wait_page("s.busy === 0", 60));
}

/* The field settings from the page: the trained field in the scene's line, a choice changes
 * the scene's settings (PATCH), a refused one leaves them and the select as they were. */
static void test_field_settings(void) {
  json_t *info = eval("document.getElementById('scene-info').textContent", 30);
  printf("scene info: %s\n", json_string_value(info));
  ASSERT(strstr(json_string_value(info), "field 2 \u00d7 the workspace") != NULL);
  json_decref(info);
  choose("field-scale", "4");
  choose("learn-background", "true");
  json_t *sc = t_scene_json("new");
  ASSERT_NEAR(JNUM(sc, "field_scale"), 4, 0);
  ASSERT(json_is_true(JGET(sc, "learn_background")));
  json_decref(sc);
  choose("field-scale", "auto");
  choose("learn-background", "auto");
  sc = t_scene_json("new");
  ASSERT_STREQ(JSTR(sc, "field_scale"), "auto");
  ASSERT_STREQ(JSTR(sc, "learn_background"), "auto");
  json_decref(sc);
  json_t *s = wait_page("s.busy === 0", 30);
  ASSERT(json_is_null(JGET(s, "banner")));
  json_decref(s);
}

/* The deep link's query: best voxel and hot pixels on the mug. */
static void test_heatmap_pixels(json_t *s) {
  json_t *mug = g_object("mug");
  json_t *best = JGET(s, "best");
  const double vs = 0.02;
  for (int a = 0; a < 3; a++) {
    char k[16];
    snprintf(k, sizeof k, "%d", a);
    const double p = JNUM(best, k);
    if (!(p >= JNUM(JGET(mug, "aabb.min"), k) - vs && p <= JNUM(JGET(mug, "aabb.max"), k) + vs))
      FG_TEST_FAIL("the best voxel's axis %d at %.3f is outside the mug's box", a, p);
  }
  /* the page's camera is the deep link's */
  json_t *cam = JGET(s, "camera");
  ASSERT_NEAR(JNUM(cam, "fov"), FOV_DEG, 1e-9);
  for (int a = 0; a < 3; a++) {
    char k[24];
    snprintf(k, sizeof k, "position.%d", a);
    ASSERT_NEAR(JNUM(cam, k), EYE[a], 1e-6);
    snprintf(k, sizeof k, "target.%d", a);
    ASSERT_NEAR(JNUM(cam, k), TARGET[a], 1e-6);
  }
  view v = view_make(JGET(s, "canvas"));
  double box[4];
  object_box(&v, mug, 8, box);
  shot sh = screenshot("heatmap.png");
  ASSERT_EQ(sh.w, PAGE_W);
  ASSERT_EQ(sh.h, PAGE_H);
  size_t hot = 0, hot_in = 0;
  double cx = 0, cy = 0;
  for (int y = (int)v.top; y < (int)(v.top + v.height) && y < sh.h; y++)
    for (int x = (int)v.left; x < (int)(v.left + v.width) && x < sh.w; x++) {
      if (!is_hot(sh.rgb + 3 * ((size_t)y * sh.w + x))) continue;
      hot++;
      hot_in += in_box(box, x, y);
      cx += x, cy += y;
    }
  if (hot) cx /= (double)hot, cy /= (double)hot;
  printf("heatmap: %zu hot pixels, %zu (%.0f%%) in the mug's box [%.0f, %.0f]-[%.0f, %.0f], "
         "their centre (%.0f, %.0f)\n", hot, hot_in, hot ? 100.0 * hot_in / hot : 0.0, box[0],
         box[1], box[2], box[3], cx, cy);
  ASSERT(hot >= 30);
  ASSERT(hot_in * 10 >= hot * 8);
  ASSERT(in_box(box, (int)cx, (int)cy));
  free(sh.rgb);
}

/* The deep link to the trained "sg", with the token in the tab: the cloud and the query; how
 * long it took. */
static json_t *test_deep_link(void) {
  const double t0 = t_now();
  cdp_navigate(g_session, g_url, 60);
  json_t *s = wait_page("s.phase === 'ready' && s.busy === 0 && s.heatmap && s.drawn", 120);
  const double secs = t_now() - t0;
  printf("deep link: %lld points drawn with the heatmap %.2f s after navigating (page clock: "
         "%.0f ms to the first cloud, %.0f ms to the heatmap)\n", JINT(s, "points"), secs,
         JNUM(s, "loadedMs"), JNUM(s, "heatmapMs"));
  /* the page's own clock of its load: the heatmap comes with or after the cloud */
  ASSERT(JNUM(s, "loadedMs") > 0);
  ASSERT(JNUM(s, "heatmapMs") >= JNUM(s, "loadedMs"));
  ASSERT(secs < 30); /* a hang guard; the load's speed is tests/bench's (run.sh viewer) */
  /* the browser draws on the CPU here: the page leaves multisampling off, which halves its
   * frame time on a large cloud */
  printf("WebGL renderer: %s, antialias %s\n", JSTR(s, "gl"),
         json_is_true(JGET(s, "antialias")) ? "on" : "off");
  ASSERT(strstr(JSTR(s, "gl"), "SwiftShader") != NULL);
  ASSERT(json_is_false(JGET(s, "antialias")));
  return s;
}

/* A click on a frustum's apex selects a frame; its photo and render are shown. */
static void test_frames(json_t *s) {
  view v = view_make(JGET(s, "canvas"));
  h_resp *r = h_get("/v1/scenes/sg/frames");
  ASSERT_STATUS(r, 200);
  json_t *frames = JGET(r->json, "frames");
  /* the apex in view farthest from every other apex on screen */
  int pick = -1;
  double pick_x = 0, pick_y = 0, pick_gap = 0;
  for (size_t i = 0; i < json_array_size(frames); i++) {
    double p[3], x, y;
    for (int a = 0; a < 3; a++) {
      char k[64];
      snprintf(k, sizeof k, "%zu.transform_matrix.%d.3", i, a);
      p[a] = JNUM(frames, k);
    }
    if (!view_project(&v, p, &x, &y) || x < v.left + 20 || x > v.left + v.width - 20 ||
        y < v.top + 20 || y > v.top + v.height - 20)
      continue;
    double gap = INFINITY;
    for (size_t j = 0; j < json_array_size(frames); j++) {
      double q[3], qx, qy;
      for (int a = 0; a < 3 && j != i; a++) {
        char k[64];
        snprintf(k, sizeof k, "%zu.transform_matrix.%d.3", j, a);
        q[a] = JNUM(frames, k);
      }
      if (j != i && view_project(&v, q, &qx, &qy)) gap = fmin(gap, hypot(qx - x, qy - y));
    }
    if (gap > pick_gap) pick = (int)i, pick_x = x, pick_y = y, pick_gap = gap;
  }
  ASSERT(pick >= 0);
  static const char *const types[] = {"mouseMoved", "mousePressed", "mouseReleased"};
  for (int k = 0; k < 3; k++)
    json_decref(cdp_call(g_session, "Input.dispatchMouseEvent",
                         json_pack("{s:s, s:f, s:f, s:s, s:i, s:i}", "type", types[k], "x",
                                   pick_x, "y", pick_y, "button", k ? "left" : "none",
                                   "buttons", k == 1 ? 1 : 0, "clickCount", k ? 1 : 0), 30));
  json_t *c = wait_page("s.frame >= 0 && s.busy === 0", 120);
  printf("clicked frame %d's frustum at (%.0f, %.0f), %.0f px from the next: frame %lld "
         "selected, photo %lld px wide, render %lld px wide\n", pick, pick_x, pick_y, pick_gap,
         JINT(c, "frame"), JINT(c, "photo"), JINT(c, "render"));
  if (pick_gap > 150) ASSERT_EQ(JINT(c, "frame"), pick);
  ASSERT_EQ(JINT(c, "photo"), G_W);
  ASSERT_EQ(JINT(c, "render"), G_W);
  json_decref(c);
  c = eval("fgViewer.selectFrame(3)", 120);
  ASSERT_EQ(JINT(c, "frame"), 3);
  ASSERT_EQ(JINT(c, "photo"), G_W);
  ASSERT_EQ(JINT(c, "render"), G_W);
  ASSERT(json_is_null(JGET(c, "banner")));
  json_decref(c);
  run_js("document.getElementById('frame-close').click()");
  h_resp_free(r);
}

/* A task's grasps drawn; dry run; a confirmed execute's error in the banner. */
static void test_grasps(json_t *s) {
  char *demo = g_demo_body("sg", "ball", "");
  h_resp *r = h_post_json("/v1/tasks/ball_grasp/demos", demo);
  if (r->status != 201) fprintf(stderr, "demo: %s\n", r->body);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(demo);

  view v = view_make(JGET(s, "canvas"));
  run_js("document.getElementById('query-clear').click()");
  json_decref(wait_page("!s.heatmap && s.drawn", 60));
  shot before = screenshot(NULL);
  json_decref(eval("fgViewer.selectTask('ball_grasp')", 60));
  json_t *g = eval("fgViewer.findGrasps()", 600);
  json_decref(g);
  g = wait_page("s.busy === 0 && s.drawn", 60);
  dump_status("grasps", g);
  ASSERT_STREQ(JSTR(g, "gripper"), "panda");
  ASSERT(json_is_null(JGET(g, "banner")));
  ASSERT(JINT(g, "grasps") > 0);
  shot after = screenshot("grasps.png");
  /* pixels of the 3D view that turned the selected grasp's yellow lie around its TCP (the
   * briefly trained field's grasps need not be on the mug: test_grasp checks where grasps
   * are, this checks that the page draws them where they are) */
  double tcp[3], tx, ty;
  for (int a = 0; a < 3; a++) {
    char k[32];
    snprintf(k, sizeof k, "selectedGrasp.%d", a);
    tcp[a] = JNUM(g, k);
  }
  ASSERT(view_project(&v, tcp, &tx, &ty));
  /* the gripper reaches at most ~0.2 m from its TCP: as many pixels as that is at the TCP's
   * distance (a grasp near the camera is drawn larger), and at least 150 */
  double side[3] = {tcp[0] + 0.2, tcp[1], tcp[2]}, sx, sy;
  ASSERT(view_project(&v, side, &sx, &sy));
  double reach = hypot(sx - tx, sy - ty);
  if (reach < 150) reach = 150;
  const double box[4] = {tx - reach, ty - reach, tx + reach, ty + reach};
  size_t yellow = 0, yellow_in = 0;
  for (int y = (int)v.top; y < (int)(v.top + v.height) && y < after.h; y++)
    for (int x = (int)v.left; x < (int)(v.left + v.width) && x < after.w; x++) {
      const size_t i = 3 * ((size_t)y * after.w + x);
      if (!is_selected_yellow(after.rgb + i) || is_selected_yellow(before.rgb + i)) continue;
      yellow++;
      yellow_in += in_box(box, x, y);
    }
  printf("grasps: %lld found, %zu pixels of the selected one drawn, %zu of them within %.0f px "
         "of its TCP at (%.0f, %.0f)\n", JINT(g, "grasps"), yellow, yellow_in, reach, tx, ty);
  ASSERT(yellow >= 10);
  ASSERT(yellow_in * 10 >= yellow * 9);
  free(before.rgb);
  free(after.rgb);
  json_decref(g);

  /* the boxes the page drew are the [gripper] model's, as lib/grasp has them */
  h_resp *r2 = h_post_json("/v1/scenes/sg/grasps", "{\"task\": \"ball_grasp\", \"top_k\": 1}");
  ASSERT_STATUS(r2, 200);
  fg_gripper_box want[FG_GRIPPER_N_BOXES];
  ASSERT_OK(fg_gripper_boxes(FG_GRIPPER_PANDA, JNUM(r2->json, "gripper.width"), want));
  ASSERT_NEAR(JNUM(r2->json, "gripper.width"), JNUM(r2->json, "grasps.0.width"), 1e-12);
  ASSERT_STREQ(JSTR(r2->json, "gripper.model"), "panda");
  ASSERT_EQ(json_array_size(JGET(r2->json, "gripper.boxes")), FG_GRIPPER_N_BOXES);
  for (int b = 0; b < FG_GRIPPER_N_BOXES; b++)
    for (int a = 0; a < 3; a++) {
      char k[64];
      snprintf(k, sizeof k, "gripper.boxes.%d.centre.%d", b, a);
      ASSERT_NEAR(JNUM(r2->json, k), want[b].centre_m[a], 1e-9);
      snprintf(k, sizeof k, "gripper.boxes.%d.half_size.%d", b, a);
      ASSERT_NEAR(JNUM(r2->json, k), want[b].half_m[a], 1e-9);
    }
  h_resp_free(r2);

  g = eval("fgViewer.dryRun()", 120);
  ASSERT(json_is_null(JGET(g, "banner")));
  ASSERT_STRCONTAINS(JSTR(g, "registers"), "robot unit 1 @128 (int16): 1 1 ");
  json_decref(g);

  /* for real: a confirmation first, then the daemon's answer (no robot) in the banner */
  run_js("document.getElementById('execute').click()");
  json_t *shown = eval("!document.getElementById('execute-confirm').hidden", 30);
  ASSERT(json_is_true(shown));
  json_decref(shown);
  run_js("document.getElementById('execute-yes').click()");
  g = wait_page("s.busy === 0 && s.banner !== null", 120);
  printf("execute: banner \"%s\"\n", JSTR(g, "banner"));
  ASSERT_STRCONTAINS(JSTR(g, "banner"), "robot_disconnected");
  ASSERT_STRCONTAINS(JSTR(g, "banner"), "nothing was sent");
  json_decref(g);

  /* &task= finds them at load */
  char *url = h_fmt("%s&task=ball_grasp", g_url);
  cdp_navigate(g_session, url, 60);
  g = wait_page("s.phase === 'ready' && s.busy === 0 && s.grasps > 0 && s.drawn", 600);
  ASSERT(json_is_true(JGET(g, "heatmap")));
  ASSERT(json_is_null(JGET(g, "banner")));
  json_decref(g);
  free(url);
}

/* ---------------------------------------------------------------- main */

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  const double t0 = t_now();
  char version[256], why[1024];
  if (cdp_start(60, version, sizeof version, why, sizeof why) != 0) {
    printf("SKIP: %s\n", why);
    h_done();
    return 77;
  }
  printf("browser: %s\n", version);
  char *imports = f_dataset(argv[2]);
  /* a robot that is configured but not there: dry runs work, real commands fail */
  /* its own lock folder: port 9 is the same "robot" for every run on this machine */
  char *robot = h_fmt("[http]\ntoken = " TOKEN "\n\n[robot]\ntransport = tcp\nhost = 127.0.0.1\n"
                      "port = 9\nlock_dir = %s\n", h_tmpdir());
  g_config(imports, robot);
  free(robot);
  f_scene("raw", "new"); /* at 2 cm, untrained */
  f_scene("t60", "sg");  /* at 2 cm, trained {"steps": 60} */
  h_set_token(TOKEN);
  h_start();

  char *emb = g_class_embedding("mug"); /* "[a, b, ...]": the deep link wants "a,b,..." */
  emb[strlen(emb) - 1] = 0;
  g_url = h_fmt("http://127.0.0.1:%d/?scene=sg&embedding=%s&alpha=" ALPHA
                "&eye=%g,%g,%g&target=%g,%g,%g&fov=%g", h_port(), emb + 1, EYE[0], EYE[1],
                EYE[2], TARGET[0], TARGET[1], TARGET[2], FOV_DEG);
  for (char *c = g_url; *c; c++)
    if (*c == ' ') *c = '+'; /* no spaces in a URL; '+' is one in a query string */
  free(emb);
  g_train_url = h_fmt("http://127.0.0.1:%d/?scene=new%s", h_port(), strchr(g_url, '&'));

  g_session = cdp_open_page(PAGE_W, PAGE_H);
  const double t_browser = t_now();
  cdp_navigate(g_session, g_train_url, 60);
  test_token();
  test_training();
  test_field_settings();
  json_t *s = test_deep_link();
  test_heatmap_pixels(s);
  test_frames(s);
  test_grasps(s);
  json_decref(s);
  check_console();
  printf("setup %.1f s, in the browser %.1f s\n", t_browser - t0, t_now() - t_browser);

  cdp_stop();
  h_stop();
  free(g_train_url);
  free(g_url);
  free(g_session);
  free(imports);
  h_done();
  return 0;
}
