/* Unit tests of lib/core: error detail, half floats, poses, atomic files, SHA-256. */
#include "test.h"

#include "core/clock.h"
#include "core/digest.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "core/pose.h"
#include "core/strbuf.h"
#include "core/threads.h"

#include <sys/stat.h>
#include <unistd.h>

static void test_error(void) {
  fg_error_clear();
  ASSERT_STREQ(fg_error_detail(), "");
  ASSERT_EQ(fg_fail(FG_EINVAL, "w must be positive, got %d", -3), FG_EINVAL);
  ASSERT_STREQ(fg_error_detail(), "w must be positive, got -3");
  fg_error_clear();
  ASSERT_STREQ(fg_error_detail(), "");
  ASSERT_STREQ(fg_strerror(FG_OK), "success");
  ASSERT_STREQ(fg_strerror(FG_EFORMAT), "unsupported or corrupt format");
  ASSERT_STREQ(fg_strerror(-1000), "unknown error");
  /* A detail longer than the buffer is truncated, not overflowed. */
  char big[3000];
  memset(big, 'x', sizeof big - 1);
  big[sizeof big - 1] = '\0';
  fg_fail(FG_EIO, "%s", big);
  ASSERT(strlen(fg_error_detail()) < sizeof big - 1);
  /* A failure wraps the one below it; a reason names it until a plain failure. */
  fg_fail(FG_EIO, "disk full");
  ASSERT(fg_error_reason() == NULL);
  ASSERT_EQ(fg_fail_as(FG_ENOENT, "task_not_found", "task %s: %s", "cup", fg_error_detail()),
            FG_ENOENT);
  ASSERT_STREQ(fg_error_detail(), "task cup: disk full");
  ASSERT_STREQ(fg_error_reason(), "task_not_found");
  fg_fail(FG_EINVAL, "later: %s", fg_error_detail());
  ASSERT_STREQ(fg_error_detail(), "later: task cup: disk full");
  ASSERT(fg_error_reason() == NULL);
  fg_fail_as(FG_EBUSY, "busy", "x");
  fg_error_clear();
  ASSERT(fg_error_reason() == NULL);
}

static void test_strbuf(void) {
  fg_strbuf b = {0};
  size_t len = 99;
  char *s = fg_strbuf_take(&b, &len); /* nothing appended: "" */
  ASSERT(s && s[0] == '\0' && len == 0);
  free(s);
  /* appends across the first growth, printf longer than the room left */
  char big[5000];
  memset(big, 'y', sizeof big - 1);
  big[sizeof big - 1] = '\0';
  fg_strbuf_puts(&b, "ab");
  fg_strbuf_add(&b, "cdef", 2);
  fg_strbuf_printf(&b, "[%d:%s]", 42, big);
  fg_strbuf_printf(&b, "%s", "");
  s = fg_strbuf_take(&b, &len);
  ASSERT(s != NULL);
  ASSERT_EQ(len, strlen(s));
  ASSERT_EQ(len, 4 + 4 + sizeof big - 1 + 1);
  ASSERT(strncmp(s, "abcd[42:yyy", 11) == 0 && s[len - 1] == ']');
  ASSERT(b.s == NULL && b.n == 0);
  free(s);
  /* a failed append is sticky: nothing more is written and take says so */
  fg_strbuf_puts(&b, "x");
  b.failed = 1;
  fg_strbuf_puts(&b, "more");
  ASSERT_EQ(b.n, 1);
  ASSERT(fg_strbuf_take(&b, &len) == NULL);
}

static void test_half(void) {
  /* Every half bit pattern survives half -> float -> half; NaNs stay NaN. */
  for (uint32_t h = 0; h < 65536; h++) {
    float f = fg_half_to_float((uint16_t)h);
    uint16_t back = fg_float_to_half(f);
    int is_nan = (h & 0x7c00) == 0x7c00 && (h & 0x03ff) != 0;
    if (is_nan) {
      ASSERT(isnan(f));
      ASSERT(isnan(fg_half_to_float(back)));
      ASSERT_EQ(back & 0x8000, h & 0x8000);
    } else {
      ASSERT_EQ(back, h);
    }
  }
  /* The bulk conversion (F16C where the CPU has it) agrees with the scalar one on every bit
   * pattern, at every offset of an unaligned buffer. */
  uint16_t *all = malloc(65536 * sizeof(uint16_t) + 2);
  float *bulk = malloc(65536 * sizeof(float));
  for (uint32_t h = 0; h < 65536; h++) all[h + 1] = (uint16_t)h;
  fg_half_to_float_n(all + 1, bulk, 65536);
  for (uint32_t h = 0; h < 65536; h++) {
    const float f = fg_half_to_float((uint16_t)h);
    if (isnan(f)) {
      ASSERT(isnan(bulk[h]));
    } else {
      uint32_t a, b;
      memcpy(&a, &f, 4);
      memcpy(&b, &bulk[h], 4);
      ASSERT_EQ(a, b);
    }
  }
  free(all);
  free(bulk);
  ASSERT_EQ(fg_float_to_half(1.0f), 0x3c00);
  ASSERT_EQ(fg_float_to_half(-2.0f), 0xc000);
  ASSERT_EQ(fg_float_to_half(-0.0f), 0x8000);
  ASSERT_EQ(fg_float_to_half(0.1f), 0x2e66);
  ASSERT_EQ(fg_float_to_half(65504.0f), 0x7bff);
  ASSERT_EQ(fg_float_to_half(65520.0f), 0x7c00); /* tie at the top rounds to even: Inf */
  ASSERT_EQ(fg_float_to_half(65519.0f), 0x7bff);
  ASSERT_EQ(fg_float_to_half(1.0f + 0x1p-11f), 0x3c00);     /* tie to even: down */
  ASSERT_EQ(fg_float_to_half(1.0f + 3 * 0x1p-11f), 0x3c02); /* tie to even: up */
  ASSERT_EQ(fg_float_to_half(1.0f + 0x1p-11f + 0x1p-20f), 0x3c01); /* above the tie */
  ASSERT_EQ(fg_float_to_half(0x1p-24f), 0x0001);             /* smallest subnormal */
  ASSERT_EQ(fg_float_to_half(0x1p-25f), 0x0000);             /* tie to even: zero */
  ASSERT_EQ(fg_float_to_half(0x1.8p-25f), 0x0001);
  ASSERT_EQ(fg_float_to_half(1e-10f), 0x0000);
  ASSERT_EQ(fg_float_to_half(INFINITY), 0x7c00);
  ASSERT_EQ(fg_float_to_half(-INFINITY), 0xfc00);
  ASSERT(isnan(fg_half_to_float(fg_float_to_half(NAN))));
  float src[3] = {0.5f, -1.25f, 3.0f}, dst[3];
  uint16_t hs[3];
  fg_float_to_half_n(src, hs, 3);
  fg_half_to_float_n(hs, dst, 3);
  for (int i = 0; i < 3; i++) ASSERT_EQ(dst[i] == src[i], 1);
}

static void rot_z(double T[16], double angle_rad) {
  memset(T, 0, 16 * sizeof *T);
  T[0] = cos(angle_rad), T[1] = -sin(angle_rad);
  T[4] = sin(angle_rad), T[5] = cos(angle_rad);
  T[10] = 1;
  T[15] = 1;
}

static void test_pose(void) {
  double I[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  ASSERT_OK(fg_pose_validate(I));

  double T[16];
  /* A unit quaternion off by rounding (norm 1 + 5e-4) is normalised, not refused. */
  const double p[3] = {0.4, -0.2, 0.3};
  const double qn = sqrt(0.95) / 1.0005;
  const double q[4] = {0.9 / qn, 0.1 / qn, -0.3 / qn, 0.2 / qn};
  ASSERT_OK(fg_pose_from_quat(p, q, T));
  ASSERT_OK(fg_pose_validate(T));

  double bad[16];
  memcpy(bad, T, sizeof bad);
  bad[5] = NAN;
  ASSERT_ERR(fg_pose_validate(bad), FG_EINVAL, "finite");
  memcpy(bad, T, sizeof bad);
  bad[3] = INFINITY;
  ASSERT_ERR(fg_pose_validate(bad), FG_EINVAL, "finite");
  memcpy(bad, T, sizeof bad);
  bad[13] = 0.5;
  ASSERT_ERR(fg_pose_validate(bad), FG_EINVAL, "last row");
  memcpy(bad, T, sizeof bad);
  bad[15] = 2;
  ASSERT_ERR(fg_pose_validate(bad), FG_EINVAL, "last row");

  double S[16];
  rot_z(S, 0.3);
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++) S[r * 4 + c] *= 1.01;
  ASSERT_ERR(fg_pose_validate(S), FG_EINVAL, "orthonormal");

  double M[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1}; /* a mirror */
  ASSERT_ERR(fg_pose_validate(M), FG_EINVAL, "determinant");

  double N[16];
  rot_z(N, 1.1);
  N[1] += 0.01; /* skew well beyond 1e-3 */
  ASSERT_ERR(fg_pose_validate(N), FG_EINVAL, "orthonormal");

  /* Noise of 1e-4 per entry, as from a JSON file printed with few digits, is accepted. */
  double Z[16];
  rot_z(Z, -0.7);
  static const double noise[9] = {1e-4, -1e-4, 5e-5, -8e-5, 1e-4, 2e-5, -1e-4, 7e-5, -3e-5};
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++) Z[r * 4 + c] += noise[r * 3 + c];
  ASSERT_OK(fg_pose_validate(Z));

  /* Quaternion round trip, including the sign convention w >= 0. */
  double p2[3], q2[4];
  fg_pose_to_quat(T, p2, q2);
  double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (int i = 0; i < 3; i++) ASSERT_NEAR(p2[i], p[i], 1e-12);
  for (int i = 0; i < 4; i++) ASSERT_NEAR(q2[i], q[i] / n, 1e-12);
  const double qneg[4] = {-0.5, 0.5, -0.5, 0.5};
  ASSERT_OK(fg_pose_from_quat(p, qneg, T));
  fg_pose_to_quat(T, p2, q2);
  for (int i = 0; i < 4; i++) ASSERT_NEAR(q2[i], -qneg[i], 1e-12);
  /* 90 degrees about z maps x to y. */
  const double qz[4] = {cos(M_PI / 4), 0, 0, sin(M_PI / 4)};
  ASSERT_OK(fg_pose_from_quat(p, qz, T));
  ASSERT_NEAR(T[0], 0, 1e-12);
  ASSERT_NEAR(T[4], 1, 1e-12);
  ASSERT_NEAR(T[1], -1, 1e-12);
  const double q0[4] = {0, 0, 0, 0};
  ASSERT_ERR(fg_pose_from_quat(p, q0, T), FG_EINVAL, "unit length");
  const double q2x[4] = {2, 0, 0, 0};
  ASSERT_ERR(fg_pose_from_quat(p, q2x, T), FG_EINVAL, "norm is 2");

  fg_convention conv;
  ASSERT_OK(fg_convention_parse("opencv", &conv));
  ASSERT_EQ(conv, FG_CONV_OPENCV);
  ASSERT_ERR(fg_convention_parse("blender", &conv), FG_EINVAL, "opengl");
  double F[16];
  memcpy(F, I, sizeof F);
  fg_pose_flip_yz(F);
  ASSERT_EQ(F[5], -1);
  ASSERT_EQ(F[10], -1);
  fg_pose_flip_yz(F);
  ASSERT_EQ(memcmp(F, I, sizeof F), 0);
}

static void test_fsutil(void) {
  char tmpl[] = "/tmp/fg_test_core_XXXXXX";
  char *dir = mkdtemp(tmpl);
  ASSERT(dir != NULL);

  char *path = fg_path_join(dir, "data.bin");
  ASSERT(path != NULL);
  const char msg[] = "hello, atomic world";
  ASSERT_OK(fg_write_file_atomic(path, msg, sizeof msg - 1));
  char *buf;
  size_t len;
  ASSERT_OK(fg_read_file(path, 1024, &buf, &len));
  ASSERT_EQ(len, sizeof msg - 1);
  ASSERT_EQ(memcmp(buf, msg, len), 0);
  ASSERT_EQ(buf[len], '\0');
  free(buf);
  ASSERT_ERR(fg_read_file(path, 5, &buf, &len), FG_ERANGE, "limit");
  ASSERT(buf == NULL);

  /* Overwriting replaces the whole content. */
  ASSERT_OK(fg_write_file_atomic(path, "x", 1));
  ASSERT_OK(fg_read_file(path, 1024, &buf, &len));
  ASSERT_EQ(len, 1);
  free(buf);

  char *missing = fg_path_join(dir, "missing");
  ASSERT_ERR(fg_read_file(missing, 1024, &buf, &len), FG_ENOENT, "missing");
  free(missing);

  /* An aborted atomic file leaves nothing behind. */
  fg_atomic_file af;
  char *aborted = fg_path_join(dir, "aborted.bin");
  ASSERT_OK(fg_atomic_file_open(&af, aborted));
  fputs("partial", af.fp);
  fg_atomic_file_abort(&af);
  ASSERT(access(aborted, F_OK) != 0);
  free(aborted);

  /* A temp file left by a killed writer is swept; the real file stays. */
  char *left = fg_path_join(dir, "x.tmp.123.0");
  ASSERT_OK(fg_write_file_atomic(left, "junk", 4));
  ASSERT_EQ(access(left, F_OK), 0);
  ASSERT_EQ(fg_fs_sweep_tmp(dir), 1);
  ASSERT(access(left, F_OK) != 0);
  ASSERT_EQ(access(path, F_OK), 0);
  free(left);

  char *deep = fg_path_join(dir, "a/b/c");
  ASSERT_OK(fg_mkdir_p(deep));
  struct stat st;
  ASSERT_EQ(stat(deep, &st), 0);
  ASSERT(S_ISDIR(st.st_mode));
  ASSERT_OK(fg_mkdir_p(deep)); /* existing is fine */
  char *leaf = fg_path_join(deep, "f");
  ASSERT_OK(fg_write_file_atomic(leaf, "1", 1));
  ASSERT_ERR(fg_mkdir_p(leaf), FG_EIO, "not a folder");
  free(leaf);
  char *a = fg_path_join(dir, "a");
  ASSERT_OK(fg_rmtree(a));
  ASSERT(access(a, F_OK) != 0);
  ASSERT_OK(fg_rmtree(a)); /* missing is success */
  free(a);
  free(deep);

  free(path);
  ASSERT_OK(fg_rmtree(dir));
  ASSERT(access(dir, F_OK) != 0);
}

/* FIPS 180-2's test vectors, and a message in parts equals it whole. */
static void test_sha256(void) {
  char hex[FG_SHA256_HEX + 1];
  fg_sha256_hex(NULL, 0, hex);
  ASSERT_STREQ(hex, "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  const fg_span abc = {"abc", 3};
  fg_sha256_hex(&abc, 1, hex);
  ASSERT_STREQ(hex, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  const char *m = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
  const fg_span parts[] = {{m, 10}, {"", 0}, {m + 10, strlen(m) - 10}};
  fg_sha256_hex(parts, 3, hex);
  ASSERT_STREQ(hex, "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  uint8_t raw[FG_SHA256_BYTES];
  fg_sha256(&abc, 1, raw);
  ASSERT_EQ(raw[0], 0xba);
  ASSERT_EQ(raw[31], 0xad);
}

/* The real-time clock in milliseconds is the one in seconds, truncated. */
static void test_clock(void) {
  const double before = fg_real_s();
  const int64_t ms = fg_real_ms();
  const double after = fg_real_s();
  ASSERT(ms >= (int64_t)(before * 1000.0) - 1);
  ASSERT(ms <= (int64_t)(after * 1000.0) + 1);
  ASSERT(ms > INT64_C(1700000000000)); /* after November 2023: milliseconds, not seconds */
}

/* A positive count is kept; anything else is OpenMP's default, at least one thread. */
static void test_threads(void) {
  ASSERT_EQ(fg_threads(3), 3);
  ASSERT_EQ(fg_threads(1), 1);
  ASSERT(fg_threads(0) >= 1);
  ASSERT_EQ(fg_threads(-2), fg_threads(0));
}

int main(void) {
  test_error();
  test_strbuf();
  test_clock();
  test_threads();
  test_sha256();
  test_half();
  test_pose();
  test_fsutil();
  printf("core: ok\n");
  return 0;
}
