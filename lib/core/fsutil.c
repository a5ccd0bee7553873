#include "core/fsutil.h"
#include "core/error.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

char *fg_path_join(const char *dir, const char *name) {
  size_t a = strlen(dir), b = strlen(name);
  char *p = malloc(a + b + 2);
  if (!p) return NULL;
  memcpy(p, dir, a);
  size_t n = a;
  if (n > 0 && p[n - 1] != '/') p[n++] = '/';
  memcpy(p + n, name, b + 1);
  return p;
}

int fg_io_error(int errno_value) {
  return errno_value == ENOSPC || errno_value == EDQUOT ? FG_ENOSPC : FG_EIO;
}

static char *dir_of(const char *path) {
  const char *slash = strrchr(path, '/');
  if (!slash) return strdup(".");
  if (slash == path) return strdup("/");
  return strndup(path, (size_t)(slash - path));
}

int fg_fsync_dir(const char *path) {
  int fd = open(path, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return fg_fail(FG_EIO, "cannot open folder %s: %s", path, strerror(errno));
  int rc = fsync(fd);
  int e = errno;
  close(fd);
  if (rc != 0) return fg_fail(fg_io_error(e), "fsync of folder %s failed: %s", path, strerror(e));
  return 0;
}

int fg_atomic_file_open(fg_atomic_file *af, const char *path) {
  static atomic_uint counter;
  memset(af, 0, sizeof *af);
  size_t n = strlen(path) + 64;
  af->tmp_path = malloc(n);
  af->final_path = strdup(path);
  if (!af->tmp_path || !af->final_path) {
    fg_atomic_file_abort(af);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  snprintf(af->tmp_path, n, "%s.tmp.%ld.%u", path, (long)getpid(), atomic_fetch_add(&counter, 1));
  int fd = open(af->tmp_path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
  if (fd < 0) {
    int e = errno;
    free(af->tmp_path);
    af->tmp_path = NULL;
    fg_atomic_file_abort(af);
    return fg_fail(fg_io_error(e), "cannot create %s: %s", path, strerror(e));
  }
  af->fp = fdopen(fd, "wb");
  if (!af->fp) {
    close(fd);
    fg_atomic_file_abort(af);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  return 0;
}

void fg_atomic_file_abort(fg_atomic_file *af) {
  if (af->fp) fclose(af->fp);
  if (af->tmp_path) unlink(af->tmp_path);
  free(af->tmp_path);
  free(af->final_path);
  memset(af, 0, sizeof *af);
}

int fg_atomic_file_commit(fg_atomic_file *af) {
  int rc = 0;
  if (fflush(af->fp) != 0 || ferror(af->fp))
    rc = fg_fail(fg_io_error(errno), "write to %s failed: %s", af->final_path, strerror(errno));
  else if (fsync(fileno(af->fp)) != 0)
    rc = fg_fail(fg_io_error(errno), "fsync of %s failed: %s", af->final_path, strerror(errno));
  int close_rc = fclose(af->fp);
  af->fp = NULL;
  if (rc == 0 && close_rc != 0)
    rc = fg_fail(fg_io_error(errno), "close of %s failed: %s", af->final_path, strerror(errno));
  if (rc == 0 && rename(af->tmp_path, af->final_path) != 0)
    rc = fg_fail(fg_io_error(errno), "rename to %s failed: %s", af->final_path, strerror(errno));
  if (rc == 0) {
    free(af->tmp_path);
    af->tmp_path = NULL; /* renamed: nothing to remove */
    char *dir = dir_of(af->final_path);
    rc = dir ? fg_fsync_dir(dir) : fg_fail(FG_ENOMEM, "out of memory");
    free(dir);
  }
  fg_atomic_file_abort(af);
  return rc;
}

int fg_write_file_atomic(const char *path, const void *buf, size_t len) {
  fg_atomic_file af;
  FG_TRY(fg_atomic_file_open(&af, path));
  if (len > 0 && fwrite(buf, 1, len, af.fp) != len) {
    int e = errno;
    fg_atomic_file_abort(&af);
    return fg_fail(fg_io_error(e), "write to %s failed: %s", path, strerror(e));
  }
  return fg_atomic_file_commit(&af);
}

int fg_read_file(const char *path, size_t max_len, char **buf, size_t *len) {
  *buf = NULL;
  *len = 0;
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    int e = errno;
    return fg_fail(e == ENOENT ? FG_ENOENT : FG_EIO, "cannot open %s: %s", path, strerror(e));
  }
  struct stat st;
  if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    close(fd);
    return fg_fail(FG_EIO, "%s is not a regular file", path);
  }
  if ((unsigned long long)st.st_size > max_len) {
    close(fd);
    return fg_fail(FG_ERANGE, "%s is %lld bytes, more than the limit of %zu", path,
                   (long long)st.st_size, max_len);
  }
  size_t size = (size_t)st.st_size;
  char *p = malloc(size + 1);
  if (!p) {
    close(fd);
    return fg_fail(FG_ENOMEM, "out of memory reading %s", path);
  }
  size_t got = 0;
  while (got < size) {
    ssize_t r = read(fd, p + got, size - got);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    got += (size_t)r;
  }
  close(fd);
  if (got != size) {
    free(p);
    return fg_fail(FG_EIO, "short read of %s", path);
  }
  p[size] = '\0';
  *buf = p;
  *len = size;
  return 0;
}

int fg_mkdir_p(const char *path) {
  char *p = strdup(path);
  if (!p) return fg_fail(FG_ENOMEM, "out of memory");
  for (char *s = p + 1;; s++) {
    if (*s == '/' || *s == '\0') {
      char c = *s;
      *s = '\0';
      if (mkdir(p, 0750) != 0 && errno != EEXIST) {
        int e = errno;
        int rc = fg_fail(fg_io_error(e), "cannot create folder %s: %s", p, strerror(e));
        free(p);
        return rc;
      }
      *s = c;
      if (c == '\0') break;
    }
  }
  free(p);
  struct stat st;
  if (stat(path, &st) != 0 || !S_ISDIR(st.st_mode))
    return fg_fail(FG_EIO, "%s exists and is not a folder", path);
  return 0;
}

int fg_rmtree(const char *path) {
  struct stat st;
  if (lstat(path, &st) != 0) return errno == ENOENT ? 0 : fg_fail(FG_EIO, "cannot stat %s", path);
  if (!S_ISDIR(st.st_mode)) {
    if (unlink(path) != 0) return fg_fail(FG_EIO, "cannot remove %s: %s", path, strerror(errno));
    return 0;
  }
  DIR *d = opendir(path);
  if (!d) return fg_fail(FG_EIO, "cannot open folder %s: %s", path, strerror(errno));
  int rc = 0;
  struct dirent *e;
  while (rc == 0 && (e = readdir(d)) != NULL) {
    if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0) continue;
    char *child = fg_path_join(path, e->d_name);
    rc = child ? fg_rmtree(child) : fg_fail(FG_ENOMEM, "out of memory");
    free(child);
  }
  closedir(d);
  if (rc == 0 && rmdir(path) != 0)
    rc = fg_fail(FG_EIO, "cannot remove folder %s: %s", path, strerror(errno));
  return rc;
}

int fg_fs_sweep_tmp(const char *dir) {
  DIR *d = opendir(dir);
  if (!d) return 0;
  int n = 0;
  struct dirent *e;
  while ((e = readdir(d)) != NULL) {
    if (!strstr(e->d_name, ".tmp.")) continue;
    char *p = fg_path_join(dir, e->d_name);
    if (p && unlink(p) == 0) n++;
    free(p);
  }
  closedir(d);
  return n;
}
