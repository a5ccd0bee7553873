/* Unit tests of lib/io/npy: hand-written .npy byte strings in, values out, and every
 * malformation the parser must refuse. */
#include "test.h"

#include "core/error.h"
#include "core/half.h"
#include "io/npy.h"

#include <stdint.h>

/* Builds a .npy of the given version: magic, version, header length, header text exactly as
 * given (no padding added, so the tests control the newline), then data. */
static uint8_t *make_npy(int major, const char *header, const void *data, size_t dlen,
                         size_t *len) {
  size_t hl = strlen(header), pre = major == 1 ? 10 : 12;
  *len = pre + hl + dlen;
  uint8_t *b = malloc(*len + 1);
  ASSERT(b != NULL);
  memcpy(b, "\x93NUMPY", 6);
  b[6] = (uint8_t)major;
  b[7] = 0;
  b[8] = (uint8_t)(hl & 0xff);
  b[9] = (uint8_t)(hl >> 8);
  if (major != 1) {
    b[10] = (uint8_t)(hl >> 16);
    b[11] = (uint8_t)(hl >> 24);
  }
  memcpy(b + pre, header, hl);
  if (dlen) memcpy(b + pre + hl, data, dlen);
  return b;
}

static float f32_at(const fg_npy *a, size_t i) {
  float v;
  memcpy(&v, (const uint8_t *)a->data + 4 * i, 4);
  return v;
}

static uint16_t f16_at(const fg_npy *a, size_t i) {
  uint16_t v;
  memcpy(&v, (const uint8_t *)a->data + 2 * i, 2);
  return v;
}

static void test_parse_ok(void) {
  float v[24];
  for (int i = 0; i < 24; i++) v[i] = (float)i * 0.5f - 3.0f;
  size_t len;
  fg_npy a;

  /* Version 1.0, float32, (2, 3, 4), numpy's exact spelling and padding. */
  uint8_t *b = make_npy(1,
                        "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }      "
                        "                                                 \n",
                        v, sizeof v, &len);
  ASSERT_OK(fg_npy_parse(b, len, &a));
  ASSERT_EQ(a.dtype, FG_DTYPE_F32);
  ASSERT_EQ(a.ndim, 3);
  ASSERT_EQ(a.shape[0], 2);
  ASSERT_EQ(a.shape[1], 3);
  ASSERT_EQ(a.shape[2], 4);
  ASSERT_EQ(a.count, 24);
  for (int i = 0; i < 24; i++) ASSERT_EQ(f32_at(&a, (size_t)i) == v[i], 1);
  free(b);

  /* Version 2.0, float16, (1,). */
  uint16_t h = fg_float_to_half(1.5f);
  b = make_npy(2, "{'descr': '<f2', 'fortran_order': False, 'shape': (1,), }\n", &h, 2, &len);
  ASSERT_OK(fg_npy_parse(b, len, &a));
  ASSERT_EQ(a.dtype, FG_DTYPE_F16);
  ASSERT_EQ(a.ndim, 1);
  ASSERT_EQ(a.shape[0], 1);
  ASSERT_EQ(a.count, 1);
  ASSERT_EQ(f16_at(&a, 0), 0x3e00);
  free(b);

  /* Version 3.0, double quotes, another key order, no trailing comma, a 0-d array. */
  b = make_npy(3, "{\"shape\": (), \"fortran_order\": False, \"descr\": \"<f4\"}\n", v, 4, &len);
  ASSERT_OK(fg_npy_parse(b, len, &a));
  ASSERT_EQ(a.ndim, 0);
  ASSERT_EQ(a.count, 1);
  ASSERT_EQ(f32_at(&a, 0) == v[0], 1);
  free(b);

  /* A zero-sized dimension is a valid empty array. */
  b = make_npy(1, "{'descr': '<f4', 'fortran_order': False, 'shape': (0, 5), }\n", NULL, 0, &len);
  ASSERT_OK(fg_npy_parse(b, len, &a));
  ASSERT_EQ(a.count, 0);
  free(b);

  /* Decision: a header that does not end in a newline is tolerated. numpy's reader accepts it
   * too, and the data's position is fully defined by the header length, so refusing would only
   * reject files written by lax tools. */
  b = make_npy(1, "{'descr': '<f4', 'fortran_order': False, 'shape': (3,), }", v, 12, &len);
  ASSERT_OK(fg_npy_parse(b, len, &a));
  ASSERT_EQ(a.count, 3);
  ASSERT_EQ(f32_at(&a, 2) == v[2], 1);
  free(b);
}

/* Parses a version-1.0 file with the given header and data length; expects FG_EFORMAT. */
static void refuse(const char *header, size_t dlen, const char *substr) {
  static uint8_t zeros[4096];
  size_t len;
  uint8_t *b = make_npy(1, header, zeros, dlen, &len);
  fg_npy a;
  ASSERT_ERR(fg_npy_parse(b, len, &a), FG_EFORMAT, substr);
  free(b);
}

static void test_parse_refuse(void) {
  fg_npy a;
  size_t len;
  float v[6] = {0};

  /* Bad magic, unknown version, too short to hold a header. */
  uint8_t *b = make_npy(1, "{'descr': '<f4', 'fortran_order': False, 'shape': (6,), }\n", v,
                        sizeof v, &len);
  b[1] = 'n';
  ASSERT_ERR(fg_npy_parse(b, len, &a), FG_EFORMAT, "NUMPY");
  b[1] = 'N';
  b[6] = 4;
  ASSERT_ERR(fg_npy_parse(b, len, &a), FG_EFORMAT, "version");
  b[6] = 1;
  ASSERT_OK(fg_npy_parse(b, len, &a));
  ASSERT_ERR(fg_npy_parse(b, 7, &a), FG_EFORMAT, "");
  ASSERT_ERR(fg_npy_parse(NULL, 0, &a), FG_EFORMAT, "");

  /* Truncated data, trailing data, header length beyond the buffer. */
  ASSERT_ERR(fg_npy_parse(b, len - 1, &a), FG_EFORMAT, "truncated");
  free(b);
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (6,), }\n", 25, "trailing");
  b = make_npy(1, "{'descr': '<f4', 'fortran_order': False, 'shape': (6,), }\n", v, sizeof v,
               &len);
  b[8] = 0xff;
  b[9] = 0x7f;
  ASSERT_ERR(fg_npy_parse(b, len, &a), FG_EFORMAT, "header claims");
  free(b);
  b = make_npy(2, "{'descr': '<f4', 'fortran_order': False, 'shape': (6,), }\n", v, sizeof v,
               &len);
  b[11] = 0x80; /* 2 GB header length in a tiny file */
  ASSERT_ERR(fg_npy_parse(b, len, &a), FG_EFORMAT, "header claims");
  free(b);

  /* Data types and memory order. */
  refuse("{'descr': '>f4', 'fortran_order': False, 'shape': (6,), }\n", 24, "big-endian");
  refuse("{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }\n", 24, "'<f8'");
  refuse("{'descr': '|u1', 'fortran_order': False, 'shape': (24,), }\n", 24, "'|u1'");
  refuse("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (6,), }\n", 24,
         "structured");
  refuse("{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3), }\n", 24, "Fortran");
  refuse("{'descr': '<f4', 'fortran_order': Maybe, 'shape': (6,), }\n", 24, "fortran_order");

  /* Shapes: negative, overflowing, too many dimensions, malformed. */
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (-1, 6), }\n", 24, "negative");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 4), }\n", 24,
         "too large");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (4611686018427387904,), }\n", 24,
         "too large");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999999999999999,), }\n", 24,
         "too large");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (1,1,1,1,1,1,1,1,6), }\n", 24,
         "dimensions");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (6 3), }\n", 24, "malformed");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': [6], }\n", 24, "'('");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (2.5,), }\n", 24, "shape");

  /* Keys: missing, unknown, repeated; not a dict at all. */
  refuse("{'descr': '<f4', 'fortran_order': False, }\n", 24, "'shape'");
  refuse("{'fortran_order': False, 'shape': (6,), }\n", 24, "'descr'");
  refuse("{'descr': '<f4', 'shape': (6,), }\n", 24, "'fortran_order'");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (6,), 'extra': 1}\n", 24, "extra");
  refuse("{'descr': '<f4', 'descr': '<f4', 'fortran_order': False, 'shape': (6,)}\n", 24,
         "repeated");
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (6,), \n", 24, NULL);
  refuse("{'descr': '<f4', 'fortran_order': False, 'shape': (6,)} x\n", 24, "after");
  refuse("['descr', '<f4']\n", 24, "dict");
  refuse("{'descr: '<f4', 'fortran_order': False, 'shape': (6,)}\n", 24, NULL);
  refuse("", 24, NULL);
}

static void test_encode_roundtrip(void) {
  float v[24];
  for (int i = 0; i < 24; i++) v[i] = (float)i / 7.0f;
  const size_t shape[3] = {2, 3, 4};
  uint8_t *buf;
  size_t len;
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F32, 3, shape, v, &buf, &len));
  size_t hlen = (size_t)buf[8] | (size_t)buf[9] << 8;
  ASSERT_EQ((10 + hlen) % 64, 0); /* data aligned as numpy writes it */
  ASSERT_EQ(buf[10 + hlen - 1], '\n');
  fg_npy a;
  ASSERT_OK(fg_npy_parse(buf, len, &a));
  ASSERT_EQ(a.dtype, FG_DTYPE_F32);
  ASSERT_EQ(a.ndim, 3);
  for (int i = 0; i < 3; i++) ASSERT_EQ(a.shape[i], shape[i]);
  ASSERT_EQ(memcmp(a.data, v, sizeof v), 0);
  free(buf);

  uint16_t h[5];
  for (int i = 0; i < 5; i++) h[i] = fg_float_to_half((float)i - 2.5f);
  const size_t shape1[1] = {5};
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F16, 1, shape1, h, &buf, &len));
  ASSERT(memmem(buf, len, "(5,)", 4) != NULL); /* Python's one-tuple spelling */
  ASSERT_OK(fg_npy_parse(buf, len, &a));
  ASSERT_EQ(a.dtype, FG_DTYPE_F16);
  ASSERT_EQ(a.ndim, 1);
  ASSERT_EQ(a.count, 5);
  ASSERT_EQ(memcmp(a.data, h, sizeof h), 0);
  free(buf);

  ASSERT_OK(fg_npy_encode(FG_DTYPE_F32, 0, NULL, v, &buf, &len));
  ASSERT_OK(fg_npy_parse(buf, len, &a));
  ASSERT_EQ(a.ndim, 0);
  ASSERT_EQ(a.count, 1);
  free(buf);

  ASSERT_ERR(fg_npy_encode(FG_DTYPE_NONE, 1, shape1, v, &buf, &len), FG_EINVAL, "dtype");
  ASSERT_ERR(fg_npy_encode(FG_DTYPE_F32, 9, shape1, v, &buf, &len), FG_EINVAL, "dimensions");
  ASSERT(buf == NULL);
  ASSERT_EQ(fg_dtype_size(FG_DTYPE_F32), 4);
  ASSERT_EQ(fg_dtype_size(FG_DTYPE_F16), 2);
  ASSERT_EQ(fg_dtype_size(FG_DTYPE_NONE), 0);
}

int main(void) {
  test_parse_ok();
  test_parse_refuse();
  test_encode_roundtrip();
  printf("npy: ok\n");
  return 0;
}
