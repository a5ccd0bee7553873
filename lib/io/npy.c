/* NumPy .npy reader and writer.
 *
 * Format (numpy.lib.format): "\x93NUMPY", major and minor version bytes, the header length
 * (uint16 LE for 1.0, uint32 LE for 2.0 and 3.0), then an ASCII (3.0: UTF-8) Python dict
 * literal such as {'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), } padded with
 * spaces and a final newline, then the raw data.
 *
 * The dict is parsed by a small recursive-descent reader that accepts exactly what numpy and
 * the common writers (cnpy, npyz, hand-written tools) produce: single- or double-quoted keys,
 * the three keys each once and nothing else (as numpy itself insists), a shape tuple of
 * non-negative integers with an optional trailing comma. Whitespace after the closing brace
 * is tolerated, including a missing final newline: numpy's own reader does not insist on it
 * either, and refusing it would only reject files whose data is perfectly well defined. */
#include "io/npy.h"
#include "core/error.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NPY_MAGIC "\x93NUMPY"
#define NPY_MAGIC_LEN 6

size_t fg_dtype_size(fg_dtype t) {
  switch (t) {
  case FG_DTYPE_F32: return 4;
  case FG_DTYPE_F16: return 2;
  default: return 0;
  }
}

/* ---- header dict parser ------------------------------------------------------------- */

typedef struct cursor {
  const char *p, *end;
} cursor;

static void skip_ws(cursor *c) {
  while (c->p < c->end && (*c->p == ' ' || *c->p == '\t' || *c->p == '\n' || *c->p == '\r'))
    c->p++;
}

static int expect_char(cursor *c, char ch, const char *what) {
  skip_ws(c);
  if (c->p >= c->end || *c->p != ch)
    return fg_fail(FG_EFORMAT, "the .npy header is not a valid Python dict: expected '%c' %s", ch,
                   what);
  c->p++;
  return 0;
}

/* Reads a quoted string (no escapes: keys and dtype strings never need them) into buf. */
static int parse_string(cursor *c, char *buf, size_t cap) {
  skip_ws(c);
  if (c->p >= c->end || (*c->p != '\'' && *c->p != '"'))
    return fg_fail(FG_EFORMAT, "the .npy header is not a valid Python dict: expected a quoted "
                               "string");
  char q = *c->p++;
  size_t n = 0;
  while (c->p < c->end && *c->p != q) {
    if (*c->p == '\\' || n + 1 >= cap)
      return fg_fail(FG_EFORMAT, "the .npy header has an unexpected string (too long or escaped)");
    buf[n++] = *c->p++;
  }
  if (c->p >= c->end) return fg_fail(FG_EFORMAT, "the .npy header has an unterminated string");
  c->p++;
  buf[n] = '\0';
  return 0;
}

static int parse_bool(cursor *c, int *out) {
  skip_ws(c);
  size_t left = (size_t)(c->end - c->p);
  if (left >= 4 && memcmp(c->p, "True", 4) == 0) {
    c->p += 4;
    *out = 1;
    return 0;
  }
  if (left >= 5 && memcmp(c->p, "False", 5) == 0) {
    c->p += 5;
    *out = 0;
    return 0;
  }
  return fg_fail(FG_EFORMAT, "the .npy header's fortran_order must be True or False");
}

/* Parses "(d0, d1, ...)" into shape; refuses negative dimensions and values that overflow. */
static int parse_shape(cursor *c, size_t *shape, int *ndim) {
  FG_TRY(expect_char(c, '(', "to open the shape tuple"));
  int n = 0;
  for (;;) {
    skip_ws(c);
    if (c->p < c->end && *c->p == ')') break;
    if (c->p < c->end && *c->p == '-')
      return fg_fail(FG_EFORMAT, "the .npy shape has a negative dimension");
    if (c->p >= c->end || *c->p < '0' || *c->p > '9')
      return fg_fail(FG_EFORMAT, "the .npy shape must be a tuple of non-negative integers");
    size_t v = 0;
    while (c->p < c->end && *c->p >= '0' && *c->p <= '9') {
      size_t d = (size_t)(*c->p - '0');
      if (v > (SIZE_MAX - d) / 10)
        return fg_fail(FG_EFORMAT, "the .npy shape has a dimension too large to address");
      v = v * 10 + d;
      c->p++;
    }
    if (c->p < c->end && *c->p == 'L') c->p++; /* Python 2 long literal */
    if (n >= FG_NPY_MAX_DIMS)
      return fg_fail(FG_EFORMAT, "the .npy array has more than %d dimensions", FG_NPY_MAX_DIMS);
    shape[n++] = v;
    skip_ws(c);
    if (c->p < c->end && *c->p == ',') {
      c->p++;
      continue;
    }
    skip_ws(c);
    if (c->p < c->end && *c->p == ')') break;
    return fg_fail(FG_EFORMAT, "the .npy shape tuple is malformed");
  }
  c->p++; /* ')' */
  *ndim = n;
  return 0;
}

static int parse_descr(const char *d, fg_dtype *out) {
  if (strcmp(d, "<f4") == 0) *out = FG_DTYPE_F32;
  else if (strcmp(d, "<f2") == 0) *out = FG_DTYPE_F16;
  else if (strcmp(d, ">f4") == 0 || strcmp(d, ">f2") == 0)
    return fg_fail(FG_EFORMAT,
                   "the .npy data is big-endian ('%s'); save it little-endian, e.g. "
                   "arr.astype('<f4')",
                   d);
  else
    return fg_fail(FG_EFORMAT,
                   "the .npy data type '%s' is not supported; save float32 or float16, e.g. "
                   "arr.astype(numpy.float32)",
                   d);
  return 0;
}

/* Parses the header dict text [p, end) into out's dtype and shape. */
static int parse_header(const char *p, const char *end, fg_npy *out) {
  cursor c = {p, end};
  int have_descr = 0, have_order = 0, have_shape = 0;
  FG_TRY(expect_char(&c, '{', "at the start of the header"));
  for (;;) {
    skip_ws(&c);
    if (c.p < c.end && *c.p == '}') break;
    char key[32];
    FG_TRY(parse_string(&c, key, sizeof key));
    FG_TRY(expect_char(&c, ':', "after a key"));
    if (strcmp(key, "descr") == 0 && !have_descr) {
      char descr[32];
      skip_ws(&c);
      if (c.p < c.end && (*c.p == '[' || *c.p == '{'))
        return fg_fail(FG_EFORMAT, "structured .npy arrays are not supported; save a plain "
                                   "float32 or float16 array");
      FG_TRY(parse_string(&c, descr, sizeof descr));
      FG_TRY(parse_descr(descr, &out->dtype));
      have_descr = 1;
    } else if (strcmp(key, "fortran_order") == 0 && !have_order) {
      int fortran = 0;
      FG_TRY(parse_bool(&c, &fortran));
      if (fortran)
        return fg_fail(FG_EFORMAT, "the .npy array is in Fortran order; save it in C order, e.g. "
                                   "numpy.ascontiguousarray(arr)");
      have_order = 1;
    } else if (strcmp(key, "shape") == 0 && !have_shape) {
      FG_TRY(parse_shape(&c, out->shape, &out->ndim));
      have_shape = 1;
    } else {
      return fg_fail(FG_EFORMAT, "the .npy header has an unexpected or repeated key '%s'", key);
    }
    skip_ws(&c);
    if (c.p < c.end && *c.p == ',') {
      c.p++;
      continue;
    }
    skip_ws(&c);
    if (c.p < c.end && *c.p == '}') break;
    return fg_fail(FG_EFORMAT, "the .npy header is not a valid Python dict: expected ',' or '}'");
  }
  c.p++; /* '}' */
  skip_ws(&c);
  if (c.p != c.end) return fg_fail(FG_EFORMAT, "the .npy header has text after its dict");
  if (!have_descr || !have_order || !have_shape)
    return fg_fail(FG_EFORMAT, "the .npy header lacks the key '%s'",
                   !have_descr ? "descr" : !have_order ? "fortran_order" : "shape");
  return 0;
}

int fg_npy_parse(const void *buf, size_t len, fg_npy *out) {
  memset(out, 0, sizeof *out);
  const uint8_t *b = buf;
  if (!b || len < 10 || memcmp(b, NPY_MAGIC, NPY_MAGIC_LEN) != 0)
    return fg_fail(FG_EFORMAT, "not a .npy file (it must start with \"\\x93NUMPY\"); save "
                               "features with numpy.save");
  int major = b[6];
  size_t hlen, hstart;
  if (major == 1) {
    hlen = (size_t)b[8] | (size_t)b[9] << 8;
    hstart = 10;
  } else if (major == 2 || major == 3) {
    if (len < 12) return fg_fail(FG_EFORMAT, "the .npy file is truncated inside its header");
    hlen = (size_t)b[8] | (size_t)b[9] << 8 | (size_t)b[10] << 16 | (size_t)b[11] << 24;
    hstart = 12;
  } else {
    return fg_fail(FG_EFORMAT, "unsupported .npy format version %d.%d (1.0, 2.0 and 3.0 are)",
                   major, b[7]);
  }
  if (hlen > len - hstart)
    return fg_fail(FG_EFORMAT, "the .npy header claims %zu bytes but the file has only %zu", hlen,
                   len - hstart);
  const char *h = (const char *)b + hstart;
  FG_TRY(parse_header(h, h + hlen, out));

  size_t count = 1;
  for (int i = 0; i < out->ndim; i++) {
    if (out->shape[i] != 0 && count > SIZE_MAX / out->shape[i])
      return fg_fail(FG_EFORMAT, "the .npy shape is too large to address");
    count *= out->shape[i];
  }
  size_t esize = fg_dtype_size(out->dtype);
  if (count > SIZE_MAX / esize)
    return fg_fail(FG_EFORMAT, "the .npy shape is too large to address");
  size_t need = count * esize, have = len - hstart - hlen;
  if (have != need)
    return fg_fail(FG_EFORMAT, "the .npy data section is %zu bytes but its shape needs %zu (%s)",
                   have, need, have < need ? "truncated" : "trailing bytes");
  out->count = count;
  out->data = b + hstart + hlen;
  return 0;
}

int fg_npy_encode(fg_dtype dtype, int ndim, const size_t *shape, const void *data, uint8_t **out,
                  size_t *out_len) {
  *out = NULL;
  *out_len = 0;
  size_t esize = fg_dtype_size(dtype);
  if (esize == 0) return fg_fail(FG_EINVAL, "npy encode: dtype must be float32 or float16");
  if (ndim < 0 || ndim > FG_NPY_MAX_DIMS)
    return fg_fail(FG_EINVAL, "npy encode: %d dimensions (0..%d allowed)", ndim, FG_NPY_MAX_DIMS);
  char hdr[512];
  int n = snprintf(hdr, sizeof hdr, "{'descr': '%s', 'fortran_order': False, 'shape': (",
                   dtype == FG_DTYPE_F32 ? "<f4" : "<f2");
  size_t count = 1;
  for (int i = 0; i < ndim; i++) {
    if (shape[i] != 0 && count > SIZE_MAX / esize / shape[i])
      return fg_fail(FG_ERANGE, "npy encode: the shape is too large");
    count *= shape[i];
    n += snprintf(hdr + n, sizeof hdr - (size_t)n, i == 0 ? "%zu" : ", %zu", shape[i]);
  }
  n += snprintf(hdr + n, sizeof hdr - (size_t)n, "%s), }", ndim == 1 ? "," : "");
  if (count > 0 && !data) return fg_fail(FG_EINVAL, "npy encode: no data for %zu elements", count);
  /* Pad with spaces so that the data starts 64-byte aligned, as numpy does. */
  size_t hlen = (size_t)n + 1;
  hlen = (10 + hlen + 63) / 64 * 64 - 10;
  size_t total = 10 + hlen + count * esize;
  uint8_t *buf = malloc(total);
  if (!buf) return fg_fail(FG_ENOMEM, "out of memory encoding a .npy of %zu bytes", total);
  memcpy(buf, NPY_MAGIC, NPY_MAGIC_LEN);
  buf[6] = 1;
  buf[7] = 0;
  buf[8] = (uint8_t)(hlen & 0xff);
  buf[9] = (uint8_t)(hlen >> 8);
  memcpy(buf + 10, hdr, (size_t)n);
  memset(buf + 10 + n, ' ', hlen - (size_t)n - 1);
  buf[10 + hlen - 1] = '\n';
  if (count > 0) memcpy(buf + 10 + hlen, data, count * esize);
  *out = buf;
  *out_len = total;
  return 0;
}
