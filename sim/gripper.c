/* fieldgrip-sim's Robotiq gripper (gripper.h): activation, go-to at the requested speed and
 * force, the fingers kinematic (stopping on --object-width-mm) or the cell's. */
#include <string.h>

#include "gripper.h"

/* ---------------------------------------------------------------- gripper */

int sim_gripper_init(sim_gripper *g, const sim_config *cfg) {
  memset(g, 0, sizeof *g);
  g->map = modbus_mapping_new_start_address(0, 0, 0, 0, SIM_RQ_OUT, 3, SIM_RQ_IN, 3);
  if (!g->map) return -1;
  g->act_due_ns = SIM_NEVER;
  g->obj_pos = -1;
  if (cfg->object_width_mm >= 0)
    g->obj_pos = (int)lround(255.0 * (cfg->stroke_mm - cfg->object_width_mm) / cfg->stroke_mm);
  return 0;
}

/* Finger position at time t (0 open .. 255 closed). */
static double gripper_pos_at(const sim_gripper *g, int64_t t) {
  if (g->cell) {
    int pos, moving, obj;
    sim_cell_fingers_status(g->cell, &pos, &moving, &obj);
    return pos;
  }
  if (!g->moving) return g->pos;
  double travel = fabs(g->stop - g->p0);
  double done = g->rate * (double)(t - g->t0_ns) * 1e-6;
  if (done > travel) done = travel;
  return g->stop > g->p0 ? g->p0 + done : g->p0 - done;
}

/* Freezes the fingers where they are at t. */
static void gripper_halt(sim_gripper *g, int64_t t) {
  g->pos = gripper_pos_at(g, t);
  if (g->cell && g->moving) sim_cell_fingers_goto(g->cell, (int)g->pos, 255, g->force, t);
  g->moving = 0;
}

static void gripper_arrive(sim_gripper *g) {
  g->pos = g->stop;
  g->moving = 0;
  g->obj = g->contact ? 2 : 3;
  /* Holding an object draws current that grows with the force setting (x 10 mA). */
  g->cu = g->contact ? 1 + g->force * 63 / 255 : 0;
}

/* Starts a motion at time t toward the requested position at the requested speed; closing
 * past the object stops at it. */
static void gripper_start_move(sim_gripper *g, const sim_config *cfg, int target, int speed,
                               int force, int64_t t) {
  gripper_halt(g, t);
  g->pr = target;
  g->force = force;
  if (g->cell) {
    sim_cell_fingers_goto(g->cell, target, speed, force, t);
    g->moving = 1;
    g->obj = 0;
    g->cu = 0;
    g->arrive_ns = SIM_NEVER;
    return;
  }
  g->rate = 255.0 / cfg->stroke_ms * (0.25 + 0.75 * speed / 255.0);
  g->stop = target;
  g->contact = 0;
  if (g->obj_pos >= 0 && target > g->obj_pos && g->pos <= g->obj_pos) {
    g->stop = g->obj_pos;
    g->contact = 1;
  }
  g->p0 = g->pos;
  g->t0_ns = t;
  double travel = fabs(g->stop - g->p0);
  if (travel < 1e-9) {
    gripper_arrive(g);
    return;
  }
  g->moving = 1;
  g->obj = 0;
  g->cu = 0;
  g->arrive_ns = t + sim_ms_to_ns(travel / g->rate);
}

/* Applies the end of the activation and the end of a motion when they are due at now. */
void sim_gripper_advance(sim_gripper *g, const sim_config *cfg, int64_t now) {
  if (now >= g->act_due_ns) {
    int64_t t = g->act_due_ns;
    g->act_due_ns = SIM_NEVER;
    g->sta = 3;
    g->act = 1;
    g->pos = 0; /* activation ends with the fingers fully open */
    g->moving = 0;
    if (g->cell) sim_cell_fingers_goto(g->cell, 0, 255, 0, t);
    const uint16_t *reg = g->map->tab_registers;
    if ((reg[0] >> 8) & 0x08) {
      /* A go-to that waited for the activation runs now. */
      g->flt = 0;
      gripper_start_move(g, cfg, reg[1] & 0xFF, reg[2] >> 8, reg[2] & 0xFF, t);
    }
  }
  if (g->cell && g->moving) {
    /* the cell's fingers stop at the position or on something */
    int pos, moving, obj;
    sim_cell_fingers_status(g->cell, &pos, &moving, &obj);
    if (!moving) {
      g->stop = pos;
      g->contact = obj == 2 || obj == 1;
      gripper_arrive(g);
      g->obj = obj;
    }
    return;
  }
  if (g->moving && now >= g->arrive_ns) gripper_arrive(g);
}

/* After a write that reached the request registers: reset, activation or a go-to. */
void sim_gripper_on_write(sim_gripper *g, const sim_config *cfg, int64_t now) {
  const uint16_t *reg = g->map->tab_registers;
  int action = reg[0] >> 8;
  int ract = action & 0x01, rgto = (action >> 3) & 0x01;
  g->gto = rgto;
  if (!ract) {
    gripper_halt(g, now);
    g->act = 0;
    g->sta = 0;
    g->obj = 0;
    g->cu = 0;
    g->act_due_ns = SIM_NEVER;
    g->flt = rgto ? SIM_RQ_FLT_NOT_ACTIVATED : 0;
    return;
  }
  if (g->sta == 0) {
    gripper_halt(g, now);
    g->act = 1; /* gACT echoes rACT; gSTA tells when the activation is complete */
    g->sta = 1;
    g->obj = 0;
    g->act_due_ns = now + sim_ms_to_ns(cfg->activation_ms);
  }
  if (g->sta == 1) {
    g->flt = rgto ? SIM_RQ_FLT_ACTION_DELAYED : 0;
    sim_gripper_advance(g, cfg, now); /* an activation of 0 ms completes at once */
    return;
  }
  g->flt = 0;
  if (rgto)
    gripper_start_move(g, cfg, reg[1] & 0xFF, reg[2] >> 8, reg[2] & 0xFF, now);
  else
    gripper_halt(g, now);
}

/* Writes the status (input) registers from the state at now. */
void sim_gripper_publish(sim_gripper *g, int64_t now) {
  uint16_t *in = g->map->tab_input_registers;
  int status = g->act | g->gto << 3 | g->sta << 4 | g->obj << 6;
  long po = lround(gripper_pos_at(g, now));
  if (po < 0) po = 0;
  if (po > 255) po = 255;
  in[0] = (uint16_t)(status << 8);
  in[1] = (uint16_t)(g->flt << 8 | g->pr);
  in[2] = (uint16_t)(po << 8 | g->cu);
}
