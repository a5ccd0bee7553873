/* Helpers shared by the scene generator's tests: temporary folders, running
 * fieldgrip-scenegen, reading files, projecting world points into a view. */
#ifndef SG_TESTUTIL_H
#define SG_TESTUTIL_H

#include "test.h"

#include <spawn.h>
#include <stdint.h>
#include <sys/wait.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "io/camera.h"

extern char **environ;

/* A fresh folder under $TMPDIR (or /tmp); the caller removes it with fg_rmtree and frees the
 * string. */
static inline char *sg_test_tmpdir(const char *tag) {
  const char *base = getenv("TMPDIR");
  char tmpl[512];
  snprintf(tmpl, sizeof tmpl, "%s/fg-%s-XXXXXX", base && *base ? base : "/tmp", tag);
  ASSERT(mkdtemp(tmpl) != NULL);
  char *dir = strdup(tmpl);
  ASSERT(dir != NULL);
  return dir;
}

/* Runs program with the given arguments (NULL-terminated, without argv[0]); returns its exit
 * status, or -1 when it did not exit normally. */
static inline int sg_test_run(const char *program, const char *const *args) {
  const char *argv[32];
  int n = 0;
  argv[n++] = program;
  while (*args && n < 31) argv[n++] = *args++;
  argv[n] = NULL;
  pid_t pid;
  int rc = posix_spawn(&pid, program, NULL, NULL, (char *const *)argv, environ);
  if (rc != 0) FG_TEST_FAIL("cannot start %s: %s", program, strerror(rc));
  int status;
  ASSERT(waitpid(pid, &status, 0) == pid);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/* The whole file dir/name; the caller frees *buf. */
static inline void sg_test_read(const char *dir, const char *name, char **buf, size_t *len) {
  char *path = fg_path_join(dir, name);
  ASSERT(path != NULL);
  int rc = fg_read_file(path, (size_t)1 << 30, buf, len);
  if (rc != 0) FG_TEST_FAIL("reading %s: %s", path, fg_error_detail());
  free(path);
}

/* Projects p_world into a pinhole camera with an OpenGL camera-to-world pose: returns 0 when
 * the point is behind the camera, else 1 with continuous pixel coordinates (u, v). */
static inline int sg_test_project(const fg_camera *cam, const double T_world_cam[16],
                                  const double p_world[3], double *u, double *v) {
  const double *T = T_world_cam;
  double d[3] = {p_world[0] - T[3], p_world[1] - T[7], p_world[2] - T[11]};
  double pc[3];
  for (int i = 0; i < 3; i++) pc[i] = T[i] * d[0] + T[4 + i] * d[1] + T[8 + i] * d[2];
  if (pc[2] >= 0) return 0;
  *u = cam->cx + cam->fl_x * pc[0] / -pc[2];
  *v = cam->cy - cam->fl_y * pc[1] / -pc[2];
  return 1;
}

#endif
