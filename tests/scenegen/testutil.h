/* Helpers shared by the scene generator's tests: temporary folders, running
 * fieldgrip-scenegen (its output optionally to a file), reading files, projecting world
 * points into a view. */
#ifndef SG_TESTUTIL_H
#define SG_TESTUTIL_H

#include "test.h"

#include <fcntl.h>
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

/* Runs program with the given arguments (NULL-terminated, without argv[0]), its stdout and
 * stderr going to the file log_path when that is not NULL; returns its exit status, or -1
 * when it did not exit normally. */
static inline int sg_test_run_logged(const char *program, const char *const *args,
                                     const char *log_path) {
  const char *argv[32];
  int n = 0;
  argv[n++] = program;
  while (*args && n < 31) argv[n++] = *args++;
  argv[n] = NULL;
  posix_spawn_file_actions_t fa;
  ASSERT(posix_spawn_file_actions_init(&fa) == 0);
  if (log_path) {
    ASSERT(posix_spawn_file_actions_addopen(&fa, 2, log_path, O_WRONLY | O_CREAT | O_TRUNC,
                                            0600) == 0);
    ASSERT(posix_spawn_file_actions_adddup2(&fa, 2, 1) == 0);
  }
  pid_t pid;
  int rc = posix_spawn(&pid, program, &fa, NULL, (char *const *)argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) FG_TEST_FAIL("cannot start %s: %s", program, strerror(rc));
  int status;
  ASSERT(waitpid(pid, &status, 0) == pid);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/* sg_test_run_logged with the test's own stdout and stderr. */
static inline int sg_test_run(const char *program, const char *const *args) {
  return sg_test_run_logged(program, args, NULL);
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
