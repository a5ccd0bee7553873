/* Fuzz target for the daemon's INI configuration: the input is the configuration file; any
 * input either loads or fails with an error message, never crashes or leaks. */
#include "conf/conf.h"

#include "fuzz_file.h"

#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *path = fuzz_file_write("fieldgripd.conf", data, size);
  fg_conf *conf = NULL;
  char err[256] = "";
  int rc = fg_conf_load(path, &conf, err, sizeof err);
  if (rc != 0) {
    if (conf || rc > 0) abort();
    return 0;
  }
  if (!conf) abort();
  (void)fg_conf_threads(conf);
  fg_conf_free(conf);
  return 0;
}
