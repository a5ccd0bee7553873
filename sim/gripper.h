/* The Robotiq gripper that fieldgrip-sim plays (gripper.c). */
#ifndef FG_SIM_GRIPPER_H
#define FG_SIM_GRIPPER_H

#include <modbus.h>
#include <stdint.h>

#include "config.h"

/* The gripper: status bits, finger position and the motion in progress. */
typedef struct {
  modbus_mapping_t *map;   /* holding 0x03E8..0x03EA, input 0x07D0..0x07D2 */
  int act, gto, sta, obj, flt, pr, cu;
  double pos;              /* finger position, 0 open .. 255 closed, when not moving */
  int64_t act_due_ns;      /* end of the activation in progress; SIM_NEVER when none */
  int moving;              /* a motion from p0 (at t0_ns) toward stop is in progress */
  int contact;             /* the motion ends on the object */
  int force;               /* rFR of the motion in progress */
  int64_t t0_ns, arrive_ns;
  double p0, stop;
  double rate;             /* position units per ms */
  int obj_pos;             /* finger position at the object; -1 without an object */
  sim_cell *cell;          /* the physics mode's cell (which moves the fingers), or NULL */
} sim_gripper;

/* Its registers, then before every request sim_gripper_advance to now; sim_gripper_on_write
 * after a write that reached it; sim_gripper_publish writes its status registers. 0, or -1
 * out of memory. */
int sim_gripper_init(sim_gripper *g, const sim_config *cfg);
void sim_gripper_advance(sim_gripper *g, const sim_config *cfg, int64_t now);
void sim_gripper_on_write(sim_gripper *g, const sim_config *cfg, int64_t now);
void sim_gripper_publish(sim_gripper *g, int64_t now);

#endif
