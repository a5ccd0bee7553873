/* Unit tests of lib/modbus/regs: the pose-registers block of proto/modbus.md word for word
 * (its worked example in both encodings), int16 rounding and limits, the refusals and their
 * details, sequence numbers, rotation vectors against an independent reference, float32 word
 * order, and the Robotiq 2F request and status words with their unit conversions. */
#include "test.h"

#include "core/error.h"
#include "core/pose.h"
#include "modbus/regs.h"

/* ---------------------------------------------------------------- helpers */

/* The command of proto/modbus.md "Worked example". */
static fg_pose_block worked_example(void) {
  fg_pose_block b = {.seq = 7, .command = FG_ROBOT_PICK};
  b.p_world_m[0] = 0.4523;
  b.p_world_m[1] = -0.1207;
  b.p_world_m[2] = 0.0350;
  const double q_wxyz[4] = {0, 0.9238795, -0.3826834, 0};
  fg_rotvec_from_quat(q_wxyz, b.rotvec_rad);
  b.width_m = 0.08;
  b.force_n = 40;
  b.approach_m = 0.10;
  b.retreat_m = 0.10;
  b.speed_mps = 0.10;
  return b;
}

/* A block at the origin that encodes cleanly; tests change one field. */
static fg_pose_block plain_block(void) {
  fg_pose_block b = {.seq = 1, .command = FG_ROBOT_MOVE, .width_m = 0.05, .force_n = 10,
                     .speed_mps = 0.1};
  return b;
}

/* Encodes b as int16 and returns word i (the call must succeed). */
static uint16_t int16_word(const fg_pose_block *b, int i) {
  uint16_t w[FG_POSE_MAX_WORDS];
  ASSERT_OK(fg_pose_block_encode(b, FG_POSE_INT16, w));
  return w[i];
}

/* The word of a signed int16 value, as Modbus carries it. */
static uint16_t s16(int v) { return (uint16_t)(int16_t)v; }

/* R (3x3, row-major) of the unit quaternion q = [w, x, y, z]. */
static void mat_from_quat(const double q[4], double R[9]) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  R[0] = 1 - 2 * (y * y + z * z);
  R[1] = 2 * (x * y - w * z);
  R[2] = 2 * (x * z + w * y);
  R[3] = 2 * (x * y + w * z);
  R[4] = 1 - 2 * (x * x + z * z);
  R[5] = 2 * (y * z - w * x);
  R[6] = 2 * (x * z - w * y);
  R[7] = 2 * (y * z + w * x);
  R[8] = 1 - 2 * (x * x + y * y);
}

/* R (3x3, row-major) of the rotation vector r by Rodrigues' formula. */
static void mat_from_rotvec(const double r[3], double R[9]) {
  const double th = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
  double k[3] = {1, 0, 0};
  if (th > 0)
    for (int i = 0; i < 3; i++) k[i] = r[i] / th;
  const double c = cos(th), s = sin(th), v = 1 - c;
  R[0] = c + k[0] * k[0] * v;
  R[1] = k[0] * k[1] * v - k[2] * s;
  R[2] = k[0] * k[2] * v + k[1] * s;
  R[3] = k[1] * k[0] * v + k[2] * s;
  R[4] = c + k[1] * k[1] * v;
  R[5] = k[1] * k[2] * v - k[0] * s;
  R[6] = k[2] * k[0] * v - k[1] * s;
  R[7] = k[2] * k[1] * v + k[0] * s;
  R[8] = c + k[2] * k[2] * v;
}

/* Axis x angle of R (angle away from 0 and pi) from its trace and skew part: a formula
 * unrelated to the quaternion's atan2. */
static void rotvec_from_mat(const double R[9], double r[3]) {
  const double th = acos((R[0] + R[4] + R[8] - 1) / 2);
  const double s = 2 * sin(th);
  r[0] = th * (R[7] - R[5]) / s;
  r[1] = th * (R[2] - R[6]) / s;
  r[2] = th * (R[3] - R[1]) / s;
}

/* A deterministic uniform number in [0, 1) (xorshift). */
static double rnd(uint64_t *s) {
  *s ^= *s << 13;
  *s ^= *s >> 7;
  *s ^= *s << 17;
  return (double)(*s >> 11) / 9007199254740992.0;
}

/* ---------------------------------------------------------------- worked example */

static void test_worked_example_int16(void) {
  fg_pose_block b = worked_example();
  ASSERT_NEAR(b.rotvec_rad[0], 2.902453, 5e-7);
  ASSERT_NEAR(b.rotvec_rad[1], -1.202235, 5e-7);
  ASSERT_NEAR(b.rotvec_rad[2], 0.0, 1e-15);
  ASSERT_EQ(fg_pose_block_words(FG_POSE_INT16), 13);
  ASSERT_EQ(fg_pose_ack_offset(FG_POSE_INT16), 13);
  ASSERT_EQ(fg_pose_stop_offset(FG_POSE_INT16), 15);
  uint16_t w[FG_POSE_MAX_WORDS];
  for (int i = 0; i < FG_POSE_MAX_WORDS; i++) w[i] = 0xAAAA;
  ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_INT16, w));
  const uint16_t want[13] = {7, 1, 4523, 64329, 350, 2902, 64334, 0, 800, 40, 1000, 1000, 100};
  for (int i = 0; i < 13; i++) ASSERT_EQ(w[i], want[i]);

  fg_pose_block d;
  fg_pose_block_decode(w, FG_POSE_INT16, &d);
  ASSERT_EQ(d.seq, 7);
  ASSERT_EQ(d.command, FG_ROBOT_PICK);
  ASSERT_NEAR(d.p_world_m[0], 0.4523, 1e-12);
  ASSERT_NEAR(d.p_world_m[1], -0.1207, 1e-12);
  ASSERT_NEAR(d.p_world_m[2], 0.0350, 1e-12);
  ASSERT_NEAR(d.rotvec_rad[0], 2.902, 1e-12);
  ASSERT_NEAR(d.rotvec_rad[1], -1.202, 1e-12);
  ASSERT_NEAR(d.rotvec_rad[2], 0.0, 1e-12);
  ASSERT_NEAR(d.width_m, 0.08, 1e-12);
  ASSERT_EQ(d.force_n, 40);
  ASSERT_NEAR(d.approach_m, 0.10, 1e-12);
  ASSERT_NEAR(d.retreat_m, 0.10, 1e-12);
  ASSERT_NEAR(d.speed_mps, 0.10, 1e-12);
}

static void test_worked_example_float32(void) {
  fg_pose_block b = worked_example();
  ASSERT_EQ(fg_pose_block_words(FG_POSE_FLOAT32), 23);
  ASSERT_EQ(fg_pose_ack_offset(FG_POSE_FLOAT32), 23);
  ASSERT_EQ(fg_pose_stop_offset(FG_POSE_FLOAT32), 25);
  uint16_t w[FG_POSE_MAX_WORDS];
  ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w));
  const uint16_t want[23] = {0x0007, 0x0001, 0x3EE7, 0x93DE, 0xBDF7, 0x3190, 0x3D0F, 0x5C29,
                             0x4039, 0xC1CB, 0xBF99, 0xE2DA, 0x0000, 0x0000, 0x3DA3, 0xD70A,
                             0x0028, 0x3DCC, 0xCCCD, 0x3DCC, 0xCCCD, 0x3DCC, 0xCCCD};
  for (int i = 0; i < 23; i++)
    if (w[i] != want[i]) FG_TEST_FAIL("float32 word %d: 0x%04X, want 0x%04X", i, w[i], want[i]);

  fg_pose_block d;
  fg_pose_block_decode(w, FG_POSE_FLOAT32, &d);
  ASSERT_EQ(d.seq, 7);
  ASSERT_EQ(d.command, 1);
  ASSERT_EQ(d.p_world_m[0], (float)0.4523);
  ASSERT_EQ(d.p_world_m[1], (float)-0.1207);
  ASSERT_EQ(d.p_world_m[2], (float)0.035);
  ASSERT_NEAR(d.rotvec_rad[0], 2.902453, 1e-6);
  ASSERT_NEAR(d.rotvec_rad[1], -1.202235, 1e-6);
  ASSERT_EQ(d.rotvec_rad[2], 0.0);
  ASSERT_EQ(d.width_m, (float)0.08);
  ASSERT_EQ(d.force_n, 40);
  ASSERT_EQ(d.approach_m, (float)0.10);
  ASSERT_EQ(d.speed_mps, (float)0.10);
}

/* ---------------------------------------------------------------- int16 encoding */

static void test_negative_round_trip(void) {
  fg_pose_block b = {.seq = 65535, .command = FG_ROBOT_PLACE, .width_m = 0.0001, .force_n = 0};
  const double p[3] = {-0.4523, -3.2768, -0.0001}, r[3] = {-3.1416, -0.001, -1.5};
  for (int i = 0; i < 3; i++) {
    b.p_world_m[i] = p[i];
    b.rotvec_rad[i] = r[i];
  }
  uint16_t w[FG_POSE_MAX_WORDS];
  ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_INT16, w));
  ASSERT_EQ(w[0], 65535);
  ASSERT_EQ(w[1], 2);
  ASSERT_EQ(w[2], s16(-4523));
  ASSERT_EQ(w[3], 0x8000); /* -32768 */
  ASSERT_EQ(w[4], 0xFFFF); /* -1 */
  ASSERT_EQ(w[5], s16(-3142));
  ASSERT_EQ(w[6], 0xFFFF);
  ASSERT_EQ(w[7], s16(-1500));
  ASSERT_EQ(w[8], 1);
  ASSERT_EQ(w[9], 0);
  fg_pose_block d;
  fg_pose_block_decode(w, FG_POSE_INT16, &d);
  ASSERT_EQ(d.seq, 65535);
  ASSERT_EQ(d.command, FG_ROBOT_PLACE);
  for (int i = 0; i < 3; i++) {
    ASSERT_NEAR(d.p_world_m[i], p[i], 0.5e-4 + 1e-12);
    ASSERT_NEAR(d.rotvec_rad[i], r[i], 0.5e-3 + 1e-12);
  }
  ASSERT_NEAR(d.rotvec_rad[0], -3.142, 1e-12);
  ASSERT_NEAR(d.width_m, 0.0001, 1e-12);

  /* float32 keeps negative values to float precision. */
  ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w));
  ASSERT_EQ(w[2] >> 15, 1); /* sign in the high word */
  fg_pose_block_decode(w, FG_POSE_FLOAT32, &d);
  for (int i = 0; i < 3; i++) {
    ASSERT_EQ(d.p_world_m[i], (float)p[i]);
    ASSERT_EQ(d.rotvec_rad[i], (float)r[i]);
  }
  ASSERT_EQ(d.seq, 65535);
}

/* Halves away from zero (proto/modbus.md). The cases are decimals whose scaled double is
 * exactly a half, so a half-to-even or truncating encoder gives a different word. */
static void test_rounding(void) {
  static const struct {
    double v;
    int units;
  } pos[] = {
      {0.00005, 1},   {-0.00005, -1}, {0.00025, 3},   {-0.00025, -3},  {0.45235, 4524},
      {-0.45235, -4524}, {0.00004, 0}, {-0.00004, 0}, {0.00006, 1}, {-0.00006, -1},
      {0.0, 0},       {-0.0, 0},
  };
  for (size_t i = 0; i < sizeof pos / sizeof pos[0]; i++) {
    fg_pose_block b = plain_block();
    b.p_world_m[1] = pos[i].v;
    if (int16_word(&b, 3) != s16(pos[i].units))
      FG_TEST_FAIL("y = %.17g m: word %u, want %d", pos[i].v, int16_word(&b, 3), pos[i].units);
  }
  static const struct {
    double v;
    int units;
  } rot[] = {{0.0025, 3}, {-0.0025, -3}, {0.0125, 13}, {-0.0125, -13}, {0.0005, 1},
             {-0.0005, -1}, {0.0004, 0}};
  for (size_t i = 0; i < sizeof rot / sizeof rot[0]; i++) {
    fg_pose_block b = plain_block();
    b.rotvec_rad[2] = rot[i].v;
    if (int16_word(&b, 7) != s16(rot[i].units))
      FG_TEST_FAIL("rz = %.17g rad: word %u, want %d", rot[i].v, int16_word(&b, 7),
                   rot[i].units);
  }
  /* width: 0.00025 m is 2.5 units, so 3; 0.00005 m is 1. */
  fg_pose_block b = plain_block();
  b.width_m = 0.00025;
  ASSERT_EQ(int16_word(&b, 8), 3);
  b.width_m = 0.00005;
  ASSERT_EQ(int16_word(&b, 8), 1);
  b.width_m = 0.0;
  ASSERT_EQ(int16_word(&b, 8), 0);
}

/* The int16 limits: in range after rounding is accepted, one unit beyond is FG_ERANGE with
 * the field, its value and its range in the detail; nothing is wrapped or clamped. */
static void test_int16_limits(void) {
  uint16_t w[FG_POSE_MAX_WORDS];
  static const struct {
    double v;
    int units; /* 0x7FFFFFFF: refused */
  } lim[] = {
      {3.2767, 32767},    {3.27674, 32767},  {3.27675, 0x7FFFFFFF}, {3.2768, 0x7FFFFFFF},
      {-3.2768, -32768},  {-3.27684, -32768}, {-3.27685, 0x7FFFFFFF}, {-3.2769, 0x7FFFFFFF},
      {10.0, 0x7FFFFFFF}, {-1e9, 0x7FFFFFFF},
  };
  static const char *const names[3] = {"x", "y", "z"};
  for (int axis = 0; axis < 3; axis++) {
    for (size_t i = 0; i < sizeof lim / sizeof lim[0]; i++) {
      fg_pose_block b = plain_block();
      b.p_world_m[axis] = lim[i].v;
      fg_error_clear();
      int rc = fg_pose_block_encode(&b, FG_POSE_INT16, w);
      if (lim[i].units == 0x7FFFFFFF) {
        if (rc != FG_ERANGE)
          FG_TEST_FAIL("%s = %.17g m: rc %d (word %u), want FG_ERANGE", names[axis], lim[i].v,
                       rc, w[2 + axis]);
        char want[64];
        snprintf(want, sizeof want, "%s = %g", names[axis], lim[i].v);
        const char *d = fg_error_detail();
        if (strncmp(d, want, strlen(want)) != 0)
          FG_TEST_FAIL("detail \"%s\" does not start with \"%s\"", d, want);
        ASSERT_STRCONTAINS(d, "-3.2768 .. 3.2767 m");
        ASSERT_STRCONTAINS(d, "int16");
        /* still refused in float32? no: float32 carries it */
        ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w));
        ASSERT_EQ(fg_float32_from_words(&w[2 + 2 * axis]), (float)lim[i].v);
      } else {
        if (rc != 0) FG_TEST_FAIL("%s = %.17g m refused: %s", names[axis], lim[i].v,
                                  fg_error_detail());
        ASSERT_EQ(w[2 + axis], s16(lim[i].units));
      }
    }
  }

  /* Rotation components in mrad: +-32.767 rad, beyond any rotation vector but still
   * checked, with the field named. */
  static const char *const rnames[3] = {"rx", "ry", "rz"};
  for (int axis = 0; axis < 3; axis++) {
    fg_pose_block b = plain_block();
    b.rotvec_rad[axis] = 32.767;
    ASSERT_EQ(int16_word(&b, 5 + axis), 32767);
    b.rotvec_rad[axis] = -32.768;
    ASSERT_EQ(int16_word(&b, 5 + axis), 0x8000);
    b.rotvec_rad[axis] = 32.768;
    fg_error_clear();
    ASSERT_EQ(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE);
    char want[32];
    snprintf(want, sizeof want, "%s = 32.768", rnames[axis]);
    ASSERT_STRCONTAINS(fg_error_detail(), want);
    ASSERT_STRCONTAINS(fg_error_detail(), "rad");
    b.rotvec_rad[axis] = -32.769;
    ASSERT_EQ(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE);
  }

  /* width: u16 in 0.1 mm, 0 .. 6.5535 m. */
  fg_pose_block b = plain_block();
  b.width_m = 6.5535;
  ASSERT_EQ(int16_word(&b, 8), 65535);
  b.width_m = 6.55355;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "width");
  ASSERT_STRCONTAINS(fg_error_detail(), "6.5535");
  b.width_m = 7.0;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "width = 7");
  ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w)); /* float32 has no such limit */
  ASSERT_EQ(fg_float32_from_words(&w[14]), 7.0f);
  b.width_m = -0.0001;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "width");
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_ERANGE, "width");

  /* force: u16 newtons. */
  b = plain_block();
  b.force_n = 65535;
  ASSERT_EQ(int16_word(&b, 9), 65535);
  ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w));
  ASSERT_EQ(w[16], 65535);
  b.force_n = 65536;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "force = 65536");
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_ERANGE, "force");
  b.force_n = -1;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "force = -1");
  b.force_n = 0;
  ASSERT_EQ(int16_word(&b, 9), 0);
}

/* seq 0, unknown commands and values that are not finite are FG_EINVAL (regs.h). */
static void test_refusals(void) {
  uint16_t w[FG_POSE_MAX_WORDS];
  fg_pose_block b = plain_block();
  b.seq = 0;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_EINVAL, "seq 0");
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_EINVAL, "seq 0");

  static const int bad_cmd[] = {6, -1, 65536};
  for (size_t i = 0; i < sizeof bad_cmd / sizeof bad_cmd[0]; i++) {
    b = plain_block();
    b.command = bad_cmd[i];
    ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_EINVAL, "command");
    ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_EINVAL, "command");
  }
  for (int c = FG_ROBOT_NOOP; c <= FG_ROBOT_MOVE; c++) {
    b = plain_block();
    b.command = c;
    ASSERT_EQ(int16_word(&b, 1), c);
  }
  /* approach, retreat and speed: negative or beyond a u16 of their unit is refused */
  b = plain_block();
  b.approach_m = -0.01;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "approach");
  b = plain_block();
  b.retreat_m = 6.6;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "retreat");
  ASSERT_OK(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w));
  b = plain_block();
  b.speed_mps = NAN;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_EINVAL, "speed");

  const double bad[3] = {NAN, INFINITY, -INFINITY};
  for (int k = 0; k < 3; k++) {
    for (int i = 0; i < 3; i++) {
      for (int e = 0; e < 2; e++) {
        const fg_pose_encoding enc = e ? FG_POSE_FLOAT32 : FG_POSE_INT16;
        b = plain_block();
        b.p_world_m[i] = bad[k];
        ASSERT_ERR(fg_pose_block_encode(&b, enc, w), FG_EINVAL, "finite");
        b = plain_block();
        b.rotvec_rad[i] = bad[k];
        ASSERT_ERR(fg_pose_block_encode(&b, enc, w), FG_EINVAL, "finite");
      }
    }
    /* A width that is not finite is "a value that is not finite" too. */
    b = plain_block();
    b.width_m = bad[k];
    ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_EINVAL, "width");
    ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_EINVAL, "width");
  }

  /* Finite doubles beyond float32 cannot be carried by the float32 encoding; the detail
   * names the field, as for any FG_ERANGE of fg_pose_block_encode (regs.h). */
  b = plain_block();
  b.p_world_m[2] = 1e39;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_ERANGE, "z = 1e+39");
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_INT16, w), FG_ERANGE, "z = 1e+39");
  b = plain_block();
  b.rotvec_rad[0] = -1e39;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_ERANGE, "rx = -1e+39");
  b = plain_block();
  b.width_m = 1e39;
  ASSERT_ERR(fg_pose_block_encode(&b, FG_POSE_FLOAT32, w), FG_ERANGE, "width");
}

/* ---------------------------------------------------------------- seq, float32 */

static void test_seq_next(void) {
  ASSERT_EQ(fg_seq_next(1), 2);
  ASSERT_EQ(fg_seq_next(7), 8);
  ASSERT_EQ(fg_seq_next(65534), 65535);
  ASSERT_EQ(fg_seq_next(65535), 1);
  ASSERT_EQ(fg_seq_next(0), 1); /* a robot whose ack is still 0 */
  for (unsigned s = 0; s <= 65535; s++) {
    const uint16_t n = fg_seq_next((uint16_t)s);
    ASSERT_NE(n, 0);
    ASSERT_NE(n, s);
  }
  /* A full cycle from 1 visits every nonzero value once and comes back to 1. */
  uint16_t s = 1;
  for (int i = 0; i < 65535; i++) s = fg_seq_next(s);
  ASSERT_EQ(s, 1);
}

static void test_float32_words(void) {
  uint16_t w[2];
  fg_float32_to_words(1.0f, w);
  ASSERT_EQ(w[0], 0x3F80);
  ASSERT_EQ(w[1], 0x0000);
  fg_float32_to_words(-2.0f, w);
  ASSERT_EQ(w[0], 0xC000);
  ASSERT_EQ(w[1], 0x0000);
  fg_float32_to_words(0.1f, w); /* 0x3DCCCCCD: the low word carries the low mantissa bits */
  ASSERT_EQ(w[0], 0x3DCC);
  ASSERT_EQ(w[1], 0xCCCD);
  fg_float32_to_words(-0.0f, w);
  ASSERT_EQ(w[0], 0x8000);
  ASSERT_EQ(w[1], 0x0000);
  const uint16_t one[2] = {0x3F80, 0x0000};
  ASSERT_EQ(fg_float32_from_words(one), 1.0f);
  const uint16_t pi[2] = {0x4049, 0x0FDB};
  ASSERT_EQ(fg_float32_from_words(pi), 3.14159265f);

  const float vals[] = {0.0f, 1.0f, -1.0f, 0.4523f, -0.1207f, 1e-38f, 1.17549435e-38f / 4,
                        3.4028235e38f, -3.4028235e38f, 123456.789f, -7.25e-5f};
  for (size_t i = 0; i < sizeof vals / sizeof vals[0]; i++) {
    fg_float32_to_words(vals[i], w);
    const float back = fg_float32_from_words(w);
    ASSERT(memcmp(&back, &vals[i], sizeof back) == 0);
  }
  uint64_t st = 0x9E3779B97F4A7C15ull;
  for (int i = 0; i < 10000; i++) {
    uint32_t bits = (uint32_t)(rnd(&st) * 4294967296.0);
    if ((bits & 0x7F800000u) == 0x7F800000u) continue; /* NaN payloads may not survive */
    float v;
    memcpy(&v, &bits, sizeof v);
    fg_float32_to_words(v, w);
    ASSERT_EQ(w[0], bits >> 16);
    ASSERT_EQ(w[1], bits & 0xFFFF);
    float back = fg_float32_from_words(w);
    ASSERT(memcmp(&back, &v, sizeof v) == 0);
  }
}

/* ---------------------------------------------------------------- rotation vectors */

static void test_rotvec(void) {
  double r[3];
  const double id[4] = {1, 0, 0, 0};
  fg_rotvec_from_quat(id, r);
  ASSERT_EQ(r[0], 0.0);
  ASSERT_EQ(r[1], 0.0);
  ASSERT_EQ(r[2], 0.0);
  const double nid[4] = {-1, 0, 0, 0}; /* the same rotation */
  fg_rotvec_from_quat(nid, r);
  ASSERT_NEAR(r[0], 0.0, 0);
  ASSERT_NEAR(r[1], 0.0, 0);
  ASSERT_NEAR(r[2], 0.0, 0);

  /* Small angles about z, down to where |(x, y, z)| underflows the atan2 branch. */
  const double small[] = {1e-3, 1e-6, 1e-9, 1e-12, 1e-13, 1e-15, 1e-300};
  for (size_t i = 0; i < sizeof small / sizeof small[0]; i++) {
    const double th = small[i];
    const double q[4] = {cos(th / 2), 0, 0, sin(th / 2)};
    fg_rotvec_from_quat(q, r);
    ASSERT_EQ(r[0], 0.0);
    ASSERT_EQ(r[1], 0.0);
    if (!(fabs(r[2] - th) <= 1e-12 * th))
      FG_TEST_FAIL("angle %g about z: rz %.17g", th, r[2]);
    const double qn[4] = {-q[0], -q[1], -q[2], -q[3]};
    fg_rotvec_from_quat(qn, r);
    if (!(fabs(r[2] - th) <= 1e-12 * th))
      FG_TEST_FAIL("angle %g about z, negated quaternion: rz %.17g", th, r[2]);
  }

  /* Half turns: angle pi about the axis, with w = 0 as given. */
  const double hx[4] = {0, 1, 0, 0}, hy[4] = {0, 0, -1, 0};
  fg_rotvec_from_quat(hx, r);
  ASSERT_NEAR(r[0], M_PI, 1e-15);
  ASSERT_EQ(r[1], 0.0);
  ASSERT_EQ(r[2], 0.0);
  fg_rotvec_from_quat(hy, r);
  ASSERT_NEAR(r[1], -M_PI, 1e-15);
  const double h[4] = {0, 0.9238795, -0.3826834, 0};
  fg_rotvec_from_quat(h, r);
  ASSERT_NEAR(r[0], M_PI * 0.9238795 / sqrt(0.9238795 * 0.9238795 + 0.3826834 * 0.3826834),
              1e-12);
  /* A quarter turn about x: (pi/2, 0, 0). */
  const double qx[4] = {cos(M_PI / 4), sin(M_PI / 4), 0, 0};
  fg_rotvec_from_quat(qx, r);
  ASSERT_NEAR(r[0], M_PI / 2, 1e-15);

  /* Random unit quaternions, both signs: the same rotation vector for q and -q, angle in
   * [0, pi], the same rotation matrix (Rodrigues) as the quaternion's, and away from 0 and pi
   * the same vector as the matrix's trace and skew part give. */
  uint64_t st = 12345;
  for (int i = 0; i < 2000; i++) {
    double q[4], n = 0;
    for (int k = 0; k < 4; k++) {
      q[k] = 2 * rnd(&st) - 1;
      n += q[k] * q[k];
    }
    n = sqrt(n);
    if (n < 1e-3) continue;
    for (int k = 0; k < 4; k++) q[k] /= n;
    double r1[3], r2[3];
    const double qn[4] = {-q[0], -q[1], -q[2], -q[3]};
    fg_rotvec_from_quat(q, r1);
    fg_rotvec_from_quat(qn, r2);
    for (int k = 0; k < 3; k++) ASSERT_NEAR(r1[k], r2[k], 1e-15);
    const double th = sqrt(r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2]);
    ASSERT(th >= 0 && th <= M_PI + 1e-12);
    ASSERT_NEAR(th, 2 * acos(fabs(q[0])), 1e-6);
    double Rq[9], Rr[9];
    mat_from_quat(q, Rq);
    mat_from_rotvec(r1, Rr);
    for (int k = 0; k < 9; k++) ASSERT_NEAR(Rr[k], Rq[k], 1e-12);
    if (th > 0.01 && th < M_PI - 0.01) {
      double r3[3];
      rotvec_from_mat(Rq, r3);
      for (int k = 0; k < 3; k++) ASSERT_NEAR(r1[k], r3[k], 1e-9);
    }
    /* the vector's direction is the quaternion's axis, signed as the quaternion with w >= 0 */
    const double s = q[0] < 0 ? -1 : 1;
    const double dot = s * (q[1] * r1[0] + q[2] * r1[1] + q[3] * r1[2]);
    ASSERT(dot >= 0);
  }
}

/* ---------------------------------------------------------------- robotiq-2f */

static void test_robotiq_request(void) {
  uint16_t w[3];
  fg_robotiq_request(0, 0, 0, 0, w); /* reset */
  ASSERT_EQ(w[0], 0x0000);
  ASSERT_EQ(w[1], 0x0000);
  ASSERT_EQ(w[2], 0x0000);
  fg_robotiq_request(FG_ROBOTIQ_ACT, 0, 0, 0, w); /* activation request */
  ASSERT_EQ(w[0], 0x0100);
  ASSERT_EQ(w[1], 0x0000);
  ASSERT_EQ(w[2], 0x0000);
  fg_robotiq_request(FG_ROBOTIQ_ACT | FG_ROBOTIQ_GTO, 255, 255, 255, w); /* close, full */
  ASSERT_EQ(w[0], 0x0900);
  ASSERT_EQ(w[1], 0x00FF);
  ASSERT_EQ(w[2], 0xFFFF);
  fg_robotiq_request(FG_ROBOTIQ_ACT | FG_ROBOTIQ_GTO, 0, 255, 100, w); /* open */
  ASSERT_EQ(w[0], 0x0900);
  ASSERT_EQ(w[1], 0x0000);
  ASSERT_EQ(w[2], 0xFF64);
  fg_robotiq_request(FG_ROBOTIQ_ACT | FG_ROBOTIQ_GTO, 0x87, 0x12, 0x34, w);
  ASSERT_EQ(w[1], 0x0087);
  ASSERT_EQ(w[2], 0x1234);
  fg_robotiq_request(FG_ROBOTIQ_ACT | FG_ROBOTIQ_ATR, 0, 0, 0, w);
  ASSERT_EQ(w[0], 0x1100);
  ASSERT_EQ(FG_ROBOTIQ_REQUEST_ADDR, 1000);
  ASSERT_EQ(FG_ROBOTIQ_STATUS_ADDR, 2000);
  ASSERT_EQ(FG_ROBOTIQ_WORDS, 3);
}

static void test_robotiq_status(void) {
  fg_robotiq_status s;
  const uint16_t activated[3] = {0x3100, 0x0000, 0x0000};
  fg_robotiq_status_decode(activated, &s);
  ASSERT_EQ(s.act, 1);
  ASSERT_EQ(s.gto, 0);
  ASSERT_EQ(s.sta, 3);
  ASSERT_EQ(s.obj, 0);
  ASSERT_EQ(s.flt, 0);
  ASSERT_EQ(s.kflt, 0);
  ASSERT_EQ(s.echo, 0);
  ASSERT_EQ(s.position, 0);
  ASSERT_EQ(s.current, 0);

  const uint16_t activating[3] = {0x1100, 0x0000, 0x0000};
  fg_robotiq_status_decode(activating, &s);
  ASSERT_EQ(s.act, 1);
  ASSERT_EQ(s.sta, 1);

  /* Closed on nothing: gOBJ 3 at the requested 255. */
  const uint16_t closed[3] = {0xF900, 0x00FF, 0xFF00};
  fg_robotiq_status_decode(closed, &s);
  ASSERT_EQ(s.act, 1);
  ASSERT_EQ(s.gto, 1);
  ASSERT_EQ(s.sta, 3);
  ASSERT_EQ(s.obj, 3);
  ASSERT_EQ(s.echo, 255);
  ASSERT_EQ(s.position, 255);
  ASSERT_EQ(s.current, 0);
  ASSERT_EQ(fg_robotiq_object_detected(&s), 0);

  /* Stopped on an object while closing, with current; fault byte 0x3A: kFLT 3, gFLT 0x0A. */
  const uint16_t holding[3] = {0xB900, 0x3AFF, 0x8712};
  fg_robotiq_status_decode(holding, &s);
  ASSERT_EQ(s.act, 1);
  ASSERT_EQ(s.gto, 1);
  ASSERT_EQ(s.sta, 3);
  ASSERT_EQ(s.obj, 2);
  ASSERT_EQ(s.flt, 0x0A);
  ASSERT_EQ(s.kflt, 3);
  ASSERT_EQ(s.echo, 0xFF);
  ASSERT_EQ(s.position, 0x87);
  ASSERT_EQ(s.current, 0x12);
  ASSERT_EQ(fg_robotiq_object_detected(&s), 1);

  /* Stopped by contact while opening; moving. */
  const uint16_t opening[3] = {0x7900, 0x0000, 0x4000};
  fg_robotiq_status_decode(opening, &s);
  ASSERT_EQ(s.obj, 1);
  ASSERT_EQ(s.position, 0x40);
  ASSERT_EQ(fg_robotiq_object_detected(&s), 1);
  const uint16_t moving[3] = {0x3900, 0x0080, 0x2000};
  fg_robotiq_status_decode(moving, &s);
  ASSERT_EQ(s.obj, 0);
  ASSERT_EQ(s.echo, 0x80);
  ASSERT_EQ(fg_robotiq_object_detected(&s), 0);

  /* Every status byte: each field from its own bits; the reserved low byte is ignored. */
  for (int st = 0; st < 256; st++) {
    const uint16_t w[3] = {(uint16_t)(st << 8 | 0xA5), (uint16_t)(st << 8 | (255 - st)),
                           (uint16_t)((255 - st) << 8 | st)};
    fg_robotiq_status_decode(w, &s);
    ASSERT_EQ(s.act, st & 1);
    ASSERT_EQ(s.gto, (st >> 3) & 1);
    ASSERT_EQ(s.sta, (st >> 4) & 3);
    ASSERT_EQ(s.obj, (st >> 6) & 3);
    ASSERT_EQ(s.flt, st & 0x0F);
    ASSERT_EQ(s.kflt, st >> 4);
    ASSERT_EQ(s.echo, 255 - st);
    ASSERT_EQ(s.position, 255 - st);
    ASSERT_EQ(s.current, st);
    ASSERT_EQ(fg_robotiq_object_detected(&s), s.obj == 1 || s.obj == 2);
  }
}

static void test_robotiq_units(void) {
  const fg_robotiq_model *m85 = &fg_robotiq_2f85, *m140 = &fg_robotiq_2f140;
  ASSERT_STREQ(m85->name, "robotiq-2f85");
  ASSERT_STREQ(m140->name, "robotiq-2f140");
  ASSERT_EQ(m85->stroke_m, 0.085);
  ASSERT_EQ(m140->stroke_m, 0.140);
  int p;
  /* P = round(255 (S - W) / S). */
  ASSERT_OK(fg_robotiq_width_to_position(m85, 0.085, &p));
  ASSERT_EQ(p, 0);
  ASSERT_OK(fg_robotiq_width_to_position(m85, 0.0, &p));
  ASSERT_EQ(p, 255);
  ASSERT_OK(fg_robotiq_width_to_position(m85, 0.040, &p));
  ASSERT_EQ(p, 135); /* 255 * 45 / 85 = 135 */
  ASSERT_OK(fg_robotiq_width_to_position(m85, 0.080, &p));
  ASSERT_EQ(p, 15);
  ASSERT_OK(fg_robotiq_width_to_position(m85, 0.010, &p));
  ASSERT_EQ(p, 225);
  ASSERT_OK(fg_robotiq_width_to_position(m140, 0.070, &p));
  ASSERT_EQ(p, 128); /* 127.5, half away from zero */
  ASSERT_OK(fg_robotiq_width_to_position(m140, 0.140, &p));
  ASSERT_EQ(p, 0);
  ASSERT_OK(fg_robotiq_width_to_position(m140, 0.0, &p));
  ASSERT_EQ(p, 255);
  ASSERT_OK(fg_robotiq_width_to_position(m140, 0.100, &p));
  ASSERT_EQ(p, 73); /* 255 * 40 / 140 = 72.86 */
  /* Every position maps back onto itself through its width. */
  for (int k = 0; k < 2; k++) {
    const fg_robotiq_model *m = k ? m140 : m85;
    for (int pos = 0; pos <= 255; pos++) {
      const double wd = fg_robotiq_position_to_width(m, pos);
      ASSERT_NEAR(wd, m->stroke_m * (255 - pos) / 255.0, 1e-15);
      ASSERT_OK(fg_robotiq_width_to_position(m, wd, &p));
      ASSERT_EQ(p, pos);
    }
  }
  ASSERT_EQ(fg_robotiq_position_to_width(m85, 0), 0.085);
  ASSERT_EQ(fg_robotiq_position_to_width(m85, 255), 0.0);
  ASSERT_NEAR(fg_robotiq_position_to_width(m85, 135), 0.040, 1e-12);

  const double bad_w85[] = {-0.0001, 0.0851, 0.14, NAN, INFINITY, -INFINITY};
  for (size_t i = 0; i < sizeof bad_w85 / sizeof bad_w85[0]; i++) {
    p = -1;
    ASSERT_ERR(fg_robotiq_width_to_position(m85, bad_w85[i], &p), FG_ERANGE, "width");
    ASSERT_STRCONTAINS(fg_error_detail(), "robotiq-2f85");
    ASSERT_STRCONTAINS(fg_error_detail(), "0.085");
    ASSERT_EQ(p, -1);
  }
  ASSERT_ERR(fg_robotiq_width_to_position(m140, 0.1401, &p), FG_ERANGE, "robotiq-2f140");

  /* Speeds: 2F-85 0.020 .. 0.150 m/s, 2F-140 0.030 .. 0.250 m/s. */
  int b;
  ASSERT_OK(fg_robotiq_speed_to_byte(m85, 0.020, &b));
  ASSERT_EQ(b, 0);
  ASSERT_OK(fg_robotiq_speed_to_byte(m85, 0.150, &b));
  ASSERT_EQ(b, 255);
  ASSERT_OK(fg_robotiq_speed_to_byte(m85, 0.1, &b));
  ASSERT_EQ(b, 157); /* 255 * 0.08 / 0.13 = 156.9 */
  ASSERT_OK(fg_robotiq_speed_to_byte(m140, 0.030, &b));
  ASSERT_EQ(b, 0);
  ASSERT_OK(fg_robotiq_speed_to_byte(m140, 0.250, &b));
  ASSERT_EQ(b, 255);
  ASSERT_OK(fg_robotiq_speed_to_byte(m140, 0.1, &b));
  ASSERT_EQ(b, 81); /* 255 * 0.07 / 0.22 = 81.1 */
  b = -1;
  ASSERT_ERR(fg_robotiq_speed_to_byte(m85, 0.019, &b), FG_ERANGE, "speed");
  ASSERT_STRCONTAINS(fg_error_detail(), "0.02 .. 0.15 m/s");
  ASSERT_ERR(fg_robotiq_speed_to_byte(m85, 0.151, &b), FG_ERANGE, "speed");
  ASSERT_ERR(fg_robotiq_speed_to_byte(m85, NAN, &b), FG_ERANGE, "speed");
  ASSERT_ERR(fg_robotiq_speed_to_byte(m140, 0.029, &b), FG_ERANGE, "robotiq-2f140");
  ASSERT_ERR(fg_robotiq_speed_to_byte(m140, 0.251, &b), FG_ERANGE, "speed");
  ASSERT_OK(fg_robotiq_speed_to_byte(m140, 0.150, &b)); /* beyond the 2F-85, within the 140 */
  ASSERT_EQ(b, 139); /* 255 * 0.12 / 0.22 = 139.1 */

  /* Forces: 2F-85 20 .. 235 N, 2F-140 10 .. 125 N. */
  ASSERT_OK(fg_robotiq_force_to_byte(m85, 20, &b));
  ASSERT_EQ(b, 0);
  ASSERT_OK(fg_robotiq_force_to_byte(m85, 235, &b));
  ASSERT_EQ(b, 255);
  ASSERT_OK(fg_robotiq_force_to_byte(m85, 100, &b));
  ASSERT_EQ(b, 95); /* 255 * 80 / 215 = 94.9 */
  ASSERT_OK(fg_robotiq_force_to_byte(m140, 10, &b));
  ASSERT_EQ(b, 0);
  ASSERT_OK(fg_robotiq_force_to_byte(m140, 125, &b));
  ASSERT_EQ(b, 255);
  ASSERT_OK(fg_robotiq_force_to_byte(m140, 67.5, &b));
  ASSERT_EQ(b, 128); /* 127.5 */
  ASSERT_ERR(fg_robotiq_force_to_byte(m85, 19.9, &b), FG_ERANGE, "force");
  ASSERT_STRCONTAINS(fg_error_detail(), "20 .. 235 N");
  ASSERT_ERR(fg_robotiq_force_to_byte(m85, 235.1, &b), FG_ERANGE, "force");
  ASSERT_ERR(fg_robotiq_force_to_byte(m140, 126, &b), FG_ERANGE, "robotiq-2f140");
  ASSERT_ERR(fg_robotiq_force_to_byte(m140, 9, &b), FG_ERANGE, "force");
  ASSERT_ERR(fg_robotiq_force_to_byte(m140, -INFINITY, &b), FG_ERANGE, "force");
}

static void test_robotiq_faults(void) {
  ASSERT_STREQ(fg_robotiq_fault_name(0), "no fault");
  ASSERT_STREQ(fg_robotiq_fault_name(0x0E), "overcurrent");
  ASSERT_STREQ(fg_robotiq_fault_name(0x0C), "internal fault");
  ASSERT_STREQ(fg_robotiq_fault_name(0x0D), "activation fault");
  ASSERT_STRCONTAINS(fg_robotiq_fault_name(0x05), "activation must complete");
  ASSERT_STRCONTAINS(fg_robotiq_fault_name(0x07), "activation bit");
  ASSERT_STRCONTAINS(fg_robotiq_fault_name(0x08), "temperature");
  ASSERT_STRCONTAINS(fg_robotiq_fault_name(0x09), "communication");
  ASSERT_STRCONTAINS(fg_robotiq_fault_name(0x0A), "voltage");
  ASSERT_STRCONTAINS(fg_robotiq_fault_name(0x0B), "automatic release in progress");
  ASSERT_STRCONTAINS(fg_robotiq_fault_name(0x0F), "automatic release completed");
  ASSERT_STREQ(fg_robotiq_fault_name(0x03), "fault 0x03");
  ASSERT_STREQ(fg_robotiq_fault_name(0x42), "fault 0x42");
  /* Every name is distinct and never empty. */
  for (int a = 0; a < 16; a++) {
    ASSERT(fg_robotiq_fault_name(a)[0] != '\0');
    char na[96];
    snprintf(na, sizeof na, "%s", fg_robotiq_fault_name(a));
    for (int b = a + 1; b < 16; b++) ASSERT(strcmp(na, fg_robotiq_fault_name(b)) != 0);
  }
}

/* ---------------------------------------------------------------- TCP pose */

/* The six words of a UR controller's registers 400-405, by hand: two's complement for
 * negative values, 0.1 mm and mrad. */
static void test_tcp_pose(void) {
  const uint16_t w[6] = {4523, (uint16_t)(65536 - 1207), 350, 0, 2221, (uint16_t)(65536 - 2221)};
  double p[3], rv[3];
  ASSERT_EQ(fg_tcp_pose_decode(w, p, rv), 0);
  ASSERT_NEAR(p[0], 0.4523, 1e-12);
  ASSERT_NEAR(p[1], -0.1207, 1e-12);
  ASSERT_NEAR(p[2], 0.0350, 1e-12);
  ASSERT_NEAR(rv[0], 0, 1e-12);
  ASSERT_NEAR(rv[1], 2.221, 1e-12);
  ASSERT_NEAR(rv[2], -2.221, 1e-12);
  uint16_t back[6];
  ASSERT_EQ(fg_tcp_pose_encode(p, rv, back), 0);
  for (int i = 0; i < 6; i++) ASSERT_EQ(back[i], w[i]);

  /* a half turn rounded component by component still reads; a longer vector does not */
  const double half[3] = {M_PI / sqrt(3), M_PI / sqrt(3), -M_PI / sqrt(3)};
  ASSERT_EQ(fg_tcp_pose_encode(p, half, back), 0);
  ASSERT_EQ(fg_tcp_pose_decode(back, p, rv), 0);
  const uint16_t bad[6] = {0, 0, 0, 3200, 0, 0};
  ASSERT_EQ(fg_tcp_pose_decode(bad, p, rv), FG_EPEER);
  ASSERT(strstr(fg_error_detail(), "(3200, 0, 0) mrad"));

  /* beyond the registers: refused naming the value, never wrapped */
  const double far[3] = {3.3, 0, 0}, zero[3] = {0, 0, 0}, nan3[3] = {0, NAN, 0};
  ASSERT_EQ(fg_tcp_pose_encode(far, zero, back), FG_ERANGE);
  ASSERT(strstr(fg_error_detail(), "x = 3.3"));
  ASSERT_EQ(fg_tcp_pose_encode(nan3, zero, back), FG_EINVAL);
}

int main(void) {
  static const struct {
    const char *name;
    void (*fn)(void);
  } cases[] = {
      {"worked_example_int16", test_worked_example_int16},
      {"worked_example_float32", test_worked_example_float32},
      {"negative_round_trip", test_negative_round_trip},
      {"rounding", test_rounding},
      {"int16_limits", test_int16_limits},
      {"refusals", test_refusals},
      {"seq_next", test_seq_next},
      {"float32_words", test_float32_words},
      {"rotvec", test_rotvec},
      {"tcp_pose", test_tcp_pose},
      {"robotiq_request", test_robotiq_request},
      {"robotiq_status", test_robotiq_status},
      {"robotiq_units", test_robotiq_units},
      {"robotiq_faults", test_robotiq_faults},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    cases[i].fn();
    fprintf(stderr, "ok %s\n", cases[i].name);
  }
  return 0;
}
