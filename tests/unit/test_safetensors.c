/* Unit tests of lib/io/safetensors: files built by a small writer below (the layout the
 * Python writer produces: header padded with spaces to a multiple of 8), exact values read
 * back in every float dtype, and every malformation the reader must refuse, each checked by
 * the detail sentence of the check that should have fired. */
#include "test.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "io/safetensors.h"

#include <stdint.h>
#include <stdio.h>
#include <unistd.h>

static char tmpdir[64];

/* ---- a small writer ----------------------------------------------------------------- */

typedef struct writer {
  char hdr[1 << 16]; /* JSON text so far */
  size_t hlen;
  uint8_t *data;
  size_t dlen;
} writer;

static void w_init(writer *w) {
  memset(w, 0, sizeof *w);
  w->hdr[0] = '{';
  w->hlen = 1;
}

static void w_text(writer *w, const char *s) {
  size_t n = strlen(s);
  ASSERT(w->hlen + n < sizeof w->hdr);
  memcpy(w->hdr + w->hlen, s, n);
  w->hlen += n;
}

/* Appends a tensor: its header entry (shape given as JSON text, e.g. "[2, 3]") and its
 * bytes at the end of the data section. */
static void w_tensor(writer *w, const char *name, const char *dtype, const char *shape,
                     const void *bytes, size_t n) {
  char ent[512];
  snprintf(ent, sizeof ent, "%s\"%s\":{\"dtype\":\"%s\",\"shape\":%s,\"data_offsets\":[%zu,%zu]}",
           w->hlen > 1 ? "," : "", name, dtype, shape, w->dlen, w->dlen + n);
  w_text(w, ent);
  w->data = realloc(w->data, w->dlen + n + 1);
  ASSERT(w->data != NULL);
  if (n) memcpy(w->data + w->dlen, bytes, n);
  w->dlen += n;
}

/* Finishes the header and returns the whole file (malloc'd exactly len bytes, so that ASan
 * sees any read past its end). pad: spaces after the JSON; -1 pads to a multiple of 8. */
static uint8_t *w_finish(writer *w, int pad, size_t *len) {
  w_text(w, "}");
  size_t npad = pad >= 0 ? (size_t)pad : (8 - w->hlen % 8) % 8;
  size_t hl = w->hlen + npad;
  *len = 8 + hl + w->dlen;
  uint8_t *b = malloc(*len);
  ASSERT(b != NULL);
  for (int i = 0; i < 8; i++) b[i] = (uint8_t)((uint64_t)hl >> (8 * i));
  memcpy(b + 8, w->hdr, w->hlen);
  memset(b + 8 + w->hlen, ' ', npad);
  if (w->dlen) memcpy(b + 8 + hl, w->data, w->dlen);
  free(w->data);
  w->data = NULL;
  return b;
}

/* A file of an arbitrary header length field, header text and dlen zero bytes of data. */
static uint8_t *raw_file(uint64_t hlen_field, const char *header, size_t dlen, size_t *len) {
  size_t hl = strlen(header);
  *len = 8 + hl + dlen;
  uint8_t *b = calloc(1, *len);
  ASSERT(b != NULL);
  for (int i = 0; i < 8; i++) b[i] = (uint8_t)(hlen_field >> (8 * i));
  memcpy(b + 8, header, hl);
  return b;
}

static void write_file(const char *path, const void *b, size_t len) {
  FILE *f = fopen(path, "wb");
  ASSERT(f != NULL);
  ASSERT_EQ(fwrite(b, 1, len, f), len);
  ASSERT_EQ(fclose(f), 0);
}

static char *tmp_path(const char *name) {
  char *p = fg_path_join(tmpdir, name);
  ASSERT(p != NULL);
  return p;
}

/* Bit pattern of a float, to compare exactly (signed zeros, subnormals). */
static uint32_t bits_of(float f) {
  uint32_t u;
  memcpy(&u, &f, 4);
  return u;
}

/* ---- valid files -------------------------------------------------------------------- */

static void test_valid_file(void) {
  float f32[6] = {0.0f, 1.0f, -2.5f, 3.25e-3f, 1e30f, -7.0f};
  /* F16: 1.0, -2.5, 65504 (max), 2^-24 (smallest subnormal), 1023 * 2^-24 (largest
   * subnormal), -0.0, +Inf */
  uint16_t f16[7] = {0x3c00, 0xc100, 0x7bff, 0x0001, 0x03ff, 0x8000, 0x7c00};
  /* BF16: 1.0, -2.5, 3.140625, max finite, smallest subnormal, -Inf */
  uint16_t bf16[6] = {0x3f80, 0xc020, 0x4049, 0x7f7f, 0x0001, 0xff80};
  int64_t pos[4] = {0, 1, 2, -3};
  uint8_t u8[3] = {7, 8, 9};
  float m[12];
  for (int i = 0; i < 12; i++) m[i] = (float)i + 0.5f;
  uint16_t u16[2] = {1, 2};

  writer w;
  w_init(&w);
  w_text(&w, "\"__metadata__\":{\"format\":\"pt\",\"note\":\"caf\\u00e9 \\\"q\\\"\"}");
  /* header order deliberately not alphabetical */
  w_tensor(&w, "zeta.f32", "F32", "[2, 3]", f32, sizeof f32);
  w_tensor(&w, "alpha.f16", "F16", "[7]", f16, sizeof f16);
  w_tensor(&w, "bytes", "U8", "[3]", u8, sizeof u8);
  /* starts at an odd offset: the conversions must not assume alignment */
  w_tensor(&w, "mid.bf16", "BF16", "[6]", bf16, sizeof bf16);
  w_tensor(&w, "position_ids", "I64", "[1, 4]", pos, sizeof pos);
  w_tensor(&w, "matrix", "F32", "[3, 4]", m, sizeof m);
  w_tensor(&w, "scalar", "F32", "[]", f32 + 1, 4);
  w_tensor(&w, "empty", "F16", "[0, 5]", NULL, 0);
  w_tensor(&w, "u16", "U16", "[2]", u16, sizeof u16);
  size_t len;
  uint8_t *b = w_finish(&w, -1, &len);
  ASSERT_EQ((b[0] | b[1] << 8) % 8, 0); /* padded like the Python writer */
  char *path = tmp_path("model.safetensors");
  write_file(path, b, len);
  free(b);

  fg_st *st = (fg_st *)1;
  ASSERT_OK(fg_st_open(&st, path));
  ASSERT_EQ(fg_st_count(st), 9);
  static const char *order[9] = {"zeta.f32", "alpha.f16", "bytes",  "mid.bf16", "position_ids",
                                 "matrix",   "scalar",    "empty",  "u16"};
  static const fg_st_dtype dts[9] = {FG_ST_F32, FG_ST_F16, FG_ST_U8,  FG_ST_BF16, FG_ST_I64,
                                     FG_ST_F32, FG_ST_F32, FG_ST_F16, FG_ST_OTHER};
  fg_st_tensor t, u;
  for (int i = 0; i < 9; i++) {
    ASSERT_OK(fg_st_tensor_at(st, i, &t));
    ASSERT_STREQ(t.name, order[i]);
    ASSERT_EQ(t.dtype, dts[i]);
    ASSERT_OK(fg_st_find(st, order[i], &u));
    ASSERT(memcmp(&t, &u, sizeof t) == 0);
  }
  ASSERT_ERR(fg_st_tensor_at(st, 9, &t), FG_EINVAL, "out of range");
  ASSERT_ERR(fg_st_tensor_at(st, -1, &t), FG_EINVAL, "out of range");
  ASSERT_ERR(fg_st_find(st, "nope", &t), FG_ENOENT, "no tensor \"nope\" in ");
  ASSERT_STRCONTAINS(fg_error_detail(), "model.safetensors");
  ASSERT_ERR(fg_st_find(st, "zeta.f3", &t), FG_ENOENT, "zeta.f3");
  ASSERT_ERR(fg_st_find(st, "", &t), FG_ENOENT, "no tensor");

  ASSERT_STREQ(fg_st_metadata(st, "format"), "pt");
  ASSERT_STREQ(fg_st_metadata(st, "note"), "caf\xc3\xa9 \"q\"");
  ASSERT(fg_st_metadata(st, "missing") == NULL);
  ASSERT(fg_st_metadata(st, "zeta.f32") == NULL);

  /* F32 */
  float out[16];
  ASSERT_OK(fg_st_find(st, "zeta.f32", &t));
  ASSERT_EQ(t.ndim, 2);
  ASSERT_EQ(t.shape[0], 2);
  ASSERT_EQ(t.shape[1], 3);
  ASSERT_EQ(t.count, 6);
  ASSERT_EQ(t.nbytes, 24);
  ASSERT_OK(fg_st_read_f32(&t, out, 6));
  for (int i = 0; i < 6; i++) ASSERT_EQ(bits_of(out[i]), bits_of(f32[i]));
  ASSERT_ERR(fg_st_read_f32(&t, out, 5), FG_EINVAL, "6 elements");
  ASSERT_ERR(fg_st_read_f32(&t, out, 7), FG_EINVAL, "zeta.f32");

  /* F16 */
  ASSERT_OK(fg_st_find(st, "alpha.f16", &t));
  ASSERT_EQ(t.nbytes, 14);
  ASSERT_OK(fg_st_read_f32(&t, out, 7));
  ASSERT_EQ(bits_of(out[0]), bits_of(1.0f));
  ASSERT_EQ(bits_of(out[1]), bits_of(-2.5f));
  ASSERT_EQ(bits_of(out[2]), bits_of(65504.0f));
  ASSERT_EQ(bits_of(out[3]), bits_of(ldexpf(1.0f, -24)));
  ASSERT_EQ(bits_of(out[4]), bits_of(1023.0f * ldexpf(1.0f, -24)));
  ASSERT_EQ(bits_of(out[5]), 0x80000000u);
  ASSERT(isinf(out[6]) && out[6] > 0);

  /* BF16 at an odd address */
  ASSERT_OK(fg_st_find(st, "mid.bf16", &t));
  ASSERT_EQ(((uintptr_t)t.data) % 2, 1);
  ASSERT_OK(fg_st_read_f32(&t, out, 6));
  ASSERT_EQ(bits_of(out[0]), bits_of(1.0f));
  ASSERT_EQ(bits_of(out[1]), bits_of(-2.5f));
  ASSERT_EQ(bits_of(out[2]), bits_of(3.140625f));
  ASSERT_EQ(bits_of(out[3]), 0x7f7f0000u);
  ASSERT_NEAR(out[3], 3.3895313892515355e38, 1e31);
  ASSERT_EQ(bits_of(out[4]), 0x00010000u); /* 2^-133, a float32 subnormal */
  ASSERT(isinf(out[5]) && out[5] < 0);

  /* I64 loads, keeps its bytes, and refuses conversion */
  ASSERT_OK(fg_st_find(st, "position_ids", &t));
  ASSERT_EQ(t.count, 4);
  ASSERT_EQ(t.nbytes, 32);
  int64_t p3;
  memcpy(&p3, (const uint8_t *)t.data + 24, 8);
  ASSERT_EQ(p3, -3);
  ASSERT_ERR(fg_st_read_f32(&t, out, 4), FG_EFORMAT, "tensor \"position_ids\" has dtype I64");
  ASSERT_ERR(fg_st_read_rows_f32(&t, 0, 1, out), FG_EFORMAT, "I64");
  ASSERT_OK(fg_st_find(st, "u16", &t));
  ASSERT_EQ(t.nbytes, 4);
  ASSERT_ERR(fg_st_read_f32(&t, out, 2), FG_EFORMAT, "OTHER");
  ASSERT_OK(fg_st_find(st, "bytes", &t));
  ASSERT_EQ(((const uint8_t *)t.data)[2], 9);

  /* rows of a 2-D tensor */
  ASSERT_OK(fg_st_find(st, "matrix", &t));
  for (int i = 0; i < 16; i++) out[i] = -1.0f;
  ASSERT_OK(fg_st_read_rows_f32(&t, 1, 2, out));
  for (int i = 0; i < 8; i++) ASSERT_EQ(bits_of(out[i]), bits_of(m[4 + i]));
  ASSERT_EQ(bits_of(out[8]), bits_of(-1.0f)); /* wrote exactly nrows * cols */
  ASSERT_OK(fg_st_read_rows_f32(&t, 2, 1, out));
  ASSERT_EQ(bits_of(out[3]), bits_of(m[11]));
  ASSERT_OK(fg_st_read_rows_f32(&t, 3, 0, out));
  ASSERT_ERR(fg_st_read_rows_f32(&t, 2, 2, out), FG_EINVAL, "outside tensor \"matrix\"");
  ASSERT_ERR(fg_st_read_rows_f32(&t, 4, 0, out), FG_EINVAL, "3 rows");
  ASSERT_ERR(fg_st_read_rows_f32(&t, 1, SIZE_MAX, out), FG_EINVAL, "outside");
  ASSERT_OK(fg_st_find(st, "alpha.f16", &t));
  ASSERT_ERR(fg_st_read_rows_f32(&t, 0, 1, out), FG_EINVAL, "1 dimensions");

  /* a scalar and an empty tensor */
  ASSERT_OK(fg_st_find(st, "scalar", &t));
  ASSERT_EQ(t.ndim, 0);
  ASSERT_EQ(t.count, 1);
  ASSERT_OK(fg_st_read_f32(&t, out, 1));
  ASSERT_EQ(bits_of(out[0]), bits_of(1.0f));
  ASSERT_OK(fg_st_find(st, "empty", &t));
  ASSERT_EQ(t.count, 0);
  ASSERT_EQ(t.nbytes, 0);
  ASSERT_OK(fg_st_read_f32(&t, NULL, 0));
  fg_st_close(st);

  ASSERT_STREQ(fg_st_dtype_name(FG_ST_BF16), "BF16");
  ASSERT_STREQ(fg_st_dtype_name(FG_ST_I64), "I64");
  ASSERT_STREQ(fg_st_dtype_name(FG_ST_BOOL), "BOOL");
  fg_st_close(NULL);
  unlink(path);
  free(path);
}

/* Header padding: none, the Python writer's multiple of 8, and far more than needed; all
 * read the same data. Also fg_st_parse from memory and an empty file "{}". */
static void test_padding_and_memory(void) {
  float v[3] = {1.5f, -2.0f, 4.0f};
  for (int pad = -1; pad <= 40; pad += 41 / 3) {
    writer w;
    w_init(&w);
    w_tensor(&w, "v", "F32", "[3]", v, sizeof v);
    size_t len;
    uint8_t *b = w_finish(&w, pad, &len);
    fg_st *st = NULL;
    ASSERT_OK(fg_st_parse(&st, b, len));
    fg_st_tensor t;
    ASSERT_OK(fg_st_find(st, "v", &t));
    ASSERT(t.data == b + len - 12);
    float out[3];
    ASSERT_OK(fg_st_read_f32(&t, out, 3));
    ASSERT(memcmp(out, v, sizeof v) == 0);
    ASSERT_ERR(fg_st_find(st, "w", &t), FG_ENOENT, "no tensor \"w\" in <memory>");
    fg_st_close(st);
    free(b);
  }
  size_t len;
  uint8_t *b = raw_file(8, "{}      ", 0, &len);
  fg_st *st = NULL;
  ASSERT_OK(fg_st_parse(&st, b, len));
  ASSERT_EQ(fg_st_count(st), 0);
  fg_st_tensor t;
  ASSERT_ERR(fg_st_find(st, "x", &t), FG_ENOENT, "no tensor \"x\"");
  ASSERT(fg_st_metadata(st, "format") == NULL);
  fg_st_close(st);
  free(b);
  /* leading whitespace and newlines are JSON whitespace too */
  b = raw_file(5, "\n{} \n", 0, &len);
  ASSERT_OK(fg_st_parse(&st, b, len));
  fg_st_close(st);
  free(b);
  ASSERT_ERR(fg_st_parse(&st, NULL, 3), FG_EINVAL, "NULL");

  /* an empty tensor at the offset where a non-empty one begins, listed after it: not an
   * overlap, whatever the header order */
  static const char *hdr_empty_after =
      "{\"a\":{\"dtype\":\"F32\",\"shape\":[1],\"data_offsets\":[0,4]},"
      "\"e\":{\"dtype\":\"F32\",\"shape\":[0],\"data_offsets\":[0,0]}}";
  b = raw_file(strlen(hdr_empty_after), hdr_empty_after, 4, &len);
  ASSERT_OK(fg_st_parse(&st, b, len));
  ASSERT_OK(fg_st_find(st, "e", &t));
  ASSERT_EQ(t.nbytes, 0);
  fg_st_close(st);
  free(b);

  /* a zero dimension empties the tensor even when the others multiply past size_t */
  static const char *hdr_huge_empty =
      "{\"z\":{\"dtype\":\"F32\",\"shape\":[4611686018427387904,4611686018427387904,0],"
      "\"data_offsets\":[0,0]}}";
  b = raw_file(strlen(hdr_huge_empty), hdr_huge_empty, 0, &len);
  ASSERT_OK(fg_st_parse(&st, b, len));
  ASSERT_OK(fg_st_find(st, "z", &t));
  ASSERT_EQ(t.count, 0);
  ASSERT_EQ(t.ndim, 3);
  ASSERT_EQ(t.shape[1], 4611686018427387904LL);
  fg_st_close(st);
  free(b);
}

/* Many tensors: every one found by name, with its own data (the lookup is a sorted search,
 * so names that sort differently from header order must all be found). */
static void test_many_tensors(void) {
  writer w;
  w_init(&w);
  for (int i = 0; i < 500; i++) {
    char name[32];
    snprintf(name, sizeof name, "layer.%d.w", (i * 7919) % 500);
    float v = (float)((i * 7919) % 500);
    w_tensor(&w, name, "F32", "[1]", &v, 4);
  }
  size_t len;
  uint8_t *b = w_finish(&w, -1, &len);
  fg_st *st = NULL;
  ASSERT_OK(fg_st_parse(&st, b, len));
  ASSERT_EQ(fg_st_count(st), 500);
  for (int k = 0; k < 500; k++) {
    char name[32];
    snprintf(name, sizeof name, "layer.%d.w", k);
    fg_st_tensor t;
    ASSERT_OK(fg_st_find(st, name, &t));
    float v;
    ASSERT_OK(fg_st_read_f32(&t, &v, 1));
    ASSERT_EQ(v, k);
  }
  fg_st_tensor t;
  ASSERT_ERR(fg_st_find(st, "layer.500.w", &t), FG_ENOENT, "layer.500.w");
  ASSERT_ERR(fg_st_find(st, "layer.", &t), FG_ENOENT, "layer.");
  fg_st_close(st);
  free(b);
}

/* Long F16 and BF16 tensors at unaligned addresses: the chunked conversion matches the
 * element-wise reference across chunk boundaries. */
static void test_long_conversion(void) {
  enum { N = 5003 };
  uint16_t *h = malloc(N * 2), *bf = malloc(N * 2);
  float *out = malloc(N * 4);
  ASSERT(h && bf && out);
  uint32_t s = 12345;
  for (int i = 0; i < N; i++) {
    s = s * 1664525u + 1013904223u;
    h[i] = (uint16_t)(s >> 16);
    bf[i] = (uint16_t)(s >> 8);
  }
  uint8_t one = 0;
  writer w;
  w_init(&w);
  w_tensor(&w, "pad", "BOOL", "[1]", &one, 1);
  w_tensor(&w, "h", "F16", "[5003]", h, N * 2);
  w_tensor(&w, "b", "BF16", "[1, 5003]", bf, N * 2);
  size_t len;
  uint8_t *b = w_finish(&w, 0, &len);
  fg_st *st = NULL;
  ASSERT_OK(fg_st_parse(&st, b, len));
  fg_st_tensor t;
  ASSERT_OK(fg_st_find(st, "h", &t));
  ASSERT_OK(fg_st_read_f32(&t, out, N));
  for (int i = 0; i < N; i++) {
    float ref = fg_half_to_float(h[i]);
    if (isnan(ref)) ASSERT(isnan(out[i]));
    else ASSERT_EQ(bits_of(out[i]), bits_of(ref));
  }
  ASSERT_OK(fg_st_find(st, "b", &t));
  ASSERT_OK(fg_st_read_f32(&t, out, N));
  for (int i = 0; i < N; i++) ASSERT_EQ(bits_of(out[i]), (uint32_t)bf[i] << 16);
  ASSERT_OK(fg_st_read_rows_f32(&t, 0, 1, out));
  ASSERT_EQ(bits_of(out[N - 1]), (uint32_t)bf[N - 1] << 16);
  fg_st_close(st);
  free(b);
  free(h);
  free(bf);
  free(out);
}

/* ---- malformed files ---------------------------------------------------------------- */

/* fg_st_parse of header text plus dlen bytes of data must fail with code and a detail
 * containing substr, and leave *out NULL. */
static void expect_bad_hlen(uint64_t hlen, const char *header, size_t dlen, int code,
                            const char *substr, int line) {
  size_t len;
  uint8_t *b = raw_file(hlen, header, dlen, &len);
  fg_st *st = (fg_st *)1;
  int rc = fg_st_parse(&st, b, len);
  if (rc != code || !strstr(fg_error_detail(), substr) || st != NULL)
    FG_TEST_FAIL("line %d: header %s: rc %d (want %d), detail \"%s\" (want \"%s\")", line, header,
                 rc, code, fg_error_detail(), substr);
  if (code == FG_EFORMAT && !strstr(fg_error_detail(), "<memory>"))
    FG_TEST_FAIL("line %d: detail \"%s\" does not name the file", line, fg_error_detail());
  free(b);
}

#define BAD(header, dlen, substr) \
  expect_bad_hlen(strlen(header), header, dlen, FG_EFORMAT, substr, __LINE__)

#define T1(name, dtype, shape, offs) \
  "\"" name "\":{\"dtype\":\"" dtype "\",\"shape\":" shape ",\"data_offsets\":" offs "}"

static void test_malformed(void) {
  fg_st *st = (fg_st *)1;
  /* shorter than 8 bytes */
  uint8_t small[8] = {2, 0, 0, 0, 0, 0, 0, 0};
  for (size_t n = 0; n < 8; n++) {
    ASSERT_ERR(fg_st_parse(&st, small, n), FG_EFORMAT, "shorter than the 8-byte");
    ASSERT(st == NULL);
  }
  ASSERT_ERR(fg_st_parse(&st, NULL, 0), FG_EFORMAT, "<memory>: the file is 0 bytes");

  /* header length field */
  expect_bad_hlen(0, "{}", 0, FG_EFORMAT, "header length is 0", __LINE__);
  expect_bad_hlen(3, "{}", 0, FG_EFORMAT, "runs past the end", __LINE__);
  expect_bad_hlen(UINT64_MAX, "{}", 0, FG_EFORMAT, "above the limit", __LINE__);
  expect_bad_hlen(FG_ST_MAX_HEADER + 1, "{}", 0, FG_EFORMAT, "above the limit", __LINE__);
  expect_bad_hlen((uint64_t)1 << 40, "{}", 0, FG_EFORMAT, "above the limit", __LINE__);

  /* not JSON, not UTF-8, not an object, NUL characters */
  BAD("{\"a\": }", 0, "not valid UTF-8 JSON");
  BAD("{\"a\xff\": {}}", 0, "not valid UTF-8 JSON");
  BAD("{\"\xc0\xaf\": {}}", 0, "not valid UTF-8 JSON"); /* overlong '/' */
  BAD("{\"\xed\xa0\x80\": {}}", 0, "not valid UTF-8 JSON"); /* a surrogate */
  BAD("{} x", 0, "not valid UTF-8 JSON");
  BAD("{}\t\x01", 0, "not valid UTF-8 JSON");
  BAD("[1, 2]", 0, "not a JSON object");
  BAD("{\"a\\u0000b\":" "{\"dtype\":\"F32\",\"shape\":[],\"data_offsets\":[0,4]}}", 4,
      "not valid UTF-8 JSON");
  {
    /* a raw NUL inside the header bytes */
    size_t len;
    uint8_t *b = raw_file(4, "{}  ", 0, &len);
    b[10] = 0;
    ASSERT_ERR(fg_st_parse(&st, b, len), FG_EFORMAT, "not valid UTF-8 JSON");
    free(b);
  }
  BAD("{" T1("a", "F32", "[1]", "[0,4]") "," T1("a", "F32", "[1]", "[4,8]") "}", 8,
      "duplicate");

  /* tensor entries */
  BAD("{\"a\": 3}", 0, "tensor \"a\" is not an object");
  BAD("{\"a\": {\"shape\":[],\"data_offsets\":[0,4]}}", 4, "tensor \"a\" has no dtype");
  BAD("{\"a\": {\"dtype\":4,\"shape\":[],\"data_offsets\":[0,4]}}", 4, "non-string dtype");
  BAD("{" T1("w", "Q4", "[1]", "[0,4]") "}", 4, "tensor \"w\" has the unknown dtype \"Q4\"");
  BAD("{" T1("w", "f32", "[1]", "[0,4]") "}", 4, "unknown dtype \"f32\"");
  BAD("{\"a\": {\"dtype\":\"F32\",\"shape\":[],\"data_offsets\":[0,4],\"x\":1}}", 4,
      "tensor \"a\" has an unexpected key \"x\"");
  BAD("{\"a\": {\"dtype\":\"F32\",\"data_offsets\":[0,4]}}", 4, "tensor \"a\" has no shape");
  BAD("{" T1("a", "F32", "4", "[0,16]") "}", 16, "non-array shape");
  BAD("{" T1("a", "F32", "[2, -2]", "[0,16]") "}", 16,
      "tensor \"a\": shape dimension 1 is not a non-negative integer");
  BAD("{" T1("a", "F32", "[1.5]", "[0,4]") "}", 4, "dimension 0 is not a non-negative integer");
  BAD("{" T1("a", "F32", "[\"2\"]", "[0,8]") "}", 8, "not a non-negative integer");
  BAD("{" T1("a", "U8", "[1,1,1,1,1,1,1,1,1]", "[0,1]") "}", 1, "9 dimensions; at most 8");
  BAD("{" T1("a", "F32", "[4611686018427387904, 4611686018427387904]", "[0,0]") "}", 0,
      "tensor \"a\": shape is too large to address");
  BAD("{" T1("a", "F32", "[4611686018427387904]", "[0,0]") "}", 0, "too large to address");
  BAD("{" T1("a", "F64", "[9223372036854775807]", "[0,0]") "}", 0, "too large to address");

  /* data_offsets */
  BAD("{\"a\": {\"dtype\":\"F32\",\"shape\":[1]}}", 4, "data_offsets must be");
  BAD("{" T1("a", "F32", "[1]", "[0]") "}", 4, "tensor \"a\": data_offsets must be");
  BAD("{" T1("a", "F32", "[1]", "[0,4,8]") "}", 4, "data_offsets must be");
  BAD("{" T1("a", "F32", "[1]", "[-4,0]") "}", 4, "data_offsets must be");
  BAD("{" T1("a", "F32", "[1]", "[0,\"4\"]") "}", 4, "data_offsets must be");
  BAD("{" T1("a", "F32", "[1]", "{}") "}", 4, "data_offsets must be");
  BAD("{" T1("a", "F32", "[1]", "[8,4]") "}", 8, "data_offsets [8, 4] end before they begin");
  BAD("{" T1("a", "F32", "[2, 4]", "[0,12]") "}", 12,
      "<memory>: tensor \"a\": data_offsets [0, 12] hold 12 bytes but shape [2, 4] of F32 "
      "needs 32");
  BAD("{" T1("a", "BF16", "[]", "[0,4]") "}", 4, "hold 4 bytes but shape [] of BF16 needs 2");
  BAD("{" T1("a", "F32", "[2]", "[0,8]") "}", 4, "tensor \"a\": data_offsets [0, 8] end past "
                                                 "the data section of 4 bytes");
  BAD("{" T1("a", "F32", "[1]", "[18446744073709551612,18446744073709551616]") "}", 4,
      "not valid UTF-8 JSON"); /* 2^64 does not fit jansson's integers: a syntax error */

  /* coverage of the data section */
  BAD("{" T1("a", "F32", "[2]", "[0,8]") "," T1("b", "F32", "[2]", "[4,12]") "}", 12,
      "tensors \"a\" [0, 8] and \"b\" [4, 12] overlap");
  BAD("{" T1("b", "F32", "[2]", "[4,12]") "," T1("a", "F32", "[2]", "[0,8]") "}", 12,
      "overlap"); /* found in offset order, not header order */
  BAD("{" T1("a", "F32", "[1]", "[0,4]") "," T1("b", "F32", "[1]", "[0,4]") "}", 4, "overlap");
  BAD("{" T1("a", "F32", "[2]", "[0,8]") "," T1("e", "F32", "[0]", "[4,4]") "}", 8, "overlap");
  BAD("{" T1("a", "F32", "[1]", "[0,4]") "," T1("b", "F32", "[1]", "[8,12]") "}", 12,
      "bytes [4, 8) of the data section belong to no tensor (a gap before tensor \"b\")");
  BAD("{" T1("a", "F32", "[1]", "[4,8]") "}", 8, "bytes [0, 4) of the data section");
  BAD("{" T1("a", "F32", "[1]", "[0,4]") "}", 5,
      "bytes [4, 5) at the end of the data section belong to no tensor");
  BAD("{}", 3, "no tensors but a data section of 3 bytes");
  BAD("{\"__metadata__\":{}}", 1, "no tensors but a data section");

  /* names and metadata */
  BAD("{" T1("", "F32", "[1]", "[0,4]") "}", 4, "empty name");
  BAD("{\"__metadata__\":[]}", 0, "__metadata__ must be an object of strings");
  BAD("{\"__metadata__\":\"pt\"}", 0, "__metadata__ must be an object");
  BAD("{\"__metadata__\":{\"format\":\"pt\",\"n\":3}}", 0, "__metadata__ \"n\" must be a string");
  BAD("{\"__metadata__\":{\"k\":null}}", 0, "__metadata__ \"k\" must be a string");
  BAD("{\"__metadata__\":{\"k\":{}}}", 0, "must be a string");
  /* an error after metadata and tensors were allocated (ASan checks that it all is freed) */
  BAD("{\"__metadata__\":{\"k\":\"v\"}," T1("a", "F32", "[1]", "[0,4]") "," T1("b", "F32", "[1]",
      "[4,8]") "," T1("c", "Q", "[1]", "[8,12]") "}", 12, "unknown dtype \"Q\"");
}

/* Errors of fg_st_open: missing file, a folder, and the file's path in content errors. */
static void test_open_errors(void) {
  fg_st *st = (fg_st *)1;
  char *path = tmp_path("missing.safetensors");
  ASSERT_ERR(fg_st_open(&st, path), FG_ENOENT, path);
  ASSERT(st == NULL);
  free(path);
  path = tmp_path("missing/dir/x.safetensors");
  ASSERT_ERR(fg_st_open(&st, path), FG_ENOENT, "missing/dir/x.safetensors");
  free(path);
  ASSERT_ERR(fg_st_open(&st, tmpdir), FG_EIO, "not a regular file");
  ASSERT(st == NULL);

  path = tmp_path("empty.safetensors");
  write_file(path, "", 0);
  ASSERT_ERR(fg_st_open(&st, path), FG_EFORMAT, "empty.safetensors: the file is 0 bytes");
  unlink(path);
  free(path);

  /* the example from the issue: the detail names the file and the tensor */
  const char *hdr = "{" T1("visual.proj", "F32", "[2, 4]", "[0,12]") "}";
  size_t len;
  uint8_t *b = raw_file(strlen(hdr), hdr, 12, &len);
  path = tmp_path("clip.safetensors");
  write_file(path, b, len);
  free(b);
  ASSERT_ERR(fg_st_open(&st, path), FG_EFORMAT,
             "clip.safetensors: tensor \"visual.proj\": data_offsets [0, 12] hold 12 bytes but "
             "shape [2, 4] of F32 needs 32");
  ASSERT(st == NULL);
  ASSERT_STRCONTAINS(fg_error_detail(), tmpdir); /* the path as given */
  unlink(path);
  free(path);
}

/* Every truncation of a valid file fails cleanly, from memory and from disk. */
static void test_truncation(void) {
  float v[4] = {1, 2, 3, 4};
  uint16_t h[3] = {0x3c00, 0x4000, 0x4200};
  writer w;
  w_init(&w);
  w_text(&w, "\"__metadata__\":{\"format\":\"pt\"}");
  w_tensor(&w, "a", "F32", "[2, 2]", v, sizeof v);
  w_tensor(&w, "b", "F16", "[3]", h, sizeof h);
  size_t len;
  uint8_t *b = w_finish(&w, -1, &len);
  fg_st *st = NULL;
  ASSERT_OK(fg_st_parse(&st, b, len));
  ASSERT_EQ(fg_st_count(st), 2);
  ASSERT_STREQ(fg_st_metadata(st, "format"), "pt");
  fg_st_close(st);

  char *path = tmp_path("trunc.safetensors");
  for (size_t n = 0; n < len; n++) {
    uint8_t *c = malloc(n ? n : 1); /* exactly n bytes: ASan flags any read past them */
    ASSERT(c != NULL);
    memcpy(c, b, n);
    st = (fg_st *)1;
    int rc = fg_st_parse(&st, c, n);
    if (rc != FG_EFORMAT || st != NULL)
      FG_TEST_FAIL("truncated to %zu of %zu bytes: rc %d (%s)", n, len, rc, fg_error_detail());
    free(c);
    write_file(path, b, n);
    rc = fg_st_open(&st, path);
    if (rc != FG_EFORMAT || st != NULL || !strstr(fg_error_detail(), "trunc.safetensors"))
      FG_TEST_FAIL("file truncated to %zu of %zu bytes: rc %d (%s)", n, len, rc,
                   fg_error_detail());
  }
  write_file(path, b, len);
  ASSERT_OK(fg_st_open(&st, path));
  fg_st_close(st);
  unlink(path);
  free(path);
  free(b);
}

/* Removes the temp folder at exit, also when an ASSERT fails (it calls exit). */
static void remove_tmpdir(void) { fg_rmtree(tmpdir); }

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "/tmp/fg_test_st_XXXXXX");
  ASSERT(mkdtemp(tmpdir) != NULL);
  atexit(remove_tmpdir);
  test_valid_file();
  test_padding_and_memory();
  test_many_tensors();
  test_long_conversion();
  test_malformed();
  test_open_errors();
  test_truncation();
  printf("safetensors: all tests passed\n");
  return 0;
}
