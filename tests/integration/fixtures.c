/* Test data made by hand for the integration tests: PNGs written with zlib alone, .npy files,
 * poses and frame meta JSON. Nothing of the project's own code is involved, so a bug in its
 * decoders cannot hide behind a matching bug in the encoder. Declared in harness.h. */
#include <zlib.h>

#include "harness.h"



static void put_be32(uint8_t *p, uint32_t v) {
  p[0] = (uint8_t)(v >> 24);
  p[1] = (uint8_t)(v >> 16);
  p[2] = (uint8_t)(v >> 8);
  p[3] = (uint8_t)v;
}

static void png_chunk(it_buf *b, const char *type, const uint8_t *data, size_t n) {
  uint8_t hdr[8];
  put_be32(hdr, (uint32_t)n);
  memcpy(hdr + 4, type, 4);
  it_buf_add(b, hdr, 8);
  if (n) it_buf_add(b, data, n);
  uLong crc = crc32(0L, (const Bytef *)type, 4);
  if (n) crc = crc32(crc, data, (uInt)n);
  uint8_t c[4];
  put_be32(c, (uint32_t)crc);
  it_buf_add(b, c, 4);
}

static uint32_t xorshift(uint32_t *s) {
  uint32_t x = *s;
  x ^= x << 13;
  x ^= x >> 17;
  x ^= x << 5;
  return *s = x;
}

void h_png(int w, int h, int channels, int bits, unsigned seed, int noise, uint8_t **out,
           size_t *out_len) {
  ASSERT(channels == 1 || channels == 3 || channels == 4);
  ASSERT(bits == 8 || bits == 16);
  size_t bps = (size_t)bits / 8;
  size_t row = 1 + (size_t)w * (size_t)channels * bps;
  size_t raw_n = row * (size_t)h;
  uint8_t *raw = malloc(raw_n);
  if (!raw) FG_TEST_FAIL("out of memory");
  uint32_t rng = seed * 2654435761u + 1u;
  for (int y = 0; y < h; y++) {
    uint8_t *p = raw + row * (size_t)y;
    *p++ = 0; /* filter: none */
    for (int x = 0; x < w; x++) {
      for (int c = 0; c < channels; c++) {
        unsigned v;
        if (noise)
          v = xorshift(&rng);
        else if (c == 3)
          v = (unsigned)(x < w / 2 ? 255 : 128) * 257u; /* half opaque, half translucent */
        else
          v = ((unsigned)(x * 5 + y * 3 + c * 40) + seed * 17u) % 256u * 257u;
        if (bits == 8) {
          *p++ = (uint8_t)(noise ? v : v >> 8);
        } else {
          *p++ = (uint8_t)(v >> 8);
          *p++ = (uint8_t)v;
        }
      }
    }
  }
  uLongf zn = compressBound((uLong)raw_n);
  uint8_t *z = malloc(zn);
  if (!z) FG_TEST_FAIL("out of memory");
  if (compress2(z, &zn, raw, (uLong)raw_n, noise ? 0 : 6) != Z_OK) FG_TEST_FAIL("compress2 failed");
  free(raw);

  it_buf b = {0};
  static const uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  it_buf_add(&b, sig, 8);
  uint8_t ihdr[13];
  put_be32(ihdr, (uint32_t)w);
  put_be32(ihdr + 4, (uint32_t)h);
  ihdr[8] = (uint8_t)bits;
  ihdr[9] = channels == 1 ? 0 : channels == 3 ? 2 : 6;
  ihdr[10] = ihdr[11] = ihdr[12] = 0;
  png_chunk(&b, "IHDR", ihdr, 13);
  png_chunk(&b, "IDAT", z, zn);
  png_chunk(&b, "IEND", NULL, 0);
  free(z);
  *out = (uint8_t *)b.p;
  *out_len = b.n;
}

/* float -> IEEE binary16 for the small exact values h_npy writes (normal range only). */
static uint16_t to_half(float f) {
  uint32_t u;
  memcpy(&u, &f, 4);
  uint16_t sign = (uint16_t)((u >> 16) & 0x8000u);
  if ((u & 0x7fffffffu) == 0) return sign;
  int e = (int)((u >> 23) & 0xff) - 127 + 15;
  uint32_t mant = u & 0x7fffffu;
  if (e <= 0 || e >= 31) FG_TEST_FAIL("to_half: %g out of the normal half range", (double)f);
  uint32_t m = mant >> 13;
  if ((mant & 0x1fffu) > 0x1000u || ((mant & 0x1fffu) == 0x1000u && (m & 1u))) m++;
  return (uint16_t)(sign | (uint16_t)(((uint32_t)e << 10) + m));
}

void h_npy(const char *descr, const int *shape, int ndim, unsigned seed, uint8_t **out,
           size_t *out_len) {
  char sh[128] = "";
  size_t count = 1;
  for (int i = 0; i < ndim; i++) {
    char part[32];
    snprintf(part, sizeof part, ndim == 1 ? "%d," : (i ? ", %d" : "%d"), shape[i]);
    strncat(sh, part, sizeof sh - strlen(sh) - 1);
    count *= (size_t)shape[i];
  }
  char dict[256];
  int dn = snprintf(dict, sizeof dict, "{'descr': '%s', 'fortran_order': False, 'shape': (%s), }",
                    descr, sh);
  size_t total = 10 + (size_t)dn + 1;
  size_t pad = (64 - total % 64) % 64;
  size_t hlen = (size_t)dn + pad + 1;
  size_t esize = strcmp(descr, "<f2") == 0 ? 2 : strcmp(descr, "<f8") == 0 ? 8 : 4;
  size_t n = 10 + hlen + count * esize;
  uint8_t *p = malloc(n);
  if (!p) FG_TEST_FAIL("out of memory");
  memcpy(p, "\x93NUMPY\x01\x00", 8);
  p[8] = (uint8_t)(hlen & 0xff);
  p[9] = (uint8_t)(hlen >> 8);
  memcpy(p + 10, dict, (size_t)dn);
  memset(p + 10 + dn, ' ', pad);
  p[10 + hlen - 1] = '\n';
  uint8_t *d = p + 10 + hlen;
  for (size_t i = 0; i < count; i++) {
    float v = (float)((i * 7 + seed) % 97) / 97.0f - 0.5f;
    if (esize == 2) {
      uint16_t hv = to_half(v);
      d[2 * i] = (uint8_t)hv;
      d[2 * i + 1] = (uint8_t)(hv >> 8);
    } else if (esize == 8) {
      double dv = v;
      memcpy(d + 8 * i, &dv, 8);
    } else {
      memcpy(d + 4 * i, &v, 4);
    }
  }
  *out = p;
  *out_len = n;
}

void h_pose(double T[16], double rx, double ry, double rz, double tx, double ty, double tz) {
  double th = sqrt(rx * rx + ry * ry + rz * rz);
  double R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  if (th > 0) {
    double kx = rx / th, ky = ry / th, kz = rz / th, c = cos(th), s = sin(th), v = 1 - c;
    R[0] = kx * kx * v + c;
    R[1] = kx * ky * v - kz * s;
    R[2] = kx * kz * v + ky * s;
    R[3] = ky * kx * v + kz * s;
    R[4] = ky * ky * v + c;
    R[5] = ky * kz * v - kx * s;
    R[6] = kz * kx * v - ky * s;
    R[7] = kz * ky * v + kx * s;
    R[8] = kz * kz * v + c;
  }
  double t[3] = {tx, ty, tz};
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) T[4 * r + c] = R[3 * r + c];
    T[4 * r + 3] = t[r];
  }
  T[12] = T[13] = T[14] = 0;
  T[15] = 1;
}

char *h_matrix_json(const double T[16]) {
  return h_fmt("[[%.17g,%.17g,%.17g,%.17g],[%.17g,%.17g,%.17g,%.17g],"
               "[%.17g,%.17g,%.17g,%.17g],[%.17g,%.17g,%.17g,%.17g]]",
               T[0], T[1], T[2], T[3], T[4], T[5], T[6], T[7], T[8], T[9], T[10], T[11], T[12],
               T[13], T[14], T[15]);
}

char *h_meta(const double T[16], const char *convention, double fl, double cx, double cy, int w,
             int h) {
  char *m = h_matrix_json(T);
  char *s = h_fmt("{\"transform_matrix\": %s, \"convention\": \"%s\", \"camera\": {\"fl_x\": %.17g, "
                  "\"fl_y\": %.17g, \"cx\": %.17g, \"cy\": %.17g, \"w\": %d, \"h\": %d, "
                  "\"camera_model\": \"PINHOLE\"}}",
                  m, convention, fl, fl, cx, cy, w, h);
  free(m);
  return s;
}
