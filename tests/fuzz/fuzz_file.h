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

static char fuzz_file_dir[256];
static char fuzz_file_path[512];

/* At a normal exit (libFuzzer's -max_total_time, -runs): the file and its folder go. A crash
 * leaves them; run-libfuzzer.sh points TMPDIR into its own work folder, which it removes. */
static void fuzz_file_cleanup(void) {
  if (fuzz_file_path[0]) unlink(fuzz_file_path);
  rmdir(fuzz_file_dir);
}

/* Writes data to DIR/name, DIR being a private folder made on the first call under $TMPDIR
 * (removed at a normal exit); returns the file's path (static storage) or aborts, since a
 * target that cannot write its input would only hide failures. One name per process. */
static const char *fuzz_file_write(const char *name, const uint8_t *data, size_t size) {
  if (!fuzz_file_dir[0]) {
    const char *tmp = getenv("TMPDIR");
    snprintf(fuzz_file_dir, sizeof fuzz_file_dir, "%s/fg-fuzz-XXXXXX",
             tmp && tmp[0] ? tmp : "/tmp");
    if (!mkdtemp(fuzz_file_dir)) abort();
    atexit(fuzz_file_cleanup);
  }
  snprintf(fuzz_file_path, sizeof fuzz_file_path, "%s/%s", fuzz_file_dir, name);
  int fd = open(fuzz_file_path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
  if (fd < 0) abort();
  size_t off = 0;
  while (off < size) {
    ssize_t w = write(fd, data + off, size - off);
    if (w <= 0) abort();
    off += (size_t)w;
  }
  close(fd);
  return fuzz_file_path;
}

#endif
