/* fieldgrip-sim's camera against what it should see: the robot moved over the ChArUco board
 * on the table, GET /rgb.png decoded and searched for the board, and every corner found where
 * the camera's true pose (X-Camera-Pose), the board's pose on the table, the intrinsics and
 * the distortion given on the command line put it; the depth image agrees; the TCP pose
 * registers, composed with the mount, give that same camera pose. Per-patch features from
 * the cell's labelled geoms. A cell far behind its time scale still answers. Bad requests
 * and refused options too.
 * argv[1]: fieldgrip-sim, argv[2]: the cells folder. */
#include <arpa/inet.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include "calib/charuco.h"
#include "cellproc.h"
#include "core/pose.h"
#include "core/half.h"
#include "io/image.h"
#include "io/npy.h"
#include "test.h"

static char g_sim[PATH_MAX], g_cells[PATH_MAX], g_dir[PATH_MAX];

/* the camera of the command line below */
static const double K[4] = {610, 605, 322.4, 236.8}, D[4] = {-0.08, 0.02, 0.001, -0.0015};
static const int W = 640, H = 480;
#define MOUNT "0.03 -0.02 -0.06 0.9990482 0.0436194 0 0" /* 5 degrees about x */
#define BOARD "7 5 0.03 0.022 DICT_5X5_100 0.30 -0.22 0.0 15"

/* ---------------------------------------------------------------- HTTP */

typedef struct {
  int status;
  char head[2048];
  uint8_t *body;
  size_t len;
} response;

static void http_get(int port, const char *request, response *r) {
  memset(r, 0, sizeof *r);
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  ASSERT(fd >= 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(connect(fd, (struct sockaddr *)&a, sizeof a), 0);
  ASSERT_EQ(send(fd, request, strlen(request), MSG_NOSIGNAL), (ssize_t)strlen(request));
  size_t cap = 1 << 16, got = 0;
  uint8_t *buf = malloc(cap);
  for (;;) {
    if (got == cap) buf = realloc(buf, cap *= 2);
    ASSERT(buf);
    const ssize_t n = recv(fd, buf + got, cap - got, 0);
    if (n < 0 && errno == EINTR) continue;
    ASSERT(n >= 0);
    if (n == 0) break;
    got += (size_t)n;
  }
  close(fd);
  const uint8_t *end = memmem(buf, got, "\r\n\r\n", 4);
  ASSERT(end);
  const size_t hl = (size_t)(end - buf);
  ASSERT(hl < sizeof r->head);
  memcpy(r->head, buf, hl);
  ASSERT_EQ(sscanf(r->head, "HTTP/1.1 %d", &r->status), 1);
  r->len = got - hl - 4;
  r->body = malloc(r->len + 1);
  memcpy(r->body, end + 4, r->len);
  free(buf);
}

static int camera_port(void) {
  char path[PATH_MAX + 16];
  snprintf(path, sizeof path, "%s/camera.port", g_dir);
  FILE *f = fopen(path, "r");
  ASSERT(f);
  int port = 0;
  ASSERT_EQ(fscanf(f, "%d", &port), 1);
  fclose(f);
  return port;
}

/* ---------------------------------------------------------------- geometry */

/* The board's frame in the world as --board lays it (camera.h): origin at x y z, x along
 * the yaw, the printed face up. */
static void board_pose(const fg_charuco_board *b, double T[16]) {
  const double yaw = 15 * M_PI / 180, fz = fg_charuco_face_z(b);
  const double xb[3] = {cos(yaw), sin(yaw), 0}, zb[3] = {0, 0, fz};
  const double yb[3] = {zb[1] * xb[2] - zb[2] * xb[1], zb[2] * xb[0] - zb[0] * xb[2],
                        zb[0] * xb[1] - zb[1] * xb[0]};
  const double o[3] = {0.30, -0.22, 0.0};
  fg_pose_identity(T);
  for (int r = 0; r < 3; r++) {
    T[4 * r] = xb[r];
    T[4 * r + 1] = yb[r];
    T[4 * r + 2] = zb[r];
    T[4 * r + 3] = o[r];
  }
}

/* A world point's pixel through the camera at T_wc (OpenCV's model); its depth in *z. */
static void project(const double T_wc[16], const double pw[3], double uv[2], double *z) {
  double T_cw[16], pc[3];
  fg_pose_inverse(T_wc, T_cw);
  fg_pose_apply(T_cw, pw, pc);
  const double x = pc[0] / pc[2], y = pc[1] / pc[2], r2 = x * x + y * y;
  const double radial = 1 + D[0] * r2 + D[1] * r2 * r2;
  const double xd = x * radial + 2 * D[2] * x * y + D[3] * (r2 + 2 * x * x);
  const double yd = y * radial + D[2] * (r2 + 2 * y * y) + 2 * D[3] * x * y;
  uv[0] = K[0] * xd + K[2];
  uv[1] = K[1] * yd + K[3];
  *z = pc[2];
}

static void header_pose(const char *head, double T[16]) {
  const char *h = strstr(head, "X-Camera-Pose: ");
  ASSERT(h);
  double v[7];
  ASSERT_EQ(sscanf(h + 15, "%lf %lf %lf %lf %lf %lf %lf", &v[0], &v[1], &v[2], &v[3], &v[4],
                   &v[5], &v[6]), 7);
  ASSERT_EQ(fg_pose_from_quat(v, v + 3, T), 0);
}

/* ---------------------------------------------------------------- cases */

/* The simulator on cells/blocks.xml with the camera and board above; time_scale NULL: the
 * motions at once (cellproc's default). */
static void start_scaled(cellproc *c, const char *time_scale) {
  char scene[PATH_MAX + 32], port_file[PATH_MAX + 16];
  snprintf(scene, sizeof scene, "%s/blocks.xml", g_cells);
  snprintf(port_file, sizeof port_file, "%s/camera.port", g_dir);
  unlink(port_file);
  const char *extra[] = {"--camera-listen", "127.0.0.1:0", "--camera-port-file", port_file,
                         "--camera-mount", MOUNT, "--camera",
                         "610 605 322.4 236.8 640 480 -0.08 0.02 0.001 -0.0015", "--board",
                         BOARD, time_scale ? "--time-scale" : NULL, time_scale, NULL};
  cellproc_start(c, scene, "int16", g_dir, extra);
}

static void start(cellproc *c) { start_scaled(c, NULL); }

static void test_sees_the_board(void) {
  cellproc c;
  start(&c);
  fg_charuco_board b = {7, 5, 0.03, 0.022, 0};
  ASSERT_EQ(fg_charuco_dictionary_parse("DICT_5X5_100", &b.dictionary), 0);
  double T_wb[16], centre_b[3] = {0.105, 0.075, 0}, centre[3];
  board_pose(&b, T_wb);
  fg_pose_apply(T_wb, centre_b, centre);
  /* over the board, the tool pointing down, 0.30 m up, turned a little */
  const double p[3] = {centre[0] - 0.03, centre[1] + 0.01, 0.30}, rv[3] = {3.0, 0.3, 0};
  ASSERT_EQ(cellproc_command(&c, 1, 5, p, rv, 0.085, 0, 0), 2);

  const int port = camera_port();
  response r;
  http_get(port, "GET /rgb.png HTTP/1.1\r\nHost: x\r\n\r\n", &r);
  ASSERT_EQ(r.status, 200);
  ASSERT(strstr(r.head, "Content-Type: image/png"));
  double T_wc[16];
  header_pose(r.head, T_wc);
  const float bg[3] = {0, 0, 0};
  fg_image img;
  ASSERT_EQ(fg_image_decode(r.body, r.len, bg, &img), 0);
  free(r.body);
  ASSERT_EQ(img.w, W);
  ASSERT_EQ(img.h, H);
  uint8_t *gray = malloc((size_t)W * H);
  for (int i = 0; i < W * H; i++) gray[i] = (uint8_t)lrintf(img.rgb[3 * i + 1] * 255);
  fg_image_release(&img);
  int ids[24], n = 0;
  double px[48];
  ASSERT_EQ(fg_charuco_detect(&b, gray, W, H, ids, px, &n), 0);
  free(gray);
  if (n < 20) FG_TEST_FAIL("found %d of the board's 24 corners", n);

  http_get(port, "GET /depth.png HTTP/1.1\r\n\r\n", &r);
  ASSERT_EQ(r.status, 200);
  double T_wc2[16];
  header_pose(r.head, T_wc2);
  ASSERT(fg_pose_angle_rad(T_wc, T_wc2) < 1e-9); /* the cell is at rest: the same pose */
  /* 16-bit grey: read back through the image decoder as values / 65535 */
  ASSERT_EQ(fg_image_decode(r.body, r.len, bg, &img), 0);
  free(r.body);

  double worst = 0, sum2 = 0;
  for (int k = 0; k < n; k++) {
    double cb[3], cw[3], uv[2], z;
    fg_charuco_corner(&b, ids[k], cb);
    fg_pose_apply(T_wb, cb, cw);
    project(T_wc, cw, uv, &z);
    const double e = hypot(px[2 * k] - uv[0], px[2 * k + 1] - uv[1]);
    sum2 += e * e;
    if (e > worst) worst = e;
    /* the depth at the corner's pixel: the board's z there, to the millimetre */
    const int iu = (int)lround(uv[0]), iv = (int)lround(uv[1]);
    const double mm = img.rgb[3 * ((size_t)iv * W + iu)] * 65535;
    if (fabs(mm - z * 1000) > 1.5)
      FG_TEST_FAIL("corner %d: depth %.1f mm, the board is %.1f mm away", ids[k], mm, z * 1000);
  }
  fg_image_release(&img);
  const double rms = sqrt(sum2 / n);
  fprintf(stderr, "%d corners, reprojection rms %.3f px, worst %.3f px\n", n, rms, worst);
  ASSERT(rms < 0.15);
  ASSERT(worst < 0.4);

  /* the TCP registers and the mount compose to the camera's pose (to their resolution) */
  uint16_t w[6];
  ASSERT_EQ(modbus_read_registers(c.robot, 400, 6, w), 6);
  double tp[3], trv[3], tq[4], T_wt[16], T_tc[16], T_est[16];
  for (int i = 0; i < 3; i++) {
    tp[i] = (int16_t)w[i] * 1e-4;
    trv[i] = (int16_t)w[3 + i] * 1e-3;
  }
  fg_quat_from_rotvec(trv, tq);
  ASSERT_EQ(fg_pose_from_quat(tp, tq, T_wt), 0);
  const double mp[3] = {0.03, -0.02, -0.06}, mq[4] = {0.9990482, 0.0436194, 0, 0};
  ASSERT_EQ(fg_pose_from_quat(mp, mq, T_tc), 0);
  fg_pose_compose(T_wt, T_tc, T_est);
  ASSERT(fg_pose_angle_rad(T_est, T_wc) < 0.002);
  ASSERT(hypot(hypot(T_est[3] - T_wc[3], T_est[7] - T_wc[7]), T_est[11] - T_wc[11]) < 0.0005);

  /* At rest the camera answers from its last render (one render for a viewpoint's colour,
   * depth and features); once the tool has moved it renders anew, from where the tool is. */
  response a;
  http_get(port, "GET /rgb.png HTTP/1.1\r\n\r\n", &a);
  ASSERT_EQ(a.status, 200);
  const double p2[3] = {p[0] + 0.05, p[1], p[2]};
  ASSERT_EQ(cellproc_command(&c, 2, 5, p2, rv, 0.085, 0, 0), 2);
  http_get(port, "GET /rgb.png HTTP/1.1\r\n\r\n", &r);
  ASSERT_EQ(r.status, 200);
  double T_wc3[16];
  header_pose(r.head, T_wc3);
  ASSERT(fabs(T_wc3[3] - T_wc[3] - 0.05) < 0.001);
  ASSERT(r.len != a.len || memcmp(r.body, a.body, a.len) != 0);
  free(r.body);
  http_get(port, "GET /depth.png HTTP/1.1\r\n\r\n", &r);
  double T_wc4[16];
  header_pose(r.head, T_wc4);
  ASSERT(fg_pose_angle_rad(T_wc3, T_wc4) < 1e-9 && T_wc3[3] == T_wc4[3]);
  free(r.body);
  free(a.body);

  /* what else it answers */
  http_get(port, "GET /nothing.png HTTP/1.1\r\n\r\n", &r);
  ASSERT_EQ(r.status, 404);
  free(r.body);
  http_get(port, "POST /rgb.png HTTP/1.1\r\nContent-Length: 0\r\n\r\n", &r);
  ASSERT_EQ(r.status, 405);
  free(r.body);
  cellproc_stop(&c);
}

/* A cell far behind its time scale answers (sim/cell.c, ADVANCE_BUDGET_S): at 1e-4 the cell
 * would have to step 10,000 times faster than the wall clock, which no machine does. A move of
 * 0.30 m at 1 mm/s (300 s of the cell's time) is under way: the camera shows the tool on its
 * way, far from the end, and the block reads busy, instead of both waiting for the motion's
 * end; and the simulator stops at once when told. */
static void test_answers_while_behind(void) {
  cellproc c;
  start_scaled(&c, "0.0001");
  const double from[3] = {0.35, -0.15, 0.30}, to[3] = {0.35, 0.15, 0.30}, rv[3] = {M_PI, 0, 0};
  ASSERT_EQ(cellproc_command(&c, 1, 5, from, rv, 0.085, 0, 0), 2);
  cellproc_command_start(&c, 2, 5, to, rv, 0.085, 0, 0, 0.001);
  response r;
  http_get(camera_port(), "GET /rgb.png HTTP/1.1\r\n\r\n", &r);
  ASSERT_EQ(r.status, 200);
  free(r.body);
  double T_wc[16];
  header_pose(r.head, T_wc);
  /* pointing down, the camera is 0.02 m beside the tool in y */
  fprintf(stderr, "behind its time scale: the camera at y %.3f m on the way from %.2f to %.2f\n",
          T_wc[7] - 0.02, from[1], to[1]);
  ASSERT(T_wc[7] - 0.02 < to[1] - 0.10);
  uint16_t v[2];
  ASSERT_EQ(modbus_read_registers(c.robot, CELLPROC_BASE + 13, 2, v), 2);
  ASSERT_EQ(v[0], 2);
  ASSERT_EQ(v[1], 1); /* busy */
  cellproc_stop(&c);
}

/* Features: a cell whose geoms carry vectors (cells/labelled.xml) serves one per 16 x 16
 * patch, the vector of what most of the patch shows; a cell without them answers 404. */
static void test_features(void) {
  cellproc c;
  char scene[PATH_MAX + 32], port_file[PATH_MAX + 16];
  snprintf(scene, sizeof scene, "%s/labelled.xml", g_cells);
  snprintf(port_file, sizeof port_file, "%s/camera.port", g_dir);
  unlink(port_file);
  /* straight down from 0.40 m over the crate's centre: it fills the middle of the view */
  const char *extra[] = {"--camera-listen", "127.0.0.1:0", "--camera-port-file", port_file,
                         "--camera-mount", "0 0 0 1 0 0 0", "--camera", "600 600 319.5 239.5 "
                         "640 480", NULL};
  cellproc_start(&c, scene, "int16", g_dir, extra);
  const double p[3] = {0.45, 0, 0.48}, rv[3] = {M_PI, 0, 0};
  ASSERT_EQ(cellproc_command(&c, 1, 5, p, rv, 0.085, 0, 0), 2);
  response r;
  http_get(camera_port(), "GET /features.npy HTTP/1.1\r\n\r\n", &r);
  ASSERT_EQ(r.status, 200);
  ASSERT(strstr(r.head, "X-Camera-Pose: "));
  fg_npy f;
  ASSERT_EQ(fg_npy_parse(r.body, r.len, &f), 0);
  ASSERT_EQ(f.dtype, FG_DTYPE_F16);
  ASSERT_EQ(f.ndim, 3);
  ASSERT_EQ(f.shape[0], 30);
  ASSERT_EQ(f.shape[1], 40);
  ASSERT_EQ(f.shape[2], 4);
  /* the crate's top, 0.40 m away, spans 0.12 * 600 / 0.40 = 180 px: cells 12..17 by 15..24
   * are inside it; the table fills the view's edges (1.2 m wide at 0.48 m: past the view) */
  const uint16_t *h = f.data;
  int crate = 0, table = 0, other = 0;
  for (size_t i = 0; i < 30 * 40; i++) {
    const int k = fg_half_to_float(h[4 * i + 2]) == 1 ? 2 : fg_half_to_float(h[4 * i + 1]) == 1 ? 1 : 0;
    crate += k == 2, table += k == 1, other += k == 0;
    const size_t row = i / 40, col = i % 40;
    if (row >= 12 && row <= 17 && col >= 15 && col <= 24 && k != 2)
      FG_TEST_FAIL("cell (%zu, %zu) inside the crate shows class %d", row, col, k);
    if ((row == 0 || row == 29 || col == 0 || col == 39) && k != 1)
      FG_TEST_FAIL("cell (%zu, %zu) at the view's edge shows class %d", row, col, k);
  }
  fprintf(stderr, "features: %d crate, %d table, %d background cells\n", crate, table, other);
  ASSERT_EQ(other, 0);
  /* about (180 / 16)^2 = 127 cells of crate */
  ASSERT(crate >= 100 && crate <= 160);
  free(r.body);
  cellproc_stop(&c);

  start(&c); /* blocks.xml: no vectors */
  http_get(camera_port(), "GET /features.npy HTTP/1.1\r\n\r\n", &r);
  ASSERT_EQ(r.status, 404);
  free(r.body);
  cellproc_stop(&c);
}

static void test_refused_options(void) {
  char scene[PATH_MAX + 32];
  snprintf(scene, sizeof scene, "%s/blocks.xml", g_cells);
  /* a camera without the physics cell */
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--camera-listen", "127.0.0.1:0", NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--scene", scene, "--camera", "600 600 320",
                                                       NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--scene", scene, "--camera-mount",
                                                       "0 0 0 0 0 0 0", NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--scene", scene, "--board",
                                                       "7 5 0.03 0.04 DICT_5X5_100 0 0 0 0",
                                                       NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--scene", scene, "--board",
                                                       "7 5 0.03 0.02 DICT_9X9 0 0 0 0", NULL}),
            2);
}

int main(int argc, char **argv) {
  if (argc < 3) FG_TEST_FAIL("usage: %s PATH-TO-fieldgrip-sim CELLS-DIR", argv[0]);
  ASSERT(realpath(argv[1], g_sim) != NULL);
  ASSERT(realpath(argv[2], g_cells) != NULL);
  snprintf(g_dir, sizeof g_dir, "/tmp/fg-camera-XXXXXX");
  ASSERT(mkdtemp(g_dir) != NULL);
  simproc_init(g_sim, g_dir);
  signal(SIGPIPE, SIG_IGN);
  test_sees_the_board();
  test_answers_while_behind();
  fprintf(stderr, "ok sees_the_board\n");
  test_features();
  fprintf(stderr, "ok features\n");
  test_refused_options();
  fprintf(stderr, "ok refused_options\n");
  printf("camera: ok\n");
  return 0;
}
