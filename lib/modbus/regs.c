#include "modbus/regs.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "core/error.h"

/* ---------------------------------------------------------------- pose-registers */

int fg_pose_block_words(fg_pose_encoding e) {
  return e == FG_POSE_FLOAT32 ? FG_POSE_WORDS_FLOAT32 : FG_POSE_WORDS_INT16;
}

int fg_pose_ack_offset(fg_pose_encoding e) { return fg_pose_block_words(e); }

int fg_pose_stop_offset(fg_pose_encoding e) { return fg_pose_block_words(e) + 2; }

uint16_t fg_seq_next(uint16_t s) { return s == 65535 ? 1 : (uint16_t)(s + 1); }

void fg_float32_to_words(float v, uint16_t w[2]) {
  uint32_t bits;
  memcpy(&bits, &v, sizeof bits);
  w[0] = (uint16_t)(bits >> 16);
  w[1] = (uint16_t)(bits & 0xFFFF);
}

float fg_float32_from_words(const uint16_t w[2]) {
  const uint32_t bits = (uint32_t)w[0] << 16 | w[1];
  float v;
  memcpy(&v, &bits, sizeof v);
  return v;
}

/* A signed value in units of `unit` (0.0001 m, 0.001 rad) as an int16 register, rounded half
 * away from zero; FG_ERANGE naming it when it does not fit. */
static int put_int16(const char *field, double v, double per_unit, const char *unit_name,
                     uint16_t *w) {
  const double r = round(v * per_unit);
  if (!(r >= -32768.0 && r <= 32767.0))
    return fg_fail(FG_ERANGE, "%s = %g does not fit the int16 encoding (%g .. %g %s; use "
                   "[robot] encoding = float32 for larger values)", field, v,
                   -32768.0 / per_unit, 32767.0 / per_unit, unit_name);
  *w = (uint16_t)(int16_t)r;
  return 0;
}

/* An unsigned length in units of 1/per_unit (0.1 mm, 1 mm/s) as a u16 register. */
static int put_uint16(const char *field, double v, double per_unit, const char *unit_name,
                      uint16_t *w) {
  const double r = round(v * per_unit);
  if (!(r >= 0.0 && r <= 65535.0))
    return fg_fail(FG_ERANGE, "%s = %g %s does not fit the int16 encoding (0 .. %g %s)", field,
                   v, unit_name, 65535.0 / per_unit, unit_name);
  *w = (uint16_t)r;
  return 0;
}

/* A finite value as float32 words; FG_ERANGE naming it when float32 cannot hold it. */
static int put_float32(const char *field, double v, const char *unit_name, uint16_t w[2]) {
  const float f = (float)v;
  if (!isfinite(f)) return fg_fail(FG_ERANGE, "%s = %g %s exceeds float32", field, v, unit_name);
  fg_float32_to_words(f, w);
  return 0;
}

int fg_pose_block_encode(const fg_pose_block *b, fg_pose_encoding e, uint16_t *w) {
  static const char *const pn[3] = {"x", "y", "z"}, *const rn[3] = {"rx", "ry", "rz"};
  if (b->seq == 0) return fg_fail(FG_EINVAL, "seq 0 is never sent");
  if (b->command < FG_ROBOT_NOOP || b->command > FG_ROBOT_MOVE)
    return fg_fail(FG_EINVAL, "unknown robot command %d (0..5)", b->command);
  for (int i = 0; i < 3; i++) {
    if (!isfinite(b->p_world_m[i]) || !isfinite(b->rotvec_rad[i]))
      return fg_fail(FG_EINVAL, "the pose is not finite");
  }
  static const char *const ln[4] = {"width", "approach", "retreat", "speed"};
  const double lv[4] = {b->width_m, b->approach_m, b->retreat_m, b->speed_mps};
  for (int i = 0; i < 4; i++) {
    if (!isfinite(lv[i])) return fg_fail(FG_EINVAL, "%s = %g is not finite", ln[i], lv[i]);
    if (lv[i] < 0) return fg_fail(FG_ERANGE, "%s = %g: expected >= 0", ln[i], lv[i]);
  }
  if (b->force_n < 0 || b->force_n > 65535)
    return fg_fail(FG_ERANGE, "force = %d N: expected 0 .. 65535", b->force_n);
  w[0] = b->seq;
  w[1] = (uint16_t)b->command;
  if (e == FG_POSE_INT16) {
    for (int i = 0; i < 3; i++) {
      FG_TRY(put_int16(pn[i], b->p_world_m[i], 1e4, "m", &w[2 + i]));
      FG_TRY(put_int16(rn[i], b->rotvec_rad[i], 1e3, "rad", &w[5 + i]));
    }
    FG_TRY(put_uint16("width", b->width_m, 1e4, "m", &w[8]));
    w[9] = (uint16_t)b->force_n;
    FG_TRY(put_uint16("approach", b->approach_m, 1e4, "m", &w[10]));
    FG_TRY(put_uint16("retreat", b->retreat_m, 1e4, "m", &w[11]));
    FG_TRY(put_uint16("speed", b->speed_mps, 1e3, "m/s", &w[12]));
    return 0;
  }
  for (int i = 0; i < 3; i++) {
    FG_TRY(put_float32(pn[i], b->p_world_m[i], "m", &w[2 + 2 * i]));
    FG_TRY(put_float32(rn[i], b->rotvec_rad[i], "rad", &w[8 + 2 * i]));
  }
  FG_TRY(put_float32("width", b->width_m, "m", &w[14]));
  w[16] = (uint16_t)b->force_n;
  FG_TRY(put_float32("approach", b->approach_m, "m", &w[17]));
  FG_TRY(put_float32("retreat", b->retreat_m, "m", &w[19]));
  FG_TRY(put_float32("speed", b->speed_mps, "m/s", &w[21]));
  return 0;
}

void fg_pose_block_decode(const uint16_t *w, fg_pose_encoding e, fg_pose_block *b) {
  memset(b, 0, sizeof *b);
  b->seq = w[0];
  b->command = w[1];
  if (e == FG_POSE_INT16) {
    for (int i = 0; i < 3; i++) {
      b->p_world_m[i] = (int16_t)w[2 + i] * 1e-4;
      b->rotvec_rad[i] = (int16_t)w[5 + i] * 1e-3;
    }
    b->width_m = w[8] * 1e-4;
    b->force_n = w[9];
    b->approach_m = w[10] * 1e-4;
    b->retreat_m = w[11] * 1e-4;
    b->speed_mps = w[12] * 1e-3;
    return;
  }
  for (int i = 0; i < 3; i++) {
    b->p_world_m[i] = fg_float32_from_words(&w[2 + 2 * i]);
    b->rotvec_rad[i] = fg_float32_from_words(&w[8 + 2 * i]);
  }
  b->width_m = fg_float32_from_words(&w[14]);
  b->force_n = w[16];
  b->approach_m = fg_float32_from_words(&w[17]);
  b->retreat_m = fg_float32_from_words(&w[19]);
  b->speed_mps = fg_float32_from_words(&w[21]);
}

/* ---------------------------------------------------------------- TCP pose (read back) */

int fg_tcp_pose_encode(const double p_m[3], const double rotvec_rad[3], uint16_t w[6]) {
  static const char *const pn[3] = {"x", "y", "z"}, *const rn[3] = {"rx", "ry", "rz"};
  for (int i = 0; i < 3; i++) {
    if (!isfinite(p_m[i]) || !isfinite(rotvec_rad[i]))
      return fg_fail(FG_EINVAL, "the TCP pose is not finite");
    FG_TRY(put_int16(pn[i], p_m[i], 1e4, "m", &w[i]));
    FG_TRY(put_int16(rn[i], rotvec_rad[i], 1e3, "rad", &w[3 + i]));
  }
  return 0;
}

int fg_tcp_pose_decode(const uint16_t w[6], double p_m[3], double rotvec_rad[3]) {
  double n2 = 0;
  for (int i = 0; i < 3; i++) {
    p_m[i] = (int16_t)w[i] * 1e-4;
    rotvec_rad[i] = (int16_t)w[3 + i] * 1e-3;
    n2 += rotvec_rad[i] * rotvec_rad[i];
  }
  /* each component is rounded to 0.5 mrad: the length by at most sqrt(3) * 0.5 mrad */
  if (sqrt(n2) > M_PI + 0.9e-3)
    return fg_fail_as(FG_EPEER, "tcp_pose_invalid", "the TCP pose registers hold no pose: rotation vector "
                   "(%d, %d, %d) mrad is %.4f rad long, a controller's is at most pi",
                   (int16_t)w[3], (int16_t)w[4], (int16_t)w[5], sqrt(n2));
  return 0;
}

/* ---------------------------------------------------------------- robotiq-2f */

const fg_robotiq_model fg_robotiq_2f85 = {"robotiq-2f85", 0.085, 0.020, 0.150, 20.0, 235.0};
const fg_robotiq_model fg_robotiq_2f140 = {"robotiq-2f140", 0.140, 0.030, 0.250, 10.0, 125.0};

void fg_robotiq_request(int action, int position, int speed, int force, uint16_t w[3]) {
  w[0] = (uint16_t)((action & 0xFF) << 8);
  w[1] = (uint16_t)(position & 0xFF);
  w[2] = (uint16_t)((speed & 0xFF) << 8 | (force & 0xFF));
}

void fg_robotiq_status_decode(const uint16_t w[3], fg_robotiq_status *s) {
  const int st = w[0] >> 8, fault = w[1] >> 8;
  s->act = st & 1;
  s->gto = st >> 3 & 1;
  s->sta = st >> 4 & 3;
  s->obj = st >> 6 & 3;
  s->flt = fault & 0x0F;
  s->kflt = fault >> 4;
  s->echo = w[1] & 0xFF;
  s->position = w[2] >> 8;
  s->current = w[2] & 0xFF;
}

int fg_robotiq_object_detected(const fg_robotiq_status *s) { return s->obj == 1 || s->obj == 2; }

const char *fg_robotiq_fault_name(int flt) {
  switch (flt) {
  case 0x00: return "no fault";
  case 0x05: return "action delayed: the activation must complete first";
  case 0x07: return "the activation bit must be set before an action";
  case 0x08: return "maximum operating temperature exceeded";
  case 0x09: return "no communication for at least 1 s";
  case 0x0A: return "under minimum operating voltage";
  case 0x0B: return "automatic release in progress";
  case 0x0C: return "internal fault";
  case 0x0D: return "activation fault";
  case 0x0E: return "overcurrent";
  case 0x0F: return "automatic release completed";
  default: {
    static _Thread_local char buf[24];
    snprintf(buf, sizeof buf, "fault 0x%02X", flt & 0xFF);
    return buf;
  }
  }
}

/* v in [lo, hi] as the byte round(255 (v - lo) / (hi - lo)); FG_ERANGE naming it otherwise. */
static int to_byte(const char *what, const char *unit, const fg_robotiq_model *m, double v,
                   double lo, double hi, int *byte) {
  if (!(v >= lo && v <= hi))
    return fg_fail(FG_ERANGE, "%s = %g %s is outside the %s's range %g .. %g %s", what, v, unit,
                   m->name, lo, hi, unit);
  *byte = (int)lround(255.0 * (v - lo) / (hi - lo));
  return 0;
}

int fg_robotiq_width_to_position(const fg_robotiq_model *m, double width_m, int *position) {
  int b;
  FG_TRY(to_byte("width", "m", m, width_m, 0.0, m->stroke_m, &b));
  *position = (int)lround(255.0 * (m->stroke_m - width_m) / m->stroke_m);
  return 0;
}

int fg_robotiq_speed_to_byte(const fg_robotiq_model *m, double speed_mps, int *byte) {
  return to_byte("speed", "m/s", m, speed_mps, m->speed_min_mps, m->speed_max_mps, byte);
}

int fg_robotiq_force_to_byte(const fg_robotiq_model *m, double force_n, int *byte) {
  return to_byte("force", "N", m, force_n, m->force_min_n, m->force_max_n, byte);
}

double fg_robotiq_position_to_width(const fg_robotiq_model *m, int position) {
  return m->stroke_m * (255 - position) / 255.0;
}
