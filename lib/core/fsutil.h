/* Files that survive a crash: temp file, fsync, rename, fsync of the folder.
 *
 * A reader sees either the old file or the new one, never a torn one. Temp files are named
 * "<name>.tmp.<pid>.<n>" in the target's folder; fg_fs_sweep_tmp() removes leftovers of a
 * process that was killed before committing. */
#ifndef FG_CORE_FSUTIL_H
#define FG_CORE_FSUTIL_H

#include <stdio.h>
#include <stddef.h>

typedef struct fg_atomic_file {
  FILE *fp;          /* write through this; owned by the struct until commit or abort */
  char *tmp_path;    /* owned */
  char *final_path;  /* owned */
} fg_atomic_file;

/* Opens a temp file beside path. On error nothing is left on disk. */
int fg_atomic_file_open(fg_atomic_file *af, const char *path);

/* Flushes, fsyncs, renames over the final path and fsyncs the folder. Frees the struct's
 * members whether it succeeds or not; on failure the temp file is removed. */
int fg_atomic_file_commit(fg_atomic_file *af);

/* Closes and removes the temp file; safe on a zeroed or already finished struct. */
void fg_atomic_file_abort(fg_atomic_file *af);

/* Writes len bytes to path atomically. */
int fg_write_file_atomic(const char *path, const void *buf, size_t len);

/* Reads a whole file into a malloc'd buffer (NUL-terminated, not counted in *len). Files
 * larger than max_len are refused with FG_ERANGE. The caller owns *buf on success. */
int fg_read_file(const char *path, size_t max_len, char **buf, size_t *len);

/* mkdir -p with mode 0750 for created folders. */
int fg_mkdir_p(const char *path);

/* Removes a folder and everything below it; a missing path is success. */
int fg_rmtree(const char *path);

/* The FG_E* code of a failed write's errno: FG_ENOSPC for a full disk or quota (ENOSPC,
 * EDQUOT), so that callers can tell the client to free space; FG_EIO otherwise. */
int fg_io_error(int errno_value);

/* fsyncs a folder so that a rename or unlink in it is durable. */
int fg_fsync_dir(const char *path);

/* Removes "*.tmp.*" files left in one folder by a killed writer. Returns how many. */
int fg_fs_sweep_tmp(const char *dir);

/* Joins a folder and a name into a malloc'd path; NULL on allocation failure. */
char *fg_path_join(const char *dir, const char *name);

#endif
