/* Command ids that are never handed out twice, across restarts too: a client that polls a
 * 202's Location (/v1/robot/commands/{id}) after the daemon restarted must get a 404, never
 * another command's record.
 *
 * The highest id reserved so far is kept in one file under the state dir. Ids are reserved
 * in blocks (the file is rewritten atomically once per block, not per command), and a block
 * is on disk before any of its ids is handed out, so a daemon that starts again, even after
 * kill -9, starts above every id the previous one could have used. The ids skipped at a
 * restart (the rest of a block) are never used. */
#ifndef FG_DAEMON_CMD_IDS_H
#define FG_DAEMON_CMD_IDS_H

#include <stdint.h>

#define FG_CMD_IDS_BLOCK 1000

typedef struct fg_cmd_ids fg_cmd_ids;

/* Opens the high-water mark at path (a missing file: none yet) and reserves the first block
 * of this run. 0, FG_EFORMAT (the file is not a number; the detail says which file),
 * FG_EIO/FG_ENOSPC, FG_ENOMEM. On success the caller owns *out (fg_cmd_ids_free). */
int fg_cmd_ids_open(fg_cmd_ids **out, const char *path);
void fg_cmd_ids_free(fg_cmd_ids *ids);

/* The next id into *id, reserving a block first when this one is used up. Thread-safe.
 * 0, or FG_EIO/FG_ENOSPC when a block could not be reserved (no id is handed out then). */
int fg_cmd_ids_next(fg_cmd_ids *ids, uint64_t *id);

/* The first id of this run: lower ids were handed out, if at all, before the daemon
 * (re)started. */
uint64_t fg_cmd_ids_first(const fg_cmd_ids *ids);

#endif
