/* The physics mode's test helpers (cellproc.h). */
#include "cellproc.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>

#include "cellreport.h"
#include "test.h"

static modbus_t *client(int port, int unit) {
  modbus_t *c = modbus_new_tcp("127.0.0.1", port);
  ASSERT(c != NULL);
  ASSERT_EQ(modbus_set_slave(c, unit), 0);
  ASSERT_EQ(modbus_set_response_timeout(c, 10, 0), 0);
  if (modbus_connect(c) != 0) FG_TEST_FAIL("connect to %d: %s", port, modbus_strerror(errno));
  return c;
}

static void client_free(modbus_t *c) {
  modbus_close(c);
  modbus_free(c);
}

void cellproc_start(cellproc *c, const char *scene, const char *encoding, const char *dir,
                    const char *const *extra) {
  static int n_reports;
  snprintf(c->report, sizeof c->report, "%s/report%d.jsonl", dir, n_reports++);
  const char *args[24] = {"--scene", scene, "--report", c->report, "--time-scale", "0",
                          "--encoding", encoding};
  int n = 8;
  for (; extra && *extra && n < 23; extra++) args[n++] = *extra;
  args[n] = NULL;
  simproc_start(&c->p, 0, args);
  c->robot = client(c->p.port, 1);
  c->grip = client(c->p.port, 9);
}

void cellproc_stop(cellproc *c) {
  client_free(c->robot);
  client_free(c->grip);
  simproc_stop(&c->p);
}

static uint16_t s16(double v) { return (uint16_t)(int16_t)lround(v); }

void cellproc_command_start(cellproc *c, int seq, int cmd, const double p[3], const double rv[3],
                           double width, double approach, double retreat, double speed) {
  const uint16_t w[13] = {(uint16_t)seq, (uint16_t)cmd, s16(p[0] * 1e4), s16(p[1] * 1e4),
                          s16(p[2] * 1e4), s16(rv[0] * 1e3), s16(rv[1] * 1e3), s16(rv[2] * 1e3),
                          (uint16_t)lround(width * 1e4), 40, (uint16_t)lround(approach * 1e4),
                          (uint16_t)lround(retreat * 1e4), (uint16_t)lround(speed * 1e3)};
  if (modbus_write_registers(c->robot, CELLPROC_BASE, 13, w) != 13)
    FG_TEST_FAIL("write the block: %s", modbus_strerror(errno));
}

int cellproc_command(cellproc *c, int seq, int cmd, const double p[3], const double rv[3],
                     double width, double approach, double retreat) {
  cellproc_command_start(c, seq, cmd, p, rv, width, approach, retreat, 0.1);
  const double deadline = simproc_now_ms() + 60000;
  for (;;) {
    uint16_t v[2];
    ASSERT_EQ(modbus_read_registers(c->robot, CELLPROC_BASE + 13, 2, v), 2);
    if (v[0] == seq && v[1] != 1) return v[1];
    ASSERT(simproc_now_ms() < deadline);
    simproc_sleep_ms(1);
  }
}

json_t *cellproc_report(const cellproc *c, int seq) {
  char *text = simproc_read(c->report);
  ASSERT(text != NULL);
  json_t *found = cellreport_line(text, seq, c->report);
  free(text);
  return found;
}

json_t *cellproc_object(json_t *line, const char *name) {
  json_t *o;
  size_t i;
  json_array_foreach(json_object_get(line, "objects"), i, o)
    if (strcmp(json_string_value(json_object_get(o, "name")), name) == 0) return o;
  FG_TEST_FAIL("no object %s in the report", name);
  return NULL;
}

int cellproc_flag(json_t *obj, const char *key) { return json_is_true(json_object_get(obj, key)); }

double cellproc_num(json_t *obj, const char *key) {
  return json_number_value(json_object_get(obj, key));
}

int cellproc_gobj(json_t *line) {
  return (int)json_integer_value(json_object_get(json_object_get(line, "fingers"), "gobj"));
}
