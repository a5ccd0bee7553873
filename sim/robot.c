/* fieldgrip-sim's robot block (robot.h): the acknowledgement, the robot program's path at the
 * block's speed in the kinematic mode or the cell's program in the physics mode, the stop
 * register. */
#include <string.h>

#include "core/pose.h"
#include "modbus/regs.h"
#include "robot.h"

/* ---------------------------------------------------------------- robot block */

/* Register offsets of proto/modbus.md: the block fieldgrip writes, then ack, status, stop. */
int sim_robot_init(sim_robot *r, const sim_config *cfg) {
  memset(r, 0, sizeof *r);
  const int words = cfg->float32 ? 23 : 13;
  r->ack_off = words;
  r->status_off = words + 1;
  r->stop_off = words + 2;
  r->n_regs = words + 3;
  r->map = modbus_mapping_new_start_address(0, 0, 0, 0, (unsigned)cfg->base,
                                            (unsigned)r->n_regs, 0, 0);
  if (!r->map) return -1;
  r->map->tab_registers[r->ack_off] = (uint16_t)cfg->ack_init;
  if (cfg->tcp_base >= 0) {
    r->tcp_map = modbus_mapping_new_start_address(0, 0, 0, 0, (unsigned)cfg->tcp_base,
                                                  FG_TCP_POSE_WORDS, 0, 0);
    if (!r->tcp_map) return -1;
  }
  r->ack_due_ns = SIM_NEVER;
  r->done_due_ns = SIM_NEVER;
  r->tcp[0] = 0.30; /* a home pose above the table, as a robot starts at one */
  r->tcp[2] = 0.40;
  r->q[1] = 1; /* pointing down: half a turn about x */
  return 0;
}

static double f32_at(const uint16_t *w) {
  const uint32_t bits = (uint32_t)w[0] << 16 | w[1];
  float f;
  memcpy(&f, &bits, sizeof f);
  return f;
}

/* The block as the robot program reads it. */
typedef struct {
  int command;
  double p[3], rv[3], width, force, approach, retreat, speed;
} sim_block;

static void block_read(const sim_robot *r, const sim_config *cfg, sim_block *b) {
  const uint16_t *w = r->map->tab_registers;
  b->command = w[1];
  if (cfg->float32) {
    for (int i = 0; i < 3; i++) {
      b->p[i] = f32_at(&w[2 + 2 * i]);
      b->rv[i] = f32_at(&w[8 + 2 * i]);
    }
    b->width = f32_at(&w[14]);
    b->force = w[16];
    b->approach = f32_at(&w[17]);
    b->retreat = f32_at(&w[19]);
    b->speed = f32_at(&w[21]);
    return;
  }
  for (int i = 0; i < 3; i++) {
    b->p[i] = (int16_t)w[2 + i] * 1e-4;
    b->rv[i] = (int16_t)w[5 + i] * 1e-3;
  }
  b->width = w[8] * 1e-4;
  b->force = w[9];
  b->approach = w[10] * 1e-4;
  b->retreat = w[11] * 1e-4;
  b->speed = w[12] * 1e-3;
}

/* The tool's +z in the base frame: R(rv) applied to (0, 0, 1) (Rodrigues). */
static void tool_z(const double rv[3], double z[3]) {
  const double th = sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]);
  if (th < 1e-12) {
    z[0] = z[1] = 0;
    z[2] = 1;
    return;
  }
  const double k[3] = {rv[0] / th, rv[1] / th, rv[2] / th}, c = cos(th), s = sin(th);
  /* v cos + (k x v) sin + k (k . v)(1 - cos) with v = (0, 0, 1) */
  z[0] = k[1] * s + k[0] * k[2] * (1 - c);
  z[1] = -k[0] * s + k[1] * k[2] * (1 - c);
  z[2] = c + k[2] * k[2] * (1 - c);
}

static double path_length(const sim_robot *r) {
  double len = 0;
  for (int i = 1; i < r->n_way; i++) {
    double d2 = 0;
    for (int k = 0; k < 3; k++) d2 += (r->way[i][k] - r->way[i - 1][k]) * (r->way[i][k] - r->way[i - 1][k]);
    len += sqrt(d2);
  }
  return len;
}

/* Where the TCP is at time t of the motion in progress, and how it is turned (q may be NULL):
 * the tool turns from q0 to qt on the way to the first waypoint. */
static void tcp_at(const sim_robot *r, const sim_config *cfg, int64_t t, double p[3],
                   double q[4]) {
  if (cfg->time_scale == 0) { /* motions are instant: it is where it goes */
    memcpy(p, r->way[r->n_way - 1], sizeof r->way[0]);
    if (q) memcpy(q, r->qt, sizeof r->qt);
    return;
  }
  const double covered = r->speed_mps * (double)(t - r->move_t0_ns) * 1e-9 / cfg->time_scale;
  double left = covered, first = -1;
  memcpy(p, r->way[0], sizeof r->way[0]);
  for (int i = 1; i < r->n_way; i++) {
    double d[3], len = 0;
    for (int k = 0; k < 3; k++) {
      d[k] = r->way[i][k] - r->way[i - 1][k];
      len += d[k] * d[k];
    }
    len = sqrt(len);
    if (first < 0) first = len;
    if (left <= len) {
      for (int k = 0; k < 3; k++) p[k] = r->way[i - 1][k] + (len > 0 ? d[k] * left / len : 0);
      break;
    }
    left -= len;
    memcpy(p, r->way[i], sizeof r->way[i]);
  }
  if (q) fg_quat_slerp(r->q0, r->qt, first > 0 && covered < first ? covered / first : 1, q);
}

static void log_point(FILE *f, const char *name, const double p[3]) {
  fprintf(f, " %s=%.4f,%.4f,%.4f", name, p[0], p[1], p[2]);
}

/* The robot program takes the block of seq: builds the path and says how long it runs
 * (ns), or -1 when it refuses the block (a motion without a speed). */
static int64_t robot_start(sim_robot *r, const sim_config *cfg, int64_t now) {
  sim_block b;
  block_read(r, cfg, &b);
  r->n_way = 1;
  memcpy(r->way[0], r->tcp, sizeof r->tcp);
  const int posed = b.command == 1 || b.command == 2 || b.command == 5;
  memcpy(r->q0, r->q, sizeof r->q);
  memcpy(r->qt, r->q, sizeof r->q);
  if (posed) {
    fg_quat_from_rotvec(b.rv, r->qt);
    double z[3];
    tool_z(b.rv, z);
    for (int k = 0; k < 3; k++) {
      r->way[1][k] = b.p[k] - b.approach * z[k];
      r->way[2][k] = b.p[k];
      r->way[3][k] = b.p[k] - (b.command == 2 ? b.retreat * z[k] : 0);
    }
    if (b.command == 1) r->way[3][2] += b.retreat;
    r->n_way = 4;
  }
  r->speed_mps = b.speed;
  r->move_t0_ns = now;
  if (r->log) {
    fprintf(r->log, "motion seq=%u cmd=%d", r->map->tab_registers[0], b.command);
    log_point(r->log, "from", r->way[0]);
    if (posed) {
      log_point(r->log, "pre", r->way[1]);
      log_point(r->log, "pose", r->way[2]);
      log_point(r->log, "end", r->way[3]);
    }
    fprintf(r->log, " speed=%.4f approach=%.4f retreat=%.4f\n", b.speed, b.approach, b.retreat);
    fflush(r->log);
  }
  if (r->cell) {
    /* the cell runs the program; robot_advance asks it when it ends */
    const sim_cell_block cb = {r->map->tab_registers[0], b.command, {b.p[0], b.p[1], b.p[2]},
                               {b.rv[0], b.rv[1], b.rv[2]}, b.width, b.force, b.approach,
                               b.retreat, b.speed};
    char why[256];
    return sim_cell_program_start(r->cell, &cb, now, why, sizeof why) != 0 ? -1 : SIM_NEVER;
  }
  if (!posed || path_length(r) == 0) return 0;
  if (!(b.speed > 0)) return -1;
  return (int64_t)(path_length(r) / b.speed * 1e9 * cfg->time_scale);
}

/* Applies the acknowledgement and the end of the command when they are due at now. */
void sim_robot_advance(sim_robot *r, const sim_config *cfg, int64_t now) {
  uint16_t *reg = r->map->tab_registers;
  if (r->pending && now >= r->ack_due_ns) {
    /* Both in one step, as one function-16 write of the robot program would. */
    const int64_t t = r->ack_due_ns;
    reg[r->status_off] = 1;
    reg[r->ack_off] = r->pending_seq;
    r->seq = r->pending_seq;
    r->pending = 0;
    r->ack_due_ns = SIM_NEVER;
    const int64_t run = robot_start(r, cfg, t);
    if (run < 0) {
      reg[r->status_off] = 3;
      r->done_due_ns = SIM_NEVER;
    } else {
      r->moving = 1;
      r->done_due_ns = run == SIM_NEVER ? SIM_NEVER : t + run + sim_ms_to_ns(cfg->done_delay_ms);
    }
  }
  if (r->cell && r->moving && r->done_due_ns == SIM_NEVER &&
      !sim_cell_program_running(r->cell)) {
    /* the cell's program ended: done, or failed; --done-delay-ms counts from here */
    r->done_due_ns = now + sim_ms_to_ns(cfg->done_delay_ms);
    if (sim_cell_program_result(r->cell) == 3) {
      reg[r->status_off] = 3;
      r->moving = 0;
      r->done_due_ns = SIM_NEVER;
    }
  }
  if (now >= r->done_due_ns) {
    reg[r->status_off] = cfg->fail ? 3 : 2;
    r->done_due_ns = SIM_NEVER;
    if (r->moving) {
      memcpy(r->tcp, r->way[r->n_way - 1], sizeof r->tcp);
      memcpy(r->q, r->qt, sizeof r->q);
    }
    r->moving = 0;
  }
}

/* The stop register went to 1: the motion halts where it is (status 4) and nothing new
 * starts until it goes back to 0. */
static void robot_stop(sim_robot *r, const sim_config *cfg, int64_t now) {
  uint16_t *reg = r->map->tab_registers;
  r->stopped = 1;
  r->pending = 0;
  r->ack_due_ns = SIM_NEVER;
  if (r->cell) sim_cell_program_stop(r->cell, now);
  if (r->moving) {
    tcp_at(r, cfg, now, r->tcp, r->q);
    r->moving = 0;
    r->done_due_ns = SIM_NEVER;
    reg[r->status_off] = 4;
  }
  if (r->log) {
    fprintf(r->log, "stop seq=%u", r->seq);
    log_point(r->log, "at", r->tcp);
    fputc('\n', r->log);
    fflush(r->log);
  }
}

/* After a write that reached the block: the stop register first; then a seq that is nonzero,
 * not yet acknowledged and not already scheduled starts a new command, superseding one that
 * has not finished. */
void sim_robot_on_write(sim_robot *r, const sim_config *cfg, int64_t now) {
  const uint16_t *reg = r->map->tab_registers;
  sim_robot_advance(r, cfg, now);
  if (reg[r->stop_off] && !r->stopped) robot_stop(r, cfg, now);
  if (!reg[r->stop_off] && r->stopped) {
    r->stopped = 0;
    if (r->log) {
      fprintf(r->log, "run\n");
      fflush(r->log);
    }
  }
  if (r->stopped) return;
  uint16_t seq = reg[0];
  if (cfg->never_ack || seq == 0 || seq == reg[r->ack_off]) return;
  if (r->pending && seq == r->pending_seq) return;
  if (r->moving) tcp_at(r, cfg, now, r->tcp, r->q); /* superseded: the new path starts here */
  r->moving = 0;
  r->pending = 1;
  r->pending_seq = seq;
  r->ack_due_ns = now + sim_ms_to_ns(cfg->ack_delay_ms);
  r->done_due_ns = SIM_NEVER;
  sim_robot_advance(r, cfg, now);
}

/* ---------------------------------------------------------------- TCP pose */

void sim_robot_tcp_pose(const sim_robot *r, const sim_config *cfg, int64_t now, double p[3],
                        double q[4]) {
  if (r->cell) {
    sim_cell_tcp(r->cell, p, q);
  } else if (r->moving) {
    tcp_at(r, cfg, now, p, q);
  } else {
    memcpy(p, r->tcp, sizeof r->tcp);
    memcpy(q, r->q, sizeof r->q);
  }
}

void sim_robot_publish_tcp(sim_robot *r, const sim_config *cfg, int64_t now) {
  double p[3], q[4], rv[3];
  sim_robot_tcp_pose(r, cfg, now, p, q);
  fg_rotvec_from_quat(q, rv);
  uint16_t w[FG_TCP_POSE_WORDS];
  /* beyond the registers' 3.27 m (the kinematic robot has no reach): the last pose stays,
   * as a controller's registers would not wrap either */
  if (fg_tcp_pose_encode(p, rv, w) == 0) memcpy(r->tcp_map->tab_registers, w, sizeof w);
}
