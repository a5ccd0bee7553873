/* Image decode and encode through OpenImageIO (oiio_shim.cpp): format checks, compositing
 * and colour conversion in C; depth images (io/depth.h), read raw; and fg_frame_prepare,
 * which decodes. Kept apart from image.c and depth.c so that only programs that call these
 * functions link OpenImageIO; the daemon decodes in a child process (fieldgrip-decode) and
 * never does.
 *
 * Pixel convention as in image.c: row-major [h][w][3], sRGB-encoded floats in [0, 1]. */
#include "io/image.h"
#include "core/error.h"
#include "core/pose.h"
#include "io/depth.h"
#include "io/depth_priv.h"
#include "io/frame.h"
#include "io/npy.h"
#include "io/shim.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- decode ------------------------------------------------------------------------- */

/* The extension that steers OIIO to the right reader, since memory has no file name; name
 * is what fg_image_sniff (image.c, the one place that knows the magic bytes) returned. */
static const char *reader_ext(const char *name) {
  if (strcmp(name, "PNG") == 0) return "png";
  if (strcmp(name, "JPEG") == 0) return "jpg";
  if (strcmp(name, "OpenEXR") == 0) return "exr";
  return "tif";
}

/* Walks a PNG's chunk list (length, type, data, CRC) up to IEND without reading any data.
 * A PNG cut short is the commonest corrupt upload, and letting it reach OIIO costs more than
 * a clear message: OIIO 2.4's read callback longjmps over a std::string when the data runs
 * out, leaking it on every such upload, and libpng prints to stderr. CRCs and the compressed
 * data are left to libpng. */
static int png_check_chunks(const uint8_t *b, size_t len) {
  size_t off = 8; /* past the signature, which the sniffer matched on its first bytes only */
  for (int n = 0;; n++) {
    if (len < off || len - off < 12) /* len < 8: a signature cut short */
      return fg_fail(FG_EFORMAT, "the PNG data is truncated or corrupt: it ends after %zu bytes, "
                                 "before its IEND chunk",
                     len);
    size_t clen = (size_t)b[off] << 24 | (size_t)b[off + 1] << 16 | (size_t)b[off + 2] << 8 |
                  (size_t)b[off + 3];
    if (clen > 0x7fffffffu || clen > len - off - 12)
      return fg_fail(FG_EFORMAT, "the PNG data is truncated or corrupt: chunk %d at byte %zu "
                                 "declares %zu bytes but only %zu remain",
                     n, off, clen, len - off - 12);
    if (memcmp(b + off + 4, "IEND", 4) == 0) return 0;
    off += 12 + clen;
  }
}

/* Walks an OpenEXR file's header(s), attribute by attribute (name, type, 32-bit size,
 * value), without reading any value. OpenEXR allocates and clears each attribute's declared
 * size before it reads the value, so a 500-byte file that declares a 1.9 GB string costs
 * 1.9 GB of memory and seconds of CPU in the decoder before it fails; a declared size past
 * the end of the data is refused here instead. Multi-part files (version flag 0x1000) hold
 * one header after another, ended by an empty one. */
static int exr_check_header(const uint8_t *b, size_t len) {
  if (len < 8)
    return fg_fail(FG_EFORMAT, "the OpenEXR data is truncated: %zu bytes, less than its "
                               "8-byte signature and version", len);
  const int multipart = (b[5] & 0x10) != 0; /* version flags, bits 8-31: 0x1000 multi-part */
  size_t off = 8;
  for (int part = 0;; part++) {
    if (multipart && part > 0 && off < len && b[off] == 0) return 0; /* the empty header */
    for (int n = 0;; n++) {
      if (off >= len)
        return fg_fail(FG_EFORMAT, "the OpenEXR data is truncated: it ends after %zu bytes, "
                                   "inside its header", len);
      if (b[off] == 0) { /* the header's end */
        off++;
        break;
      }
      const uint8_t *name = b + off;
      const uint8_t *nul = memchr(name, 0, len - off);
      const uint8_t *type_nul = nul ? memchr(nul + 1, 0, len - (size_t)(nul + 1 - b)) : NULL;
      if (!type_nul || len - (size_t)(type_nul + 1 - b) < 4)
        return fg_fail(FG_EFORMAT, "the OpenEXR data is truncated: header attribute %d at byte "
                                   "%zu ends before its size", n, off);
      off = (size_t)(type_nul + 1 - b);
      const uint32_t size = (uint32_t)b[off] | (uint32_t)b[off + 1] << 8 |
                            (uint32_t)b[off + 2] << 16 | (uint32_t)b[off + 3] << 24;
      off += 4;
      if (size > 0x7fffffffu || size > len - off)
        return fg_fail(FG_EFORMAT, "the OpenEXR data is truncated or corrupt: header attribute "
                                   "'%.*s' declares %u bytes but only %zu remain",
                       (int)(nul - name < 64 ? nul - name : 64), (const char *)name, size,
                       len - off);
      off += size;
    }
    if (!multipart) return 0;
  }
}

/* Clamps to [0, 1] and maps NaN to 0. Written with comparisons rather than fminf/fmaxf, which
 * gcc leaves as libm calls on x86-64 and which dominated the compositing pass. */
static inline float clamp01(float v) { return !(v > 0.0f) ? 0.0f : v > 1.0f ? 1.0f : v; }

static float srgb_encode(float v) {
  v = clamp01(v);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * powf(v, 1.0f / 2.4f) - 0.055f;
}

static float srgb_decode(float v) {
  return v <= 0.04045f ? v / 12.92f : powf((v + 0.055f) / 1.055f, 2.4f);
}

/* Converts n decoded samples to float: integers to [0, 1] (by division, so that full scale
 * is exactly 1 and every 16-bit value survives a round trip), floats as they are. */
static void samples_to_float(const void *src, int type, size_t n, float *dst) {
  if (type == FG_SHIM_U8) {
    const uint8_t *s = src;
    for (size_t i = 0; i < n; i++) dst[i] = (float)s[i] / 255.0f;
  } else if (type == FG_SHIM_U16) {
    const uint16_t *s = src;
    for (size_t i = 0; i < n; i++) dst[i] = (float)s[i] / 65535.0f;
  } else {
    memcpy(dst, src, n * sizeof(float));
  }
}

/* Turns one row of w decoded pixels, in[w][nch] floats, into out[w][3] sRGB-encoded RGB:
 * grey is expanded, alpha composited over bg, linear light encoded and clamped.
 *
 * Compositing of linear data happens in linear light, with the background converted there
 * too, which is what a physically blended pixel would be; sRGB data is composited in its
 * encoding, as browsers and viewers do. bg is already in the data's space. */
static void row_to_rgb(const float *in, size_t w, int nch, int alpha, int associated, int linear,
                       const float bg[3], float *out) {
  if (nch == 3) {
    for (size_t i = 0; i < w * 3; i++) out[i] = linear ? srgb_encode(in[i]) : clamp01(in[i]);
  } else if (nch == 1) {
    for (size_t i = 0; i < w; i++) {
      float g = linear ? srgb_encode(in[i]) : clamp01(in[i]);
      out[3 * i] = out[3 * i + 1] = out[3 * i + 2] = g;
    }
  } else if (nch == 2 && alpha == 1) {
    for (size_t i = 0; i < w; i++) {
      float a = clamp01(in[2 * i + 1]);
      float g = associated ? in[2 * i] : in[2 * i] * a;
      for (int k = 0; k < 3; k++) {
        float v = g + bg[k] * (1.0f - a);
        out[3 * i + (size_t)k] = linear ? srgb_encode(v) : clamp01(v);
      }
    }
  } else { /* nch == 4, alpha == 3 */
    for (size_t i = 0; i < w; i++) {
      const float *s = in + 4 * i;
      float a = clamp01(s[3]), na = 1.0f - a;
      float ca = associated ? 1.0f : a;
      float *d = out + 3 * i;
      for (int k = 0; k < 3; k++) {
        float v = s[k] * ca + bg[k] * na;
        d[k] = linear ? srgb_encode(v) : clamp01(v);
      }
    }
  }
}

int fg_image_decode(const void *bytes, size_t len, const float background_rgb[3], fg_image *out) {
  if (!out) return fg_fail(FG_EINVAL, "fg_image_decode: no output image");
  memset(out, 0, sizeof *out);
  if (!bytes || len == 0)
    return fg_fail(FG_EFORMAT, "the image is empty; send PNG, JPEG, OpenEXR or TIFF data");
  const uint8_t *b = bytes;
  const char *name = fg_image_sniff(b, len);
  if (!name) {
    unsigned c[4] = {0, 0, 0, 0};
    for (size_t i = 0; i < 4 && i < len; i++) c[i] = b[i];
    return fg_fail(FG_EFORMAT,
                   "unrecognised image format (data starts with %02x %02x %02x %02x); supported "
                   "formats are PNG, JPEG, OpenEXR and TIFF",
                   c[0], c[1], c[2], c[3]);
  }
  const char *ext = reader_ext(name);
  if (strcmp(ext, "png") == 0) FG_TRY(png_check_chunks(b, len));
  if (strcmp(ext, "exr") == 0) FG_TRY(exr_check_header(b, len));
  static const float white[3] = {1, 1, 1};
  if (!background_rgb) background_rgb = white;
  fg_shim_decoded d;
  FG_TRY(fg_oiio_decode(bytes, len, ext, name, FG_IMAGE_MAX_SIDE,
                        (size_t)FG_IMAGE_MAX_PIXELS, &d));
  float bg[3];
  for (int k = 0; k < 3; k++)
    bg[k] = d.linear ? srgb_decode(clamp01(background_rgb[k])) : clamp01(background_rgb[k]);

  size_t w = (size_t)d.w, h = (size_t)d.h, nch = (size_t)d.nch;
  size_t ssize = d.type == FG_SHIM_U8 ? 1 : d.type == FG_SHIM_U16 ? 2 : 4;
  float *rgb = malloc(w * h * 3 * sizeof(float));
  /* Plain 8- or 16-bit sRGB colour converts straight into the output, its values in [0, 1] by
   * construction; anything else goes through one row of floats, which stays in cache, so the
   * image is still walked once. Float samples that are not linear light (signed integers,
   * which OpenImageIO hands over as floats in [-1, 1]) are clamped there. */
  int direct = nch == 3 && !d.linear && d.type != FG_SHIM_F32;
  float *row = direct ? NULL : malloc(w * nch * sizeof(float));
  if (!rgb || (!direct && !row)) {
    free(rgb);
    free(row);
    free(d.px);
    return fg_fail(FG_ENOMEM, "out of memory decoding a %dx%d image", d.w, d.h);
  }
  if (direct) {
    samples_to_float(d.px, d.type, w * h * 3, rgb);
  } else {
    for (size_t y = 0; y < h; y++) {
      samples_to_float((const uint8_t *)d.px + y * w * nch * ssize, d.type, w * nch, row);
      row_to_rgb(row, w, d.nch, d.alpha, d.associated, d.linear, bg, rgb + y * w * 3);
    }
  }
  free(row);
  free(d.px);
  out->w = d.w;
  out->h = d.h;
  out->rgb = rgb;
  return 0;
}

/* ---- depth -------------------------------------------------------------------------- */

/* How refusals of a depth encoding end: what to send instead. */
#define DEPTH_FORMATS                                                                      \
  "one channel of 16-bit unsigned integers (PNG or TIFF; metres = value * scale, scale "  \
  "0.001 for millimetres) or of floats in metres (OpenEXR or TIFF), or a float32 .npy of "  \
  "metres"

/* A bad scale is the caller's mistake whatever the bytes hold, so every encoding refuses it,
 * including those that ignore it. */
static int depth_check_scale(double scale) {
  if (!isfinite(scale) || scale <= 0)
    return fg_fail(FG_EINVAL, "the depth scale is %g; it must be a finite number > 0: the metres "
                              "per unit of integer depth (%g for millimetres)",
                   scale, FG_DEPTH_DEFAULT_SCALE);
  return 0;
}

/* Refuses, from the header alone, files whose samples are not depth as io/depth.h takes it:
 * one channel of 16-bit unsigned integers or of floats. name is the format ("PNG"). */
static int depth_check_info(const fg_shim_info *in, const char *name) {
  if (in->nch != 1)
    return fg_fail(FG_EINVAL, "the depth %s has %d channels, so it looks like a colour image; "
                              "send depth as " DEPTH_FORMATS,
                   name, in->nch);
  if (in->sample == FG_SHIM_SAMPLE_FLOAT) return 0;
  if (in->sample == FG_SHIM_SAMPLE_UINT && in->bits == 16) return 0;
  if (in->sample == FG_SHIM_SAMPLE_UINT && in->bits <= 8)
    return fg_fail(FG_EINVAL, "the depth %s is %d-bit, too coarse for depth; send 16-bit "
                              "millimetres as RGB-D cameras save them (scale 0.001), or floats "
                              "in metres (OpenEXR, float TIFF or a float32 .npy)",
                   name, in->bits);
  return fg_fail(FG_EINVAL, "the depth %s holds %d-bit %s integers; send " DEPTH_FORMATS, name,
                 in->bits, in->sample == FG_SHIM_SAMPLE_INT ? "signed" : "unsigned");
}

/* m = v * scale for n samples: float [n] metres from uint16 [n]; 0 stays 0 (invalid). */
static void depth_from_u16(const uint16_t *v, size_t n, double scale, float *m) {
  for (size_t i = 0; i < n; i++) m[i] = (float)((double)v[i] * scale);
}

int fg_depth_decode(const void *bytes, size_t len, double scale, fg_depth_map *out) {
  if (!out) return fg_fail(FG_EINVAL, "fg_depth_decode: no output depth map");
  memset(out, 0, sizeof *out);
  FG_TRY(depth_check_scale(scale));
  if (!bytes || len == 0)
    return fg_fail(FG_EFORMAT, "the depth image is empty; send " DEPTH_FORMATS);
  const uint8_t *b = bytes;
  const char *name = fg_image_sniff(b, len);
  if (!name) {
    unsigned c[4] = {0, 0, 0, 0};
    for (size_t i = 0; i < 4 && i < len; i++) c[i] = b[i];
    return fg_fail(FG_EFORMAT,
                   "unrecognised depth format (data starts with %02x %02x %02x %02x); send "
                   DEPTH_FORMATS,
                   c[0], c[1], c[2], c[3]);
  }
  if (strcmp(name, "JPEG") == 0)
    return fg_fail(FG_EINVAL, "the depth image is a JPEG, whose lossy 8-bit compression does not "
                              "keep depth; send " DEPTH_FORMATS);
  const char *ext = reader_ext(name);
  if (strcmp(ext, "png") == 0) FG_TRY(png_check_chunks(b, len));
  if (strcmp(ext, "exr") == 0) FG_TRY(exr_check_header(b, len));
  /* The header first, so that a colour image sent as depth is refused before its pixels are
   * decoded, and so that integer samples other than 16-bit never reach OIIO's conversion to
   * float, which would normalise them. */
  fg_shim_info info;
  FG_TRY(fg_oiio_probe(bytes, len, ext, name, &info));
  FG_TRY(depth_check_info(&info, name));
  FG_TRY(fg_depth_check_size("the depth image", (size_t)info.w, (size_t)info.h));
  int u16 = info.sample == FG_SHIM_SAMPLE_UINT;
  if (u16) {
    /* Every value lands in (0, FLT_MAX] when 1 and 65535 do: rounding is monotonic. */
    float lo = (float)scale, hi = (float)(65535.0 * scale);
    if (!(lo > 0) || !(hi <= FLT_MAX))
      return fg_fail(FG_EINVAL, "the depth scale %g is out of range for 16-bit depth; it is the "
                                "metres per unit (%g for millimetres)",
                     scale, FG_DEPTH_DEFAULT_SCALE);
  }
  fg_shim_decoded d;
  FG_TRY(fg_oiio_decode(bytes, len, ext, name, FG_IMAGE_MAX_SIDE, (size_t)FG_IMAGE_MAX_PIXELS,
                        &d));
  if (d.nch != 1 || d.w != info.w || d.h != info.h ||
      d.type != (u16 ? FG_SHIM_U16 : FG_SHIM_F32)) {
    free(d.px);
    return fg_fail(FG_EFORMAT, "the %s data is corrupt: its pixels do not match its header",
                   name);
  }
  size_t n = (size_t)d.w * (size_t)d.h;
  float *m = d.px; /* float pixels are [h][w] metres already */
  if (u16) {
    m = malloc(n * sizeof(float));
    if (!m) {
      free(d.px);
      return fg_fail(FG_ENOMEM, "out of memory decoding a %dx%d depth image", d.w, d.h);
    }
    depth_from_u16(d.px, n, scale, m);
    free(d.px);
  } else {
    int rc = fg_depth_clean_metres(m, d.w, d.h);
    if (rc != 0) {
      free(m);
      return rc;
    }
  }
  out->w = d.w;
  out->h = d.h;
  out->m = m;
  return 0;
}

int fg_depth_read(const void *bytes, size_t len, double scale, fg_depth_map *out) {
  if (!out) return fg_fail(FG_EINVAL, "fg_depth_read: no output depth map");
  memset(out, 0, sizeof *out);
  if (!bytes || len < 6 || memcmp(bytes, "\x93NUMPY", 6) != 0)
    return fg_depth_decode(bytes, len, scale, out);
  FG_TRY(depth_check_scale(scale));
  fg_npy npy;
  FG_TRY(fg_npy_parse(bytes, len, &npy));
  return fg_depth_from_npy(&npy, out);
}

/* ---- encode ------------------------------------------------------------------------- */


int fg_image_encode_png(const void *pixels, int w, int h, int channels, int bits, uint8_t **out,
                        size_t *out_len) {
  if (!out || !out_len) return fg_fail(FG_EINVAL, "fg_image_encode_png: no output buffer");
  *out = NULL;
  *out_len = 0;
  if (!pixels) return fg_fail(FG_EINVAL, "fg_image_encode_png: no pixels");
  FG_TRY(fg_image_check_size("PNG encode", w, h));
  if (channels != 1 && channels != 3 && channels != 4)
    return fg_fail(FG_EINVAL, "PNG encode: channels must be 1, 3 or 4, got %d", channels);
  if (bits != 8 && bits != 16)
    return fg_fail(FG_EINVAL, "PNG encode: bits must be 8 or 16, got %d", bits);
  return fg_oiio_encode_png(pixels, w, h, channels, bits, out, out_len);
}

int fg_image_write_file(const char *path, const float *pixels, int w, int h, int channels) {
  if (!path || !pixels) return fg_fail(FG_EINVAL, "fg_image_write_file: no path or pixels");
  FG_TRY(fg_image_check_size("image write", w, h));
  if (channels < 1 || channels > 4)
    return fg_fail(FG_EINVAL, "image write: channels must be 1..4, got %d", channels);
  return fg_oiio_write_file(path, pixels, w, h, channels);
}

/* ---- frames from encoded images ----------------------------------------------------- */

/* Declared in frame.h; here because it decodes (see the comment at the top). */
int fg_frame_prepare(fg_frame *out, const void *image, size_t image_len, const fg_camera *cam,
                     const double T_world_cam[16], const fg_npy *features,
                     const fg_ingest_opts *opts) {
  if (!out) return fg_fail(FG_EINVAL, "fg_frame_prepare: no output frame");
  memset(out, 0, sizeof *out);
  if (!image) return fg_fail(FG_EINVAL, "fg_frame_prepare: no image given");
  if (!opts) return fg_fail(FG_EINVAL, "frame ingest: options are required");
  fg_image img;
  FG_TRY(fg_image_decode(image, image_len, opts->background_rgb, &img));
  int rc = fg_frame_prepare_image(out, &img, cam, T_world_cam, features, opts);
  fg_image_release(&img);
  return rc;
}
