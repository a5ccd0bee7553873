/* Unit tests of the robot's command ids (daemon/robot/cmd_ids.c): a store opened again, as after a
 * restart or kill -9, starts above every id the previous one could have handed out, and a
 * block is reserved on disk before its first id is used. */
#include "test.h"

#include "robot/cmd_ids.h"
#include "core/error.h"
#include "core/fsutil.h"

#include <stdlib.h>
#include <unistd.h>

int main(void) {
  char tmpdir[] = "/tmp/fg-test-cmd-ids-XXXXXX";
  ASSERT(mkdtemp(tmpdir));
  char *path = fg_path_join(tmpdir, "command_ids");
  fg_cmd_ids *ids;
  ASSERT_OK(fg_cmd_ids_open(&ids, path));
  ASSERT_EQ(fg_cmd_ids_first(ids), 1u);
  uint64_t id = 0, last = 0;
  /* past the first block: the second is reserved on the way */
  for (int i = 0; i < FG_CMD_IDS_BLOCK + 5; i++) {
    ASSERT_OK(fg_cmd_ids_next(ids, &id));
    ASSERT_EQ(id, last + 1);
    last = id;
  }
  char *text;
  size_t len;
  ASSERT_OK(fg_read_file(path, 64, &text, &len));
  ASSERT(strtoull(text, NULL, 10) >= last);
  free(text);
  fg_cmd_ids_free(ids); /* no write at the end: the reservation is all a restart needs */

  ASSERT_OK(fg_cmd_ids_open(&ids, path));
  ASSERT(fg_cmd_ids_first(ids) > last);
  ASSERT_OK(fg_cmd_ids_next(ids, &id));
  ASSERT_EQ(id, fg_cmd_ids_first(ids));
  fg_cmd_ids_free(ids);

  ASSERT_OK(fg_write_file_atomic(path, "twelve\n", 7));
  ASSERT_ERR(fg_cmd_ids_open(&ids, path), FG_EFORMAT, "command id");
  free(path);
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("cmd_ids: ok\n");
  return 0;
}
