// OpenImageIO behind a C interface (shim.h): header probe and decode from memory, PNG encode
// to memory, and file writing for tests and tools. Every entry point catches all exceptions;
// errors are recorded with fg_fail() in the C library's per-thread detail.
#include <OpenEXR/ImfHeader.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>

extern "C" {
#include "core/error.h"
#include "io/image.h"
}
#include "io/shim.h"

using OIIO::ImageInput;
using OIIO::ImageOutput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

namespace {

// OIIO messages can span lines and repeat the file name we made up; keep the first line.
std::string first_line(std::string s) {
  size_t nl = s.find('\n');
  if (nl != std::string::npos) s.resize(nl);
  if (s.empty()) s = "no detail from the decoder";
  return s;
}

// Linear light is what EXR holds by definition and what OIIO reports for float data; an
// 8- or 16-bit file is sRGB-encoded unless it explicitly says it is linear (a PNG with gAMA 1.0
// is reported as "linear" by OIIO's reader).
bool spec_is_linear(const ImageSpec &spec) {
  std::string cs = spec.get_string_attribute("oiio:ColorSpace");
  if (OIIO::Strutil::icontains(cs, "linear") || OIIO::Strutil::istarts_with(cs, "lin_") ||
      OIIO::Strutil::iequals(cs, "scene_linear"))
    return true;
  TypeDesc::BASETYPE b = TypeDesc::BASETYPE(spec.format.basetype);
  return b == TypeDesc::FLOAT || b == TypeDesc::HALF || b == TypeDesc::DOUBLE;
}

// OpenEXR sizes its line and tile buffers from the header when a file is opened, before OIIO
// reports the size to be checked: a few hundred bytes declaring a data window 9 million pixels
// wide cost ten seconds of page faults under AddressSanitizer. OpenEXR's own process-wide
// limit refuses such a header first; it is set once, to the largest side the library accepts.
const char *const kExrTooLarge = "exceeds the maximum";

void limit_openexr() {
  static const bool set = [] {
    Imf::Header::setMaxImageSize(FG_IMAGE_MAX_SIDE, FG_IMAGE_MAX_SIDE);
    Imf::Header::setMaxTileSize(FG_IMAGE_MAX_SIDE, FG_IMAGE_MAX_SIDE);
    return true;
  }();
  (void)set;
}

// Opens an image held in mem (which must outlive the reader) with the reader ext names.
// nullptr with *err and a detail recorded when the data cannot be opened (FG_EFORMAT, or
// FG_ERANGE for an EXR over OpenEXR's size limit) or is not a 2-D image.
std::unique_ptr<ImageInput> open_mem(OIIO::Filesystem::IOMemReader &mem, const char *ext,
                                     const char *format_name, int *err) {
  *err = FG_EFORMAT;
  limit_openexr();
  ImageSpec config;
  // Straight alpha stays straight: premultiplying 8-bit data would lose precision that the
  // compositing pass needs, and the pass handles both kinds exactly.
  config.attribute("oiio:UnassociatedAlpha", 1);
  // OIIO 2.4 readers take the proxy from the config hint; passing it to open() alone is not
  // enough for all of them.
  void *proxy = &mem;
  config.attribute("oiio:ioproxy", TypeDesc::PTR, &proxy);
  std::string name = std::string("upload.") + ext;
  std::unique_ptr<ImageInput> in = ImageInput::open(name, &config, &mem);
  if (!in) {
    std::string detail = first_line(OIIO::geterror());
    if (detail.find(kExrTooLarge) != std::string::npos)
      *err = fg_fail(FG_ERANGE, "the %s data window or tiles are larger than %d pixels per side, "
                     "the largest accepted, so downscale it first", format_name,
                     FG_IMAGE_MAX_SIDE);
    else
      fg_fail(FG_EFORMAT, "the %s data is truncated or corrupt: %s", format_name,
              detail.c_str());
    return nullptr;
  }
  const ImageSpec &spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) {
    fg_fail(FG_EFORMAT, "the %s data declares an empty image (%dx%d, %d channels)", format_name,
            spec.width, spec.height, spec.nchannels);
    return nullptr;
  }
  if (spec.depth > 1) {
    fg_fail(FG_EFORMAT, "the %s data is a volume image; send a 2-D image", format_name);
    return nullptr;
  }
  return in;
}

int probe_impl(const void *bytes, size_t len, const char *ext, const char *format_name,
               fg_shim_info *out) {
  OIIO::Filesystem::IOMemReader mem(bytes, len);
  int err;
  std::unique_ptr<ImageInput> in = open_mem(mem, ext, format_name, &err);
  if (!in) return err;
  const ImageSpec &spec = in->spec();
  TypeDesc::BASETYPE b = TypeDesc::BASETYPE(spec.format.basetype);
  out->w = spec.width;
  out->h = spec.height;
  out->nch = spec.nchannels;
  out->sample = b == TypeDesc::FLOAT || b == TypeDesc::HALF || b == TypeDesc::DOUBLE
                  ? FG_SHIM_SAMPLE_FLOAT
                : b == TypeDesc::INT8 || b == TypeDesc::INT16 || b == TypeDesc::INT32 ||
                    b == TypeDesc::INT64
                  ? FG_SHIM_SAMPLE_INT
                  : FG_SHIM_SAMPLE_UINT;
  // Readers widen 1-, 2-, 4- and 12-bit data to the next type and say so here.
  out->bits = spec.get_int_attribute("oiio:BitsPerSample", 0);
  if (out->bits <= 0) out->bits = (int)spec.format.size() * 8;
  in->close();
  return 0;
}

int decode_impl(const void *bytes, size_t len, const char *ext, const char *format_name,
                int max_side, size_t max_pixels, fg_shim_decoded *out) {
  OIIO::Filesystem::IOMemReader mem(bytes, len);
  int err;
  std::unique_ptr<ImageInput> in = open_mem(mem, ext, format_name, &err);
  if (!in) return err;
  const ImageSpec &spec = in->spec();
  if (spec.width > max_side || spec.height > max_side ||
      (size_t)spec.width * (size_t)spec.height > max_pixels)
    return fg_fail(FG_ERANGE,
                   "the image is %dx%d; the largest accepted is %d pixels per side and %zu pixels "
                   "in all, so downscale it first",
                   spec.width, spec.height, max_side, max_pixels);

  // Which channels to read: grey, grey+alpha, RGB or RGBA. Extra channels (depth, masks)
  // are not read; an alpha that is not right after the colour is ignored rather than
  // costing a second read.
  int nch, alpha = -1;
  if (spec.nchannels == 1) {
    nch = 1;
  } else if (spec.nchannels == 2) {
    nch = spec.alpha_channel == 1 ? 2 : 1;
    alpha = spec.alpha_channel == 1 ? 1 : -1;
  } else {
    nch = spec.alpha_channel == 3 ? 4 : 3;
    alpha = spec.alpha_channel == 3 ? 3 : -1;
  }
  // 8- and 16-bit data is read as it is stored and converted to float by the caller's
  // compositing pass: OIIO's own conversion to float was a third of the decode time.
  TypeDesc::BASETYPE base = TypeDesc::BASETYPE(spec.format.basetype);
  int type = base == TypeDesc::UINT8    ? FG_SHIM_U8
             : base == TypeDesc::UINT16 ? FG_SHIM_U16
                                        : FG_SHIM_F32;
  TypeDesc read_fmt = type == FG_SHIM_U8    ? TypeDesc::UINT8
                      : type == FG_SHIM_U16 ? TypeDesc::UINT16
                                            : TypeDesc::FLOAT;
  size_t npix = (size_t)spec.width * (size_t)spec.height;
  void *px = std::malloc(npix * (size_t)nch * read_fmt.size());
  if (!px)
    return fg_fail(FG_ENOMEM, "out of memory decoding a %dx%d image", spec.width, spec.height);
  bool ok = in->read_image(0, 0, 0, nch, read_fmt, px);
  if (!ok || in->has_error()) {
    std::string err = in->geterror();
    std::free(px);
    return fg_fail(FG_EFORMAT, "the %s data is truncated or corrupt: %s", format_name,
                   first_line(err).c_str());
  }
  out->px = px;
  out->type = type;
  out->w = spec.width;
  out->h = spec.height;
  out->nch = nch;
  out->alpha = alpha;
  out->associated = alpha >= 0 && !spec.get_int_attribute("oiio:UnassociatedAlpha", 0);
  out->linear = spec_is_linear(spec);
  in->close();
  return 0;
}

int encode_png_impl(const void *pixels, int w, int h, int channels, int bits, uint8_t **out,
                    size_t *out_len) {
  OIIO::Filesystem::IOVecOutput vec;
  std::unique_ptr<ImageOutput> o = ImageOutput::create("render.png", &vec);
  if (!o)
    return fg_fail(FG_EIO, "PNG encoder unavailable: %s", first_line(OIIO::geterror()).c_str());
  TypeDesc fmt = bits == 16 ? TypeDesc::UINT16 : TypeDesc::UINT8;
  ImageSpec spec(w, h, channels, fmt);
  // Pixels are written as given; without this OIIO would un-premultiply RGBA.
  spec.attribute("oiio:UnassociatedAlpha", 1);
  if (!o->open("render.png", spec) || !o->write_image(fmt, pixels) || !o->close())
    return fg_fail(FG_EIO, "PNG encoding failed: %s", first_line(o->geterror()).c_str());
  const std::vector<unsigned char> &buf = vec.buffer();
  uint8_t *p = static_cast<uint8_t *>(std::malloc(buf.size() ? buf.size() : 1));
  if (!p) return fg_fail(FG_ENOMEM, "out of memory encoding a PNG");
  std::memcpy(p, buf.data(), buf.size());
  *out = p;
  *out_len = buf.size();
  return 0;
}

int write_file_impl(const char *path, const float *pixels, int w, int h, int channels) {
  std::unique_ptr<ImageOutput> o = ImageOutput::create(path);
  if (!o)
    return fg_fail(FG_EINVAL, "cannot write %s: %s", path, first_line(OIIO::geterror()).c_str());
  // Float where the format has it (EXR, TIFF); the writers narrow it (16-bit PNG, 8-bit JPEG).
  ImageSpec spec(w, h, channels, TypeDesc::FLOAT);
  spec.attribute("oiio:UnassociatedAlpha", 1);
  if (!o->open(path, spec) || !o->write_image(TypeDesc::FLOAT, pixels) || !o->close())
    return fg_fail(FG_EIO, "writing %s failed: %s", path, first_line(o->geterror()).c_str());
  return 0;
}

}  // namespace

extern "C" int fg_oiio_decode(const void *bytes, size_t len, const char *ext,
                              const char *format_name, int max_side, size_t max_pixels,
                              fg_shim_decoded *out) {
  std::memset(out, 0, sizeof *out);
  try {
    return decode_impl(bytes, len, ext, format_name, max_side, max_pixels, out);
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "out of memory decoding a %s image", format_name);
  } catch (const std::exception &e) {
    return fg_fail(FG_EFORMAT, "the %s data is truncated or corrupt: %s", format_name, e.what());
  } catch (...) {
    return fg_fail(FG_EFORMAT, "the %s data is truncated or corrupt", format_name);
  }
}

extern "C" int fg_oiio_probe(const void *bytes, size_t len, const char *ext,
                             const char *format_name, fg_shim_info *out) {
  std::memset(out, 0, sizeof *out);
  try {
    return probe_impl(bytes, len, ext, format_name, out);
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "out of memory reading a %s header", format_name);
  } catch (const std::exception &e) {
    return fg_fail(FG_EFORMAT, "the %s data is truncated or corrupt: %s", format_name, e.what());
  } catch (...) {
    return fg_fail(FG_EFORMAT, "the %s data is truncated or corrupt", format_name);
  }
}

extern "C" int fg_oiio_encode_png(const void *pixels, int w, int h, int channels, int bits,
                                  uint8_t **out, size_t *out_len) {
  *out = nullptr;
  *out_len = 0;
  try {
    return encode_png_impl(pixels, w, h, channels, bits, out, out_len);
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "out of memory encoding a PNG");
  } catch (const std::exception &e) {
    return fg_fail(FG_EIO, "PNG encoding failed: %s", e.what());
  } catch (...) {
    return fg_fail(FG_EIO, "PNG encoding failed");
  }
}

extern "C" int fg_oiio_write_file(const char *path, const float *pixels, int w, int h,
                                  int channels) {
  try {
    return write_file_impl(path, pixels, w, h, channels);
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "out of memory writing %s", path);
  } catch (const std::exception &e) {
    return fg_fail(FG_EIO, "writing %s failed: %s", path, e.what());
  } catch (...) {
    return fg_fail(FG_EIO, "writing %s failed", path);
  }
}
