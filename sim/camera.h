/* fieldgrip-sim's camera (SPEC.md "The cell around the field"): a camera on the simulated
 * robot's tool at a mount fieldgripd is not told, with its own intrinsics and distortion,
 * serving what the physics cell holds as seen from the current TCP pose, and a ChArUco board
 * lying on the table. GET /rgb.png (8-bit RGB) and GET /depth.png (16-bit z-depth in
 * millimetres, 0 where nothing was hit) over HTTP/1.1, one request per connection, and, when
 * the cell's model holds feature vectors (cell.h, sim_cell_feature), GET /features.npy: per
 * patch of P x P pixels the vector of what most of its pixels show, float16 [ceil(h / P),
 * ceil(w / P), D], pixel (u, v) in cell (floor(v ceil(h / P) / h), floor(u ceil(w / P) / w))
 * as SPEC.md lays features out: what a feature extractor on the camera's side would send. Each
 * answer carries the camera's true pose as "X-Camera-Pose: x y z qw qx qy qz" (world frame,
 * OpenCV convention) for tests to compare with, which fieldgripd does not read.
 *
 * Rendering casts one ray per pixel with MuJoCo's mj_ray against the cell's geoms (their
 * material colour, shaded by the surface's normal from the depth image); the board is drawn
 * from the ray's hit on its plane, each pixel the mean of 4 x 4 samples over its footprint, so
 * its corners are where a camera would see them to a fraction of a pixel. Pixel (u, v) looks
 * along the ray through (u, v) in OpenCV's convention (pixel centres at integers), distorted
 * by k1 k2 p1 p2 as OpenCV models it. */
#ifndef FG_SIM_CAMERA_H
#define FG_SIM_CAMERA_H

#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "calib/charuco.h"
#include "cell.h"

typedef struct sim_camera_config {
  int on;                       /* --camera-listen given */
  double T_tcp_cam[16];         /* --camera-mount: OpenCV camera frame (+z optical axis) */
  double fx, fy, cx, cy;        /* --camera, pixels */
  double k[4];                  /* k1 k2 p1 p2 (OpenCV); zeros: none */
  int w, h;
  char listen[300];             /* HOST:PORT, PORT 0: a free one */
  const char *port_file;        /* --camera-port-file: the bound port, once listening */
  const char *log_path;         /* --camera-log: a line per image served, with its true pose */
  int has_board;
  fg_charuco_board board;       /* --board or --board-on-tool */
  double board_xyz[3], board_yaw; /* --board: where the board frame's origin lies, its x
                                   * turned by yaw */
  int board_on_tool;            /* --board-on-tool: the tool holds the board ... */
  double T_tcp_board[16];       /* ... there (the board frame in the TCP's) */
  int patch;                    /* --camera-patch: pixels per feature cell (default 16) */
  int fixed;                    /* --camera-fixed: the camera stands still ... */
  double T_base_cam[16];        /* ... there (OpenCV convention), not on the tool */
} sim_camera_config;

/* Defaults: mounted 0.05 m behind the TCP along the tool's -z, looking along +z; 640 x 480,
 * fx = fy = 600, centred, no distortion; no board. */
void sim_camera_config_default(sim_camera_config *c);

/* The command-line values: "x y z qw qx qy qz", "fx fy cx cy w h [k1 k2 p1 p2]",
 * "squares_x squares_y square_m marker_m DICT x y z yaw" (yaw in degrees). 0, or -1 with a
 * message in err. */
int sim_camera_parse_mount(sim_camera_config *c, const char *s, char *err, size_t errsz);
int sim_camera_parse_intrinsics(sim_camera_config *c, const char *s, char *err, size_t errsz);
int sim_camera_parse_board(sim_camera_config *c, const char *s, char *err, size_t errsz);
/* "x y z qw qx qy qz" of a fixed camera; "squares_x squares_y square_m marker_m DICT x y z qw
 * qx qy qz" of a board the tool holds (its frame in the TCP's). */
int sim_camera_parse_fixed(sim_camera_config *c, const char *s, char *err, size_t errsz);
int sim_camera_parse_board_on_tool(sim_camera_config *c, const char *s, char *err,
                                   size_t errsz);
/* "P": 1 to 64 pixels. */
int sim_camera_parse_patch(sim_camera_config *c, const char *s, char *err, size_t errsz);

typedef struct sim_camera sim_camera;

/* Makes the camera over cell: the board's texture and the pixels' rays. NULL with a message. */
sim_camera *sim_camera_new(const sim_camera_config *cfg, sim_cell *cell, char *err,
                           size_t errsz);
void sim_camera_free(sim_camera *cam);

/* Renders the view: rgb (w * h * 3 bytes) and depth_mm (w * h); geom (w * h; may be NULL)
 * the geom each pixel's ray met, -1 for none, the board's pixels the geom it lies on;
 * T_world_cam: the camera's pose it was rendered from (OpenCV convention). 0, or -1 when
 * out of memory (the images then black and without depth). */
int sim_camera_render(const sim_camera *cam, const sim_cell_view *v, uint8_t *rgb,
                       uint16_t *depth_mm, int *geom, double T_world_cam[16]);

/* Serves GET /rgb.png, /depth.png and /features.npy on cfg->listen from a thread of its own, copying the
 * cell's state under lock (which the caller holds whenever it changes the cell). 0, or -1
 * with a message (the port could not be bound). The port is in *port. */
int sim_camera_serve(sim_camera *cam, pthread_mutex_t *lock, int *port, char *err,
                     size_t errsz);

#endif
