#include "cmd_ids.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/fsutil.h"

struct fg_cmd_ids {
  char *path;
  pthread_mutex_t lock;
  uint64_t first;    /* this run's first id */
  uint64_t next;     /* the next id to hand out */
  uint64_t reserved; /* the highest id on disk: next may go up to it */
};

/* Writes the new high-water mark. Under the lock (or before the store is shared). */
static int reserve_locked(fg_cmd_ids *ids) {
  const uint64_t top = ids->reserved + FG_CMD_IDS_BLOCK;
  char text[32];
  int n = snprintf(text, sizeof text, "%" PRIu64 "\n", top);
  FG_TRY(fg_write_file_atomic(ids->path, text, (size_t)n));
  ids->reserved = top;
  return 0;
}

int fg_cmd_ids_open(fg_cmd_ids **out, const char *path) {
  *out = NULL;
  fg_cmd_ids *ids = calloc(1, sizeof *ids);
  if (!ids || !(ids->path = strdup(path))) {
    free(ids);
    return FG_ENOMEM;
  }
  pthread_mutex_init(&ids->lock, NULL);
  char *text = NULL;
  size_t len;
  int rc = fg_read_file(path, 64, &text, &len);
  if (rc == 0) {
    char *end;
    ids->reserved = strtoull(text, &end, 10);
    if (end == text || (*end && *end != '\n') || ids->reserved > UINT64_MAX / 2)
      rc = fg_fail(FG_EFORMAT, "%s does not hold a command id; remove it (command ids then "
                   "start again at 1)", path);
  } else if (rc == FG_ENOENT) {
    rc = 0;
  }
  free(text);
  if (rc == 0) rc = reserve_locked(ids);
  if (rc < 0) {
    fg_cmd_ids_free(ids);
    return rc;
  }
  ids->first = ids->next = ids->reserved - FG_CMD_IDS_BLOCK + 1;
  *out = ids;
  return 0;
}

void fg_cmd_ids_free(fg_cmd_ids *ids) {
  if (!ids) return;
  pthread_mutex_destroy(&ids->lock);
  free(ids->path);
  free(ids);
}

int fg_cmd_ids_next(fg_cmd_ids *ids, uint64_t *id) {
  pthread_mutex_lock(&ids->lock);
  int rc = ids->next > ids->reserved ? reserve_locked(ids) : 0;
  if (rc == 0) *id = ids->next++;
  pthread_mutex_unlock(&ids->lock);
  return rc;
}

uint64_t fg_cmd_ids_first(const fg_cmd_ids *ids) { return ids->first; }
