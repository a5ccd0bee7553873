/* fieldgrip-sim in its physics mode for the tests: started on a scene with a report file and
 * motions at once (--time-scale 0), a libmodbus client per peer, int16 blocks of the robot
 * program run to their end, and the report read back as JSON. Every helper succeeds or fails
 * the test (tests/test.h); call simproc_init first. */
#ifndef FG_TEST_CELLPROC_H
#define FG_TEST_CELLPROC_H

#include <jansson.h>
#include <limits.h>
#include <modbus.h>

#include "simproc.h"

#define CELLPROC_BASE 128 /* the robot block's first register */

typedef struct cellproc {
  simproc p;
  modbus_t *robot, *grip; /* units 1 and 9 */
  char report[PATH_MAX + 32];
} cellproc;

/* Starts the simulator on scene (a path) with encoding "int16" or "float32" and the options in
 * extra (NULL-terminated; NULL: none); the report is a new file in dir. */
void cellproc_start(cellproc *c, const char *scene, const char *encoding, const char *dir,
                    const char *const *extra);

/* Closes the clients and stops the simulator (which must exit with status 0). */
void cellproc_stop(cellproc *c);

/* Writes an int16 block (proto/modbus.md) of command cmd at pose p (metres) and rotation
 * vector rv, force 40 N, speed 0.1 m/s, and waits until seq is acknowledged and no longer
 * busy; returns the status (2 done, 3 failed, 4 stopped). */
int cellproc_command(cellproc *c, int seq, int cmd, const double p[3], const double rv[3],
                     double width, double approach, double retreat);

/* Writes that block with speed (m/s) and returns at once. */
void cellproc_command_start(cellproc *c, int seq, int cmd, const double p[3], const double rv[3],
                           double width, double approach, double retreat, double speed);

/* The report's last line about seq, parsed; the caller decrefs. */
json_t *cellproc_report(const cellproc *c, int seq);

/* The object called name in a report line (borrowed). */
json_t *cellproc_object(json_t *line, const char *name);

/* A boolean and a number of a report object; gOBJ of a report line. */
int cellproc_flag(json_t *obj, const char *key);
double cellproc_num(json_t *obj, const char *key);
int cellproc_gobj(json_t *line);

#endif
