/* Secret files; see secret.h. */
#include "secret.h"

#include "core/error.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

void fg_secret_free(char *secret) {
  if (!secret) return;
  explicit_bzero(secret, strlen(secret));
  free(secret);
}

int fg_secret_read(const char *path, char **out) {
  *out = NULL;
  int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOCTTY);
  if (fd < 0) {
    const int e = errno;
    return fg_fail(e == ENOENT ? FG_ENOENT : FG_EIO, "cannot open %s: %s", path, strerror(e));
  }
  /* the mode of what was opened, not of what the name points to a moment later */
  struct stat st;
  if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    close(fd);
    return fg_fail(FG_EINVAL, "%s is not a regular file", path);
  }
  if (st.st_mode & (S_IRWXG | S_IRWXO)) {
    close(fd);
    return fg_fail(FG_EPERM, "%s may be read or written by group or others (mode %04o); "
                   "make it the daemon's alone: chmod 600 %s", path,
                   (unsigned)(st.st_mode & 07777), path);
  }
  char *buf = malloc(FG_SECRET_MAX_BYTES + 2);
  if (!buf) {
    close(fd);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  size_t len = 0;
  while (len < FG_SECRET_MAX_BYTES + 1) {
    ssize_t n = read(fd, buf + len, FG_SECRET_MAX_BYTES + 1 - len);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int e = errno;
      close(fd);
      fg_secret_free(buf);
      return fg_fail(FG_EIO, "cannot read %s: %s", path, strerror(e));
    }
    if (n == 0) break;
    len += (size_t)n;
  }
  close(fd);
  buf[len] = '\0';
  const char *why = NULL;
  if (len > FG_SECRET_MAX_BYTES) why = "is longer than 4096 bytes";
  if (!why && len > 0 && buf[len - 1] == '\n') buf[--len] = '\0';
  if (!why && len > 0 && buf[len - 1] == '\r') buf[--len] = '\0';
  if (!why && len == 0) why = "is empty; write the token into it (one line)";
  for (size_t i = 0; !why && i < len; i++)
    if ((unsigned char)buf[i] < 0x20 || buf[i] == 0x7f)
      why = "holds more than one line or a control character; keep the token alone on one line";
  if (why) {
    fg_secret_free(buf);
    return fg_fail(FG_EINVAL, "%s %s", path, why);
  }
  *out = buf;
  return 0;
}
