/* For fuzz targets whose parser reads a file by path (configuration, transforms.json,
 * checkpoints): the input is written to one private file per process, rewritten for every
 * input, so the parser sees exactly the fuzzed bytes through its real open/read path. */
#ifndef FG_FUZZ_FILE_H
#define FG_FUZZ_FILE_H

#include <fcntl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Writes data to DIR/name, DIR being a private folder made on the first call (removed at
 * exit); returns the file's path (static storage) or aborts, since a target that cannot write
 * its input would only hide failures. */
static const char *fuzz_file_write(const char *name, const uint8_t *data, size_t size) {
  static char dir[256];
  static char path[512];
  if (!dir[0]) {
    const char *tmp = getenv("TMPDIR");
    snprintf(dir, sizeof dir, "%s/fg-fuzz-XXXXXX", tmp && tmp[0] ? tmp : "/tmp");
    if (!mkdtemp(dir)) abort();
  }
  snprintf(path, sizeof path, "%s/%s", dir, name);
  int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
  if (fd < 0) abort();
  size_t off = 0;
  while (off < size) {
    ssize_t w = write(fd, data + off, size - off);
    if (w <= 0) abort();
    off += (size_t)w;
  }
  close(fd);
  return path;
}

#endif
