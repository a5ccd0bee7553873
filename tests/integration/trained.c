/* The trained fixture; see trained.h. */
#include "trained.h"

#include "grasp_util.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

static char g_fixture[PATH_MAX];

/* What the fixture is built with: a relinked daemon or scenegen builds it again. */
static char *build_key(const char *scenegen) {
  struct stat a, b;
  if (stat(h_daemon_path(), &a) != 0 || stat(scenegen, &b) != 0)
    FG_TEST_FAIL("stat %s, %s: %s", h_daemon_path(), scenegen, strerror(errno));
  return h_fmt("fieldgripd %lld %lld\nscenegen %lld %lld\n", (long long)a.st_size,
               (long long)a.st_mtime, (long long)b.st_size, (long long)b.st_mtime);
}

/* Runs argv to its end with its output into log; its exit status. */
static int run(const char *const *argv, const char *log) {
  pid_t pid = fork();
  if (pid < 0) FG_TEST_FAIL("fork: %s", strerror(errno));
  if (pid == 0) {
    int fd = open(log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
    }
    execv(argv[0], (char *const *)argv);
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid) FG_TEST_FAIL("waitpid: %s", strerror(errno));
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

const char *f_fixture(const char *scenegen) {
  if (g_fixture[0]) return g_fixture;
  const char *given = getenv("FG_IT_FIXTURE");
  if (given && *given) {
    char *keyfile = h_fmt("%s/key", given);
    if (access(keyfile, R_OK) != 0)
      FG_TEST_FAIL("FG_IT_FIXTURE=%s holds no built fixture (no %s)", given, keyfile);
    printf("the trained fixture of another build of this tree: %s\n", given);
    snprintf(g_fixture, sizeof g_fixture, "%s", given);
    free(keyfile);
    return g_fixture;
  }
  const char *build = getenv("FG_BUILD_DIR");
  if (!build) FG_TEST_FAIL("FG_BUILD_DIR is not set (meson test sets it)");
  char *dir = h_fmt("%s/tests/integration/it-fixture", build);
  char *lock = h_fmt("%s.lock", dir), *keyfile = h_fmt("%s/key", dir);
  int fd = open(lock, O_RDWR | O_CREAT, 0644);
  if (fd < 0 || flock(fd, LOCK_EX) != 0) FG_TEST_FAIL("lock %s: %s", lock, strerror(errno));
  char *key = build_key(scenegen), *have = h_read_file(keyfile, NULL);
  if (!have || strcmp(have, key) != 0) {
    printf("building the trained fixture %s (about a minute on two idle cores)\n", dir);
    char *tmp = h_fmt("%s.new", dir), *log = h_fmt("%s.log", dir);
    char *builder = h_fmt("%s/tests/integration/it_make_fixture", build);
    const char *argv[] = {builder, h_daemon_path(), scenegen, tmp, NULL};
    h_remove_tree(tmp);
    if (run(argv, log) != 0) {
      char *out = h_read_file(log, NULL);
      FG_TEST_FAIL("the trained fixture could not be built; %s said:\n%s", builder,
                   out ? out : "(nothing)");
    }
    char *tmpkey = h_fmt("%s/key", tmp);
    h_write_file(tmpkey, key, strlen(key));
    h_remove_tree(dir);
    if (rename(tmp, dir) != 0)
      FG_TEST_FAIL("rename %s to %s: %s", tmp, dir, strerror(errno));
    free(tmpkey);
    free(builder);
    free(log);
    free(tmp);
  }
  flock(fd, LOCK_UN);
  close(fd);
  snprintf(g_fixture, sizeof g_fixture, "%s", dir);
  free(have);
  free(key);
  free(keyfile);
  free(lock);
  free(dir);
  return g_fixture;
}

char *f_dataset(const char *scenegen) {
  char *from = h_fmt("%s/sg", f_fixture(scenegen));
  char *imports = h_fmt("%s/imports", h_tmpdir()), *to = h_fmt("%s/sg", imports);
  h_copy_tree(from, to);
  g_dataset_at(to);
  free(to);
  free(from);
  return imports;
}

void f_scene(const char *from, const char *as) {
  if (!g_fixture[0]) FG_TEST_FAIL("f_scene before f_fixture");
  char *src = h_fmt("%s/scenes/%s", g_fixture, from);
  char *dst = h_fmt("%s/scenes/%s", h_state_dir(), as);
  h_copy_tree(src, dst);
  free(dst);
  free(src);
}
