/* fieldgrip-sim's camera (camera.h). */
#include "camera.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "core/error.h"
#include "core/pose.h"
#include "core/half.h"
#include "io/image.h"
#include "io/npy.h"

#define BOARD_PX_PER_M 4000.0 /* the board's texture: a texel of 0.25 mm */
#define SUB 4                 /* board samples per pixel side */

struct sim_camera {
  sim_camera_config cfg;
  sim_cell *cell;
  double *ray;      /* [h][w][2]: the undistorted normalised coordinates of pixel centres */
  double *corner;   /* [h + 1][w + 1][2]: the same of pixel corners (u - 0.5, v - 0.5) */
  uint8_t *tex;     /* the board's face in its frame (charuco.h), white margin outside it */
  int tw, th;
  double margin_m;  /* white paper around the chessboard */
  double T_world_board[16], T_board_world[16];
  /* the server */
  pthread_mutex_t *lock;
  int listen_fd;
  int stop_pipe[2];   /* written to stop the thread */
  pthread_t thread;
  int serving;
  /* The server thread's copies of the cell (made once: a copy of a cell with a bin takes
   * 0.3 s to allocate) and the last render, answered again while the cell looks the same, so
   * that a scan's colour, depth and features of one viewpoint cost one render, not three. */
  sim_cell_view *view;      /* the state now */
  sim_cell_view *last_view; /* the state last rendered */
  int rendered;             /* last_* hold a render of last_view */
  uint8_t *last_rgb;
  uint16_t *last_d;
  int *last_geom;
  double last_T[16];
};

static int errf(char *err, size_t errsz, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static int errf(char *err, size_t errsz, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(err, errsz, fmt, ap);
  va_end(ap);
  return -1;
}

/* ---------------------------------------------------------------- configuration */

void sim_camera_config_default(sim_camera_config *c) {
  memset(c, 0, sizeof *c);
  fg_pose_identity(c->T_tcp_cam);
  c->T_tcp_cam[11] = -0.05;
  c->fx = c->fy = 600;
  c->w = 640;
  c->h = 480;
  c->cx = 319.5;
  c->cy = 239.5;
  c->patch = 16;
}

/* Up to max numbers from s; their count, or -1 when something else is in it. */
static int numbers(const char *s, double *out, int max) {
  int n = 0;
  const char *p = s;
  for (;;) {
    while (*p == ' ' || *p == '\t' || *p == ',') p++;
    if (!*p) return n;
    if (n == max) return -1;
    char *end;
    errno = 0;
    out[n] = strtod(p, &end);
    if (end == p || errno || !isfinite(out[n])) return -1;
    n++;
    p = end;
  }
}

int sim_camera_parse_mount(sim_camera_config *c, const char *s, char *err, size_t errsz) {
  double v[7];
  if (numbers(s, v, 7) != 7)
    return errf(err, errsz, "--camera-mount wants \"x y z qw qx qy qz\", got \"%s\"", s);
  if (fg_pose_from_quat(v, v + 3, c->T_tcp_cam) != 0)
    return errf(err, errsz, "--camera-mount: %s", fg_error_detail());
  return 0;
}

int sim_camera_parse_intrinsics(sim_camera_config *c, const char *s, char *err, size_t errsz) {
  double v[10] = {0};
  const int n = numbers(s, v, 10);
  if (n != 6 && n != 10)
    return errf(err, errsz, "--camera wants \"fx fy cx cy w h [k1 k2 p1 p2]\", got \"%s\"", s);
  if (!(v[0] > 0 && v[1] > 0) || v[4] != floor(v[4]) || v[5] != floor(v[5]) || v[4] < 16 ||
      v[5] < 16 || v[4] > 4096 || v[5] > 4096)
    return errf(err, errsz, "--camera: positive focal lengths and a size of 16 to 4096 "
                "whole pixels a side, got \"%s\"", s);
  c->fx = v[0];
  c->fy = v[1];
  c->cx = v[2];
  c->cy = v[3];
  c->w = (int)v[4];
  c->h = (int)v[5];
  memcpy(c->k, v + 6, sizeof c->k);
  return 0;
}

int sim_camera_parse_board(sim_camera_config *c, const char *s, char *err, size_t errsz) {
  char dict[64];
  int sx, sy, used = 0;
  double sq, mk, x, y, z, yaw;
  if (sscanf(s, "%d %d %lf %lf %63s %lf %lf %lf %lf %n", &sx, &sy, &sq, &mk, dict, &x, &y, &z,
             &yaw, &used) != 9 || s[used] != '\0')
    return errf(err, errsz, "--board wants \"squares_x squares_y square_m marker_m DICT x y z "
                "yaw\", got \"%s\"", s);
  fg_charuco_board b = {sx, sy, sq, mk, 0};
  if (fg_charuco_dictionary_parse(dict, &b.dictionary) != 0 || fg_charuco_board_check(&b) != 0)
    return errf(err, errsz, "--board: %s", fg_error_detail());
  c->has_board = 1;
  c->board = b;
  c->board_xyz[0] = x;
  c->board_xyz[1] = y;
  c->board_xyz[2] = z;
  c->board_yaw = yaw * M_PI / 180;
  return 0;
}

int sim_camera_parse_fixed(sim_camera_config *c, const char *s, char *err, size_t errsz) {
  double v[7];
  if (numbers(s, v, 7) != 7 || fg_pose_from_quat(v, v + 3, c->T_base_cam) != 0)
    return errf(err, errsz, "--camera-fixed wants \"x y z qw qx qy qz\" (a unit quaternion), "
                "got \"%s\"", s);
  c->fixed = 1;
  return 0;
}

int sim_camera_parse_board_on_tool(sim_camera_config *c, const char *s, char *err,
                                   size_t errsz) {
  char dict[64];
  int sx, sy, used = 0;
  double sq, mk, v[7];
  if (sscanf(s, "%d %d %lf %lf %63s %lf %lf %lf %lf %lf %lf %lf %n", &sx, &sy, &sq, &mk, dict,
             &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &v[6], &used) != 12 || s[used] != '\0' ||
      fg_pose_from_quat(v, v + 3, c->T_tcp_board) != 0)
    return errf(err, errsz, "--board-on-tool wants \"squares_x squares_y square_m marker_m DICT "
                "x y z qw qx qy qz\", got \"%s\"", s);
  fg_charuco_board b = {sx, sy, sq, mk, 0};
  if (fg_charuco_dictionary_parse(dict, &b.dictionary) != 0 || fg_charuco_board_check(&b) != 0)
    return errf(err, errsz, "--board-on-tool: %s", fg_error_detail());
  c->has_board = 1;
  c->board_on_tool = 1;
  c->board = b;
  return 0;
}

int sim_camera_parse_patch(sim_camera_config *c, const char *s, char *err, size_t errsz) {
  double v[1] = {0};
  if (numbers(s, v, 1) != 1 || !(v[0] >= 1 && v[0] <= 64) || v[0] != floor(v[0]))
    return errf(err, errsz, "--camera-patch: pixels per feature cell, 1 to 64, not \"%s\"", s);
  c->patch = (int)v[0];
  return 0;
}

/* ---------------------------------------------------------------- set-up */

/* The normalised, undistorted coordinates whose distortion (OpenCV's k1 k2 p1 p2) is the
 * pixel's: fixed-point iteration from the distorted point, to 1e-12. */
static void undistort(const double k[4], double xd, double yd, double *x, double *y) {
  double u = xd, v = yd;
  for (int it = 0; it < 100; it++) {
    const double r2 = u * u + v * v, radial = 1 + k[0] * r2 + k[1] * r2 * r2;
    const double dx = 2 * k[2] * u * v + k[3] * (r2 + 2 * u * u);
    const double dy = k[2] * (r2 + 2 * v * v) + 2 * k[3] * u * v;
    const double nu = (xd - dx) / radial, nv = (yd - dy) / radial;
    const double step = fabs(nu - u) + fabs(nv - v);
    u = nu;
    v = nv;
    if (step < 1e-12) break;
  }
  *x = u;
  *y = v;
}

static void rays(sim_camera *cam) {
  const sim_camera_config *c = &cam->cfg;
  for (int v = 0; v <= c->h; v++)
    for (int u = 0; u <= c->w; u++) {
      double *o = cam->corner + 2 * ((size_t)v * (c->w + 1) + u);
      undistort(c->k, (u - 0.5 - c->cx) / c->fx, (v - 0.5 - c->cy) / c->fy, o, o + 1);
      if (u < c->w && v < c->h) {
        double *r = cam->ray + 2 * ((size_t)v * c->w + u);
        undistort(c->k, (u - c->cx) / c->fx, (v - c->cy) / c->fy, r, r + 1);
      }
    }
}

/* The board's frame in the world: its origin at board_xyz, its x along yaw, its printed face
 * up (charuco.h: the face looks along the board's z times fg_charuco_face_z). */
static void board_pose(sim_camera *cam) {
  const sim_camera_config *c = &cam->cfg;
  const double fz = fg_charuco_face_z(&c->board);
  const double xb[3] = {cos(c->board_yaw), sin(c->board_yaw), 0}, zb[3] = {0, 0, fz};
  const double yb[3] = {zb[1] * xb[2] - zb[2] * xb[1], zb[2] * xb[0] - zb[0] * xb[2],
                        zb[0] * xb[1] - zb[1] * xb[0]};
  double *T = cam->T_world_board;
  fg_pose_identity(T);
  for (int r = 0; r < 3; r++) {
    T[4 * r + 0] = xb[r];
    T[4 * r + 1] = yb[r];
    T[4 * r + 2] = zb[r];
    T[4 * r + 3] = c->board_xyz[r];
  }
  fg_pose_inverse(T, cam->T_board_world);
}

sim_camera *sim_camera_new(const sim_camera_config *cfg, sim_cell *cell, char *err,
                           size_t errsz) {
  sim_camera *cam = calloc(1, sizeof *cam);
  if (!cam) return errf(err, errsz, "out of memory"), NULL;
  cam->cfg = *cfg;
  cam->cell = cell;
  cam->listen_fd = -1;
  cam->ray = malloc(sizeof *cam->ray * 2 * (size_t)cfg->w * cfg->h);
  cam->corner = malloc(sizeof *cam->corner * 2 * (size_t)(cfg->w + 1) * (cfg->h + 1));
  if (!cam->ray || !cam->corner) {
    sim_camera_free(cam);
    return errf(err, errsz, "out of memory"), NULL;
  }
  rays(cam);
  if (cfg->has_board) {
    cam->margin_m = cfg->board.square_m / 2;
    if (fg_charuco_texture(&cfg->board, BOARD_PX_PER_M, &cam->tex, &cam->tw, &cam->th) != 0) {
      errf(err, errsz, "--board: %s", fg_error_detail());
      sim_camera_free(cam);
      return NULL;
    }
    if (!cfg->board_on_tool) board_pose(cam);
  }
  return cam;
}

/* ---------------------------------------------------------------- rendering */

/* The board's brightness (0..1) at a point of its plane (board frame), -1 off the paper. */
static double board_at(const sim_camera *cam, double bx, double by) {
  const sim_camera_config *c = &cam->cfg;
  const double W = c->board.squares_x * c->board.square_m;
  const double H = c->board.squares_y * c->board.square_m, m = cam->margin_m;
  if (bx < -m || by < -m || bx > W + m || by > H + m) return -1;
  const long i = (long)floor(bx * BOARD_PX_PER_M), j = (long)floor(by * BOARD_PX_PER_M);
  if (i < 0 || j < 0 || i >= cam->tw || j >= cam->th) return 1; /* the white margin */
  return cam->tex[(size_t)j * cam->tw + i] / 255.0;
}

/* Where the ray from the camera at o along world d meets the board's plane: distance t and
 * the point in the board frame; 0 when it does not (parallel, or behind). */
static int board_hit(const double B[16], const double o[3], const double d[3], double *t,
                     double *bx, double *by) {
  double ob[3], db[3];
  for (int r = 0; r < 3; r++) {
    ob[r] = B[4 * r] * o[0] + B[4 * r + 1] * o[1] + B[4 * r + 2] * o[2] + B[4 * r + 3];
    db[r] = B[4 * r] * d[0] + B[4 * r + 1] * d[1] + B[4 * r + 2] * d[2];
  }
  if (fabs(db[2]) < 1e-12) return 0;
  *t = -ob[2] / db[2];
  if (*t <= 0) return 0;
  *bx = ob[0] + *t * db[0];
  *by = ob[1] + *t * db[1];
  return 1;
}

/* World direction of normalised camera coordinates (x, y), unit length. */
static void world_dir(const double T_wc[16], double x, double y, double d[3]) {
  const double n = sqrt(x * x + y * y + 1);
  for (int r = 0; r < 3; r++)
    d[r] = (T_wc[4 * r] * x + T_wc[4 * r + 1] * y + T_wc[4 * r + 2]) / n;
}

/* The board's mean brightness over pixel (u, v)'s footprint, -1 when a sample is off it. */
static double board_pixel(const sim_camera *cam, const double T_bw[16], const double T_wc[16],
                          const double o[3], int u, int v) {
  const int W1 = cam->cfg.w + 1;
  const double *c00 = cam->corner + 2 * ((size_t)v * W1 + u), *c10 = c00 + 2;
  const double *c01 = c00 + 2 * W1, *c11 = c01 + 2;
  double sum = 0;
  for (int b = 0; b < SUB; b++)
    for (int a = 0; a < SUB; a++) {
      const double s = (a + 0.5) / SUB, t = (b + 0.5) / SUB;
      double xy[2], d[3], dist, bx, by;
      for (int k = 0; k < 2; k++)
        xy[k] = (1 - t) * ((1 - s) * c00[k] + s * c10[k]) + t * ((1 - s) * c01[k] + s * c11[k]);
      world_dir(T_wc, xy[0], xy[1], d);
      if (!board_hit(T_bw, o, d, &dist, &bx, &by)) return -1;
      const double g = board_at(cam, bx, by);
      if (g < 0) return -1;
      sum += g;
    }
  return sum / (SUB * SUB);
}

int sim_camera_render(const sim_camera *cam, const sim_cell_view *view, uint8_t *rgb,
                       uint16_t *depth_mm, int *geom, double T_wc[16]) {
  const sim_camera_config *c = &cam->cfg;
  double p[3], q[4], T_wt[16];
  sim_cell_view_tcp(view, p, q);
  fg_pose_from_quat(p, q, T_wt);
  if (c->fixed)
    memcpy(T_wc, c->T_base_cam, 16 * sizeof *T_wc);
  else
    fg_pose_compose(T_wt, c->T_tcp_cam, T_wc);
  double T_bw[16]; /* the board's frame from the world's: it stands still, or the tool holds it */
  if (c->board_on_tool) {
    double T_wb[16];
    fg_pose_compose(T_wt, c->T_tcp_board, T_wb);
    fg_pose_inverse(T_wb, T_bw);
  } else {
    memcpy(T_bw, cam->T_board_world, sizeof T_bw);
  }
  const double o[3] = {T_wc[3], T_wc[7], T_wc[11]};
  float *lum = malloc(sizeof *lum * 3 * (size_t)c->w * c->h); /* colour before shading */
  float *zc = malloc(sizeof *zc * (size_t)c->w * c->h);     /* camera z, metres; 0: none */
  if (!lum || !zc) {
    memset(rgb, 0, 3 * (size_t)c->w * c->h);
    memset(depth_mm, 0, sizeof *depth_mm * (size_t)c->w * c->h);
    free(lum);
    free(zc);
    return -1;
  }
  /* a ray a pixel through the cell (mj_ray only reads the view), rows over the cores */
#pragma omp parallel for schedule(dynamic, 8)
  for (int v = 0; v < c->h; v++)
    for (int u = 0; u < c->w; u++) {
      const size_t i = (size_t)v * c->w + u;
      const double *r = cam->ray + 2 * i;
      double d[3], tb, bx, by;
      float col[3] = {0.8f, 0.8f, 0.82f}; /* nothing: a grey room */
      world_dir(T_wc, r[0], r[1], d);
      int g;
      const double tg = sim_cell_view_ray(view, o, d, col, &g);
      if (geom) geom[i] = g;
      double t = tg;
      if (c->has_board && board_hit(T_bw, o, d, &tb, &bx, &by) && board_at(cam, bx, by) >= 0 &&
          (tg < 0 || tb <= tg + 2e-4)) {
        const double grey = board_pixel(cam, T_bw, T_wc, o, u, v);
        if (grey >= 0) {
          col[0] = col[1] = col[2] = (float)grey;
          t = tb;
        }
      }
      for (int k = 0; k < 3; k++) lum[3 * i + k] = col[k];
      zc[i] = t > 0 ? (float)(t / sqrt(r[0] * r[0] + r[1] * r[1] + 1)) : 0;
    }
  /* Shading: the surface's normal from the depth image, lit from above and behind. */
  const double lw[3] = {0.3, 0.2, 1}, ln = sqrt(0.3 * 0.3 + 0.2 * 0.2 + 1);
  double lc[3]; /* the light's direction in the camera frame: R_wc^T l */
  for (int k = 0; k < 3; k++)
    lc[k] = (T_wc[k] * lw[0] + T_wc[4 + k] * lw[1] + T_wc[8 + k] * lw[2]) / ln;
  for (int v = 0; v < c->h; v++)
    for (int u = 0; u < c->w; u++) {
      const size_t i = (size_t)v * c->w + u;
      double shade = 1;
      const int du = u + 1 < c->w ? 1 : -1, dv = v + 1 < c->h ? 1 : -1;
      const size_t iu = i + du, iv = i + (long)dv * c->w;
      if (zc[i] > 0 && zc[iu] > 0 && zc[iv] > 0 && fabsf(zc[iu] - zc[i]) < 0.01f &&
          fabsf(zc[iv] - zc[i]) < 0.01f) {
        const double *r = cam->ray + 2 * i, *ru = cam->ray + 2 * iu, *rv = cam->ray + 2 * iv;
        double P[3] = {r[0] * zc[i], r[1] * zc[i], zc[i]};
        double a[3] = {ru[0] * zc[iu] - P[0], ru[1] * zc[iu] - P[1], zc[iu] - P[2]};
        double b[3] = {rv[0] * zc[iv] - P[0], rv[1] * zc[iv] - P[1], zc[iv] - P[2]};
        double n[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                       a[0] * b[1] - a[1] * b[0]};
        const double nn = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (nn > 0) {
          /* towards the camera: its z is negative there */
          const double sgn = (n[0] * P[0] + n[1] * P[1] + n[2] * P[2]) < 0 ? 1 : -1;
          const double lambert = sgn * (n[0] * lc[0] + n[1] * lc[1] + n[2] * lc[2]) / nn;
          shade = 0.55 + 0.45 * (lambert > 0 ? lambert : 0);
        }
      }
      for (int k = 0; k < 3; k++) {
        const double x = lum[3 * i + k] * shade * 255;
        rgb[3 * i + k] = (uint8_t)(x < 0 ? 0 : x > 255 ? 255 : lrint(x));
      }
      const double mm = zc[i] * 1000;
      depth_mm[i] = (uint16_t)(mm > 65535 ? 0 : lrint(mm));
    }
  free(lum);
  free(zc);
  return 0;
}

/* ---------------------------------------------------------------- server */

static int send_all(int fd, const void *buf, size_t len) {
  const char *p = buf;
  while (len > 0) {
    const ssize_t n = send(fd, p, len, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return -1;
    p += n;
    len -= (size_t)n;
  }
  return 0;
}

static void reply(int fd, int status, const char *reason, const char *type, const void *body,
                  size_t len, const char *extra) {
  char head[768];
  const int n = snprintf(head, sizeof head,
                         "HTTP/1.1 %d %s\r\nContent-Type: %s\r\nContent-Length: %zu\r\n"
                         "Cache-Control: no-store\r\nConnection: close\r\n%s\r\n",
                         status, reason, type, len, extra ? extra : "");
  if (send_all(fd, head, (size_t)n) == 0 && len) send_all(fd, body, len);
}

static void reply_text(int fd, int status, const char *reason, const char *text) {
  reply(fd, status, reason, "text/plain", text, strlen(text), NULL);
}

enum { SNAP_RGB, SNAP_DEPTH, SNAP_FEATURES };

/* The patch features of a rendered view (see camera.h): float16 [fh][fw][D]. */
static int features_npy(const sim_camera *cam, const int *geom, uint8_t **out, size_t *len) {
  const sim_camera_config *c = &cam->cfg;
  const int D = sim_cell_feature_dim(cam->cell);
  const int fh = (c->h + c->patch - 1) / c->patch, fw = (c->w + c->patch - 1) / c->patch;
  const double **vec = malloc(sizeof *vec * (size_t)c->w * c->h); /* each pixel's vector */
  const double **seen = malloc(sizeof *seen * (size_t)c->w * c->h);
  int *count = malloc(sizeof *count * (size_t)c->w * c->h);
  uint16_t *f = malloc(sizeof *f * (size_t)fh * fw * D);
  int rc = -1;
  if (vec && seen && count && f) {
    for (size_t i = 0; i < (size_t)c->w * c->h; i++) vec[i] = sim_cell_feature(cam->cell, geom[i]);
    for (int r = 0; r < fh; r++)
      for (int q = 0; q < fw; q++) {
        /* the pixels of cell (r, q): v with floor(v fh / h) == r, likewise u */
        const int v0 = (r * c->h + fh - 1) / fh, v1 = ((r + 1) * c->h + fh - 1) / fh;
        const int u0 = (q * c->w + fw - 1) / fw, u1 = ((q + 1) * c->w + fw - 1) / fw;
        int n = 0, best = 0;
        for (int v = v0; v < v1 && v < c->h; v++)
          for (int u = u0; u < u1 && u < c->w; u++) {
            const double *x = vec[(size_t)v * c->w + u];
            int k = 0;
            while (k < n && seen[k] != x) k++;
            if (k == n) {
              seen[n] = x;
              count[n++] = 0;
            }
            if (++count[k] > count[best]) best = k;
          }
        uint16_t *cell = f + ((size_t)r * fw + q) * D;
        for (int k = 0; k < D; k++)
          cell[k] = fg_float_to_half(n ? (float)seen[best][k] : 0.0f);
      }
    const size_t shape[3] = {(size_t)fh, (size_t)fw, (size_t)D};
    rc = fg_npy_encode(FG_DTYPE_F16, 3, shape, f, out, len) == 0 ? 0 : -1;
  }
  free(vec);
  free(seen);
  free(count);
  free(f);
  return rc;
}

/* Renders the cell as it is now and encodes what was asked for: the colour or depth image
 * (PNG), or the patch features (.npy); T_wc: where the camera was. */
static int snapshot(sim_camera *cam, int kind, uint8_t **out, size_t *len, double T_wc[16]) {
  const size_t n = (size_t)cam->cfg.w * cam->cfg.h;
  if (!cam->view) cam->view = sim_cell_view_new(cam->cell);
  if (!cam->last_view) cam->last_view = sim_cell_view_new(cam->cell);
  if (!cam->last_rgb) cam->last_rgb = malloc(3 * n);
  if (!cam->last_d) cam->last_d = malloc(sizeof *cam->last_d * n);
  if (!cam->last_geom) cam->last_geom = malloc(sizeof *cam->last_geom * n);
  if (!cam->view || !cam->last_view || !cam->last_rgb || !cam->last_d || !cam->last_geom)
    return -1;
  pthread_mutex_lock(cam->lock);
  sim_cell_view_take(cam->view, cam->cell);
  pthread_mutex_unlock(cam->lock);
  if (!cam->rendered || !sim_cell_view_same(cam->view, cam->last_view)) {
    cam->rendered = 0; /* a failed render is not answered again */
    if (sim_camera_render(cam, cam->view, cam->last_rgb, cam->last_d, cam->last_geom,
                          cam->last_T) != 0)
      return -1;
    sim_cell_view *t = cam->last_view;
    cam->last_view = cam->view;
    cam->view = t;
    cam->rendered = 1;
  }
  memcpy(T_wc, cam->last_T, sizeof cam->last_T);
  const int w = cam->cfg.w, h = cam->cfg.h;
  return kind == SNAP_FEATURES ? features_npy(cam, cam->last_geom, out, len)
         : kind == SNAP_DEPTH  ? fg_image_encode_png(cam->last_d, w, h, 1, 16, out, len)
                               : fg_image_encode_png(cam->last_rgb, w, h, 3, 8, out, len);
}

/* One request: its head read (to the blank line, at most 8 KiB), then the answer. */
static void serve_one(sim_camera *cam, int fd) {
  char req[8192];
  size_t got = 0;
  while (got < sizeof req - 1) {
    const ssize_t n = recv(fd, req + got, sizeof req - 1 - got, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return;
    got += (size_t)n;
    req[got] = '\0';
    if (strstr(req, "\r\n\r\n") || strstr(req, "\n\n")) break;
  }
  char method[16], path[256];
  if (sscanf(req, "%15s %255s", method, path) != 2)
    return reply_text(fd, 400, "Bad Request", "a request line: GET /rgb.png HTTP/1.1\n");
  static const char *const paths[] = {"/rgb.png", "/depth.png", "/features.npy"};
  static const char *const names[] = {"rgb", "depth", "features"};
  int kind = -1;
  for (int k = 0; k < 3; k++)
    if (strcmp(path, paths[k]) == 0) kind = k;
  const int has_features = sim_cell_feature_dim(cam->cell) > 0;
  const char *which = has_features ? "GET /rgb.png, /depth.png or /features.npy\n"
                                   : "GET /rgb.png or /depth.png\n";
  if (strcmp(method, "GET") != 0) return reply_text(fd, 405, "Method Not Allowed", which);
  if (kind < 0 || (kind == SNAP_FEATURES && !has_features))
    return reply_text(fd, 404, "Not Found", which);
  uint8_t *png = NULL;
  size_t len = 0;
  double T[16], p[3], q[4];
  if (snapshot(cam, kind, &png, &len, T) != 0)
    return reply_text(fd, 500, "Internal Server Error", "rendering failed\n");
  /* the truth a test compares calibrations and scans with (fieldgripd never reads it) */
  fg_pose_to_quat(T, p, q);
  char pose[200], extra[256];
  snprintf(pose, sizeof pose, "%.9f %.9f %.9f %.9f %.9f %.9f %.9f", p[0], p[1], p[2], q[0], q[1],
           q[2], q[3]);
  snprintf(extra, sizeof extra, "X-Camera-Pose: %s\r\n", pose);
  if (cam->cfg.log_path) { /* before the answer: whoever has the image finds its line */
    FILE *f = fopen(cam->cfg.log_path, "a");
    if (f) {
      fprintf(f, "%s %s\n", names[kind], pose);
      fclose(f);
    }
  }
  reply(fd, 200, "OK", kind == SNAP_FEATURES ? "application/octet-stream" : "image/png", png,
        len, extra);
  free(png);
}

static void *serve(void *arg) {
  sim_camera *cam = arg;
  for (;;) {
    struct pollfd p[2] = {{.fd = cam->listen_fd, .events = POLLIN},
                          {.fd = cam->stop_pipe[0], .events = POLLIN}};
    if (poll(p, 2, -1) < 0 && errno != EINTR) return NULL;
    if (p[1].revents) return NULL; /* stopping */
    if (!(p[0].revents & POLLIN)) continue;
    const int fd = accept4(cam->listen_fd, NULL, NULL, SOCK_CLOEXEC);
    if (fd < 0) continue;
    const struct timeval tv = {5, 0}; /* a client that sends nothing is dropped */
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    serve_one(cam, fd);
    close(fd);
  }
}

int sim_camera_serve(sim_camera *cam, pthread_mutex_t *lock, int *port, char *err,
                     size_t errsz) {
  char host[300];
  snprintf(host, sizeof host, "%s", cam->cfg.listen);
  char *colon = strrchr(host, ':');
  if (!colon) return errf(err, errsz, "--camera-listen wants HOST:PORT, got \"%s\"", host);
  *colon = '\0';
  const char *h = host, *service = colon + 1;
  if (h[0] == '[' && h[strlen(h) - 1] == ']') {
    h++;
    host[strlen(host) - 1] = '\0';
  }
  struct addrinfo hints = {.ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM,
                           .ai_flags = AI_PASSIVE | AI_NUMERICSERV}, *ai = NULL;
  const int gai = getaddrinfo(h[0] ? h : NULL, service, &hints, &ai);
  if (gai != 0)
    return errf(err, errsz, "--camera-listen %s: %s", cam->cfg.listen, gai_strerror(gai));
  int fd = socket(ai->ai_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  const int one = 1;
  if (fd >= 0) setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (fd < 0 || bind(fd, ai->ai_addr, ai->ai_addrlen) != 0 || listen(fd, 16) != 0) {
    const int e = errno;
    freeaddrinfo(ai);
    if (fd >= 0) close(fd);
    return errf(err, errsz, "cannot listen on %s: %s", cam->cfg.listen, strerror(e));
  }
  freeaddrinfo(ai);
  struct sockaddr_storage ss;
  socklen_t sl = sizeof ss;
  getsockname(fd, (struct sockaddr *)&ss, &sl);
  *port = ss.ss_family == AF_INET6 ? ntohs(((struct sockaddr_in6 *)&ss)->sin6_port)
                                   : ntohs(((struct sockaddr_in *)&ss)->sin_port);
  cam->listen_fd = fd;
  cam->lock = lock;
  if (pipe2(cam->stop_pipe, O_CLOEXEC) != 0 ||
      pthread_create(&cam->thread, NULL, serve, cam) != 0) {
    close(fd);
    cam->listen_fd = -1;
    return errf(err, errsz, "cannot start the camera's thread");
  }
  cam->serving = 1;
  return 0;
}

void sim_camera_free(sim_camera *cam) {
  if (!cam) return;
  if (cam->serving) {
    const char one = 1;
    if (write(cam->stop_pipe[1], &one, 1) != 1) abort(); /* a pipe with room cannot refuse */
    pthread_join(cam->thread, NULL);
    close(cam->stop_pipe[0]);
    close(cam->stop_pipe[1]);
  }
  if (cam->listen_fd >= 0) close(cam->listen_fd);
  free(cam->ray);
  free(cam->corner);
  free(cam->tex);
  sim_cell_view_free(cam->view);
  sim_cell_view_free(cam->last_view);
  free(cam->last_rgb);
  free(cam->last_d);
  free(cam->last_geom);
  free(cam);
}
