#include "cellreport.h"

#include <stdlib.h>
#include <string.h>

#include "test.h"

json_t *cellreport_line(const char *text, int seq, const char *what) {
  char *copy = strdup(text), *save = NULL;
  ASSERT(copy != NULL);
  json_t *found = NULL;
  for (char *line = strtok_r(copy, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
    json_error_t e;
    json_t *j = json_loads(line, 0, &e);
    if (!j) FG_TEST_FAIL("a line of %s is not JSON (%s): %s", what, e.text, line);
    if (json_object_get(j, "command") &&
        (seq < 0 || json_integer_value(json_object_get(j, "seq")) == seq)) {
      json_decref(found);
      found = j;
    } else {
      json_decref(j);
    }
  }
  free(copy);
  if (!found) {
    if (seq < 0) FG_TEST_FAIL("%s reports no command", what);
    FG_TEST_FAIL("%s has no line for seq %d", what, seq);
  }
  return found;
}
