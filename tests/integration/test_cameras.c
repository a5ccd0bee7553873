/* The cameras over HTTP against the simulator's camera on the tool (physics mode): GET
 * /v1/cameras and /v1/cameras/{c} before any calibration, a capture (the image and the depth
 * image as the camera served them, the robot's TCP pose read around it), and what fails:
 * an unknown camera, a camera that does not answer, one that takes a connection and never
 * answers (its own timeout_ms, not the default), a V4L2 device that is not there (the
 * grabber child's message), a capture with keys.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "cell_util.h"
#include "robot_util.h"

#include <arpa/inet.h>
#include <limits.h>
#include <math.h>
#include <netinet/in.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

/* A PNG's size from its header. */
static void png_size(const uint8_t *p, size_t len, int *w, int *h, int *depth) {
  ASSERT(len > 26 && memcmp(p, "\x89PNG\r\n\x1a\n", 8) == 0);
  *w = p[16] << 24 | p[17] << 16 | p[18] << 8 | p[19];
  *h = p[20] << 24 | p[21] << 16 | p[22] << 8 | p[23];
  *depth = p[24];
}

/* A loopback port that takes connections into its backlog and never answers; *port is set. */
static int silent_listener(int *port) {
  const int s = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
  socklen_t len = sizeof a;
  ASSERT(s >= 0 && bind(s, (struct sockaddr *)&a, sizeof a) == 0 && listen(s, 8) == 0 &&
         getsockname(s, (struct sockaddr *)&a, &len) == 0);
  *port = ntohs(a.sin_port);
  return s;
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  simproc sim;
  const char *args[] = {"--camera", "600 600 319.5 239.5 320 240", NULL};
  const int cam_port = cu_sim_start(&sim, args);
  int silent_port;
  const int silent = silent_listener(&silent_port);
  char conf[1280];
  snprintf(conf, sizeof conf,
           "[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = 5000\n"
           "limit_min = -1.5 -1.5 -0.5\nlimit_max = 1.5 1.5 1.5\n"
           "[camera wrist]\nsource = http://127.0.0.1:%d/rgb.png\n"
           "depth_source = http://127.0.0.1:%d/depth.png\n"
           "[camera dead]\nsource = http://127.0.0.1:1/rgb.png\nmount = fixed\n"
           "[camera usb]\nsource = v4l2:/dev/video-none\nmount = fixed\n"
           "[camera nofeat]\nsource = http://127.0.0.1:%d/rgb.png\nmount = fixed\n"
           "features_source = http://127.0.0.1:%d/features.npy\n"
           "[camera badfeat]\nsource = http://127.0.0.1:%d/rgb.png\nmount = fixed\n"
           "features_source = http://127.0.0.1:%d/depth.png\n"
           "[camera silent]\nsource = http://127.0.0.1:%d/rgb.png\nmount = fixed\n"
           "timeout_ms = 300\n",
           sim.port, cam_port, cam_port, cam_port, cam_port, cam_port, cam_port, silent_port);
  h_write_config(conf);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));

  /* before any calibration */
  h_resp *r = h_get("/v1/cameras");
  ASSERT_STATUS(r, 200);
  json_t *list = json_object_get(r->json, "cameras");
  ASSERT_EQ(json_array_size(list), 6);
  json_t *w = json_array_get(list, 0);
  ASSERT_STREQ(json_string_value(json_object_get(w, "name")), "wrist");
  ASSERT_STREQ(json_string_value(json_object_get(w, "mount")), "hand");
  ASSERT(json_is_false(json_object_get(w, "calibrated")));
  ASSERT(json_is_null(json_object_get(w, "intrinsics")));
  ASSERT(json_is_null(json_object_get(w, "T_tcp_cam")));
  ASSERT(json_is_null(json_object_get(json_array_get(list, 1), "T_base_cam")));
  h_resp_free(r);
  r = h_get("/v1/cameras/dead");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "mount")), "fixed");
  h_resp_free(r);

  /* a capture: the images as served, the TCP where the simulated robot stands (home) */
  r = h_post_json("/v1/cameras/wrist/capture", "");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "image_type")), "PNG");
  size_t len;
  int pw, ph, depth;
  uint8_t *png = cu_unbase64(json_string_value(json_object_get(r->json, "image")), &len);
  png_size(png, len, &pw, &ph, &depth);
  ASSERT(pw == 320 && ph == 240 && depth == 8);
  free(png);
  png = cu_unbase64(json_string_value(json_object_get(r->json, "depth")), &len);
  png_size(png, len, &pw, &ph, &depth);
  ASSERT(pw == 320 && ph == 240 && depth == 16);
  free(png);
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "depth_scale")), 0.001, 1e-12);
  json_t *pos = json_object_get(json_object_get(r->json, "robot_pose"), "position");
  ASSERT_NEAR(json_real_value(json_array_get(pos, 0)), 0.30, 0.002);
  ASSERT_NEAR(json_real_value(json_array_get(pos, 2)), 0.40, 0.002);
  ASSERT(json_is_null(json_object_get(r->json, "camera_pose"))); /* not calibrated */
  ASSERT(json_is_null(json_object_get(r->json, "features"))); /* no features_source */
  h_resp_free(r);

  /* what fails */
  r = h_post_json("/v1/cameras/nothing/capture", "");
  ASSERT_HTTP_ERROR(r, 404, "camera_not_found");
  h_resp_free(r);
  r = h_post_json("/v1/cameras/dead/capture", "");
  ASSERT_HTTP_ERROR(r, 502, "camera_unavailable");
  h_resp_free(r);
  /* a V4L2 device that is not there: the grabber's own words */
  r = h_post_json("/v1/cameras/usb/capture", "");
  ASSERT_HTTP_ERROR(r, 502, "camera_unavailable");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "cannot open /dev/video-none");
  h_resp_free(r);
  /* features that are not there (this cell's geoms carry none: 404), or not a .npy */
  r = h_post_json("/v1/cameras/nofeat/capture", "");
  ASSERT_HTTP_ERROR(r, 502, "camera_unavailable");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "features.npy");
  h_resp_free(r);
  r = h_post_json("/v1/cameras/badfeat/capture", "");
  ASSERT_HTTP_ERROR(r, 502, "camera_unavailable");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "sent no .npy");
  h_resp_free(r);
  /* connected and never answered: its own timeout_ms, not the default 5000 */
  r = h_post_json("/v1/cameras/silent/capture", "");
  ASSERT_HTTP_ERROR(r, 504, "camera_timeout");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "did not answer within 300 ms");
  h_resp_free(r);
  close(silent);
  r = h_post_json("/v1/cameras/wrist/capture", "{\"exposure\": 3}");
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
  h_done();
  printf("ok\n");
  return 0;
}
