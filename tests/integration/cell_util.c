/* The tests' cell helpers (cell_util.h). */
#include "cell_util.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "core/pose.h"
#include "harness.h"

int cu_sim_start(simproc *sim, const char *const *extra) {
  const char *src = getenv("FG_SOURCE_DIR");
  ASSERT(src);
  static char scene[PATH_MAX], port_file[PATH_MAX];
  static int n_started;
  snprintf(scene, sizeof scene, "%s/tests/sim/cells/blocks.xml", src);
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

void cu_look_at(const double eye[3], const double target[3], double roll_deg, double q[4]) {
  double z[3], x[3], y[3], n = 0;
  for (int k = 0; k < 3; k++) {
    z[k] = target[k] - eye[k];
    n += z[k] * z[k];
  }
  ASSERT(n > 0);
  for (int k = 0; k < 3; k++) z[k] /= sqrt(n);
  /* x = z × up, level; straight down, any heading will do */
  x[0] = z[1];
  x[1] = -z[0];
  x[2] = 0;
  n = hypot(x[0], x[1]);
  if (n < 1e-9) {
    x[0] = 1;
    x[1] = 0;
    n = 1;
  }
  x[0] /= n;
  x[1] /= n;
  y[0] = z[1] * x[2] - z[2] * x[1];
  y[1] = z[2] * x[0] - z[0] * x[2];
  y[2] = z[0] * x[1] - z[1] * x[0];
  const double c = cos(roll_deg * M_PI / 180), s = sin(roll_deg * M_PI / 180);
  double R[9];
  for (int r = 0; r < 3; r++) {
    R[3 * r] = c * x[r] + s * y[r];
    R[3 * r + 1] = -s * x[r] + c * y[r];
    R[3 * r + 2] = z[r];
  }
  fg_quat_from_rotmat(R, q);
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
