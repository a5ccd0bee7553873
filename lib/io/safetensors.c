/* safetensors reader: mmap, strict header validation, float32 conversion.
 *
 * The header is parsed with jansson (UTF-8 checked, duplicate keys refused, nesting depth
 * bounded) and then checked field by field against what the format allows; only once every
 * tensor has passed are views into the data section handed out. The tensors are checked in
 * offset order to prove that they neither overlap nor leave bytes unaccounted for, which is
 * what the format's reference reader insists on too: a file with holes is either corrupt or
 * hiding something, and refusing it costs nothing for files written by the real writers.
 *
 * Names and metadata are copied out of the JSON tree, which is freed before fg_st_parse
 * returns; the data is never copied. A file truncated by someone else while it is mapped
 * can still raise SIGBUS on a read; that is the price of not reading 600 MB of weights. */
#include "io/safetensors.h"
#include "core/error.h"
#include "core/half.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "safetensors data is little-endian; this reader converts it on little-endian hosts only"
#endif

/* One tensor as parsed: the public view plus its offsets inside the data section. */
typedef struct st_entry {
  fg_st_tensor t; /* t.name is owned (strdup), t.data points into the buffer */
  uint64_t begin, end;
} st_entry;

struct fg_st {
  char *file;          /* owned; the path, or "<memory>", for messages */
  void *map;           /* owned mapping of fg_st_open, NULL for fg_st_parse */
  size_t map_len;
  const uint8_t *bytes; /* the whole file: the mapping or fg_st_parse's buffer */
  size_t len;
  int n;               /* number of tensors */
  st_entry *entries;   /* [n] in header order, owned */
  st_entry **by_name;  /* [n] pointers into entries sorted by strcmp of the names, owned */
  int nmeta;
  char **meta;         /* [2 * nmeta] key, value, key, value ... each owned */
};

/* ---- dtypes ------------------------------------------------------------------------- */

typedef struct st_dtype_info {
  const char *name;
  fg_st_dtype dtype;
  size_t size;
} st_dtype_info;

/* Every dtype the format defines with a whole number of bytes per element. The sub-byte
 * ones (F4, F6_*) have no agreed packing for shapes with odd sizes and are left unknown. */
static const st_dtype_info st_dtypes[] = {
    {"F32", FG_ST_F32, 4},       {"F16", FG_ST_F16, 2},         {"BF16", FG_ST_BF16, 2},
    {"F64", FG_ST_F64, 8},       {"I64", FG_ST_I64, 8},         {"I32", FG_ST_I32, 4},
    {"I16", FG_ST_I16, 2},       {"I8", FG_ST_I8, 1},           {"U8", FG_ST_U8, 1},
    {"BOOL", FG_ST_BOOL, 1},     {"U16", FG_ST_OTHER, 2},       {"U32", FG_ST_OTHER, 4},
    {"U64", FG_ST_OTHER, 8},     {"F8_E4M3", FG_ST_OTHER, 1},   {"F8_E5M2", FG_ST_OTHER, 1},
    {"F8_E8M0", FG_ST_OTHER, 1},
};

const char *fg_st_dtype_name(fg_st_dtype d) {
  switch (d) {
  case FG_ST_F32: return "F32";
  case FG_ST_F16: return "F16";
  case FG_ST_BF16: return "BF16";
  case FG_ST_F64: return "F64";
  case FG_ST_I64: return "I64";
  case FG_ST_I32: return "I32";
  case FG_ST_I16: return "I16";
  case FG_ST_I8: return "I8";
  case FG_ST_U8: return "U8";
  case FG_ST_BOOL: return "BOOL";
  case FG_ST_OTHER: return "OTHER";
  }
  return "OTHER";
}

/* Looks a dtype up by its spelling in the file; NULL when unknown. */
static const st_dtype_info *dtype_lookup(const char *name) {
  for (size_t i = 0; i < sizeof st_dtypes / sizeof st_dtypes[0]; i++)
    if (strcmp(st_dtypes[i].name, name) == 0) return &st_dtypes[i];
  return NULL;
}

/* ---- messages ----------------------------------------------------------------------- */

/* Writes "[d0, d1, ...]" into buf (cap bytes, always NUL-terminated). */
static void shape_str(char *buf, size_t cap, const int64_t *shape, int ndim) {
  size_t n = 0;
  buf[0] = '\0';
  n += (size_t)snprintf(buf, cap, "[");
  for (int i = 0; i < ndim && n < cap; i++)
    n += (size_t)snprintf(buf + n, cap - n, i ? ", %" PRId64 : "%" PRId64, shape[i]);
  if (n < cap) snprintf(buf + n, cap - n, "]");
}

/* ---- header validation -------------------------------------------------------------- */

/* Reads a JSON integer that must be >= 0; 0 with *v set, or -1. */
static int json_nonneg(const json_t *j, uint64_t *v) {
  if (!json_is_integer(j)) return -1;
  json_int_t x = json_integer_value(j);
  if (x < 0) return -1;
  *v = (uint64_t)x;
  return 0;
}

/* Validates one tensor's {"dtype", "shape", "data_offsets"} object and fills e, except for
 * e->t.data, which the caller sets once all offsets are known to be in range. data_len is
 * the size of the data section. */
static int parse_tensor(const char *file, const char *name, json_t *obj, uint64_t data_len,
                        st_entry *e) {
  if (!json_is_object(obj))
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\" is not an object with dtype, shape and "
                               "data_offsets", file, name);
  const char *key;
  json_t *val;
  json_object_foreach(obj, key, val) {
    if (strcmp(key, "dtype") != 0 && strcmp(key, "shape") != 0 &&
        strcmp(key, "data_offsets") != 0)
      return fg_fail(FG_EFORMAT, "%s: tensor \"%s\" has an unexpected key \"%s\" (only dtype, "
                                 "shape and data_offsets belong there)", file, name, key);
  }

  json_t *jd = json_object_get(obj, "dtype");
  if (!jd || !json_is_string(jd))
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\" has %s dtype", file, name,
                   jd ? "a non-string" : "no");
  const st_dtype_info *di = dtype_lookup(json_string_value(jd));
  if (!di)
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\" has the unknown dtype \"%s\" (known: F32, F16, "
                               "BF16, F64, I64, I32, I16, I8, U8, BOOL, U16, U32, U64, F8_E4M3, "
                               "F8_E5M2, F8_E8M0)", file, name, json_string_value(jd));
  e->t.dtype = di->dtype;

  json_t *js = json_object_get(obj, "shape");
  if (!js || !json_is_array(js))
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\" has %s shape", file, name,
                   js ? "a non-array" : "no");
  size_t ndim = json_array_size(js);
  if (ndim > FG_ST_MAX_DIMS)
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\" has %zu dimensions; at most %d are supported",
                   file, name, ndim, FG_ST_MAX_DIMS);
  e->t.ndim = (int)ndim;
  int has_zero = 0;
  for (size_t i = 0; i < ndim; i++) {
    uint64_t d;
    if (json_nonneg(json_array_get(js, i), &d) != 0)
      return fg_fail(FG_EFORMAT, "%s: tensor \"%s\": shape dimension %zu is not a non-negative "
                                 "integer", file, name, i);
    e->t.shape[i] = (int64_t)d;
    if (d == 0) has_zero = 1;
  }
  /* product(shape) * size; a zero dimension makes the tensor empty however large the others */
  size_t count = has_zero ? 0 : 1;
  for (size_t i = 0; i < ndim && count; i++) {
    uint64_t d = (uint64_t)e->t.shape[i];
    if (d > SIZE_MAX / count) goto overflow;
    count *= (size_t)d;
  }
  if (count > SIZE_MAX / di->size) goto overflow;
  e->t.count = count;
  e->t.nbytes = count * di->size;

  json_t *jo = json_object_get(obj, "data_offsets");
  if (!jo || !json_is_array(jo) || json_array_size(jo) != 2 ||
      json_nonneg(json_array_get(jo, 0), &e->begin) != 0 ||
      json_nonneg(json_array_get(jo, 1), &e->end) != 0)
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\": data_offsets must be an array of two "
                               "non-negative integers [begin, end]", file, name);
  if (e->begin > e->end)
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\": data_offsets [%" PRIu64 ", %" PRIu64 "] "
                               "end before they begin", file, name, e->begin, e->end);
  if (e->end - e->begin != (uint64_t)e->t.nbytes) {
    char sh[160];
    shape_str(sh, sizeof sh, e->t.shape, e->t.ndim);
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\": data_offsets [%" PRIu64 ", %" PRIu64 "] hold "
                               "%" PRIu64 " bytes but shape %s of %s needs %zu", file, name,
                   e->begin, e->end, e->end - e->begin, sh, di->name, e->t.nbytes);
  }
  if (e->end > data_len)
    return fg_fail(FG_EFORMAT, "%s: tensor \"%s\": data_offsets [%" PRIu64 ", %" PRIu64 "] end "
                               "past the data section of %" PRIu64 " bytes (truncated file?)",
                   file, name, e->begin, e->end, data_len);
  return 0;

overflow:
  return fg_fail(FG_EFORMAT, "%s: tensor \"%s\": shape is too large to address", file, name);
}

/* Copies the string-valued __metadata__ object into st. */
static int parse_metadata(fg_st *st, json_t *obj) {
  if (!json_is_object(obj))
    return fg_fail(FG_EFORMAT, "%s: __metadata__ must be an object of strings", st->file);
  size_t n = json_object_size(obj);
  st->meta = calloc(n ? 2 * n : 1, sizeof *st->meta);
  if (!st->meta) return fg_fail(FG_ENOMEM, "%s: out of memory for the metadata", st->file);
  const char *key;
  size_t klen;
  json_t *val;
  json_object_keylen_foreach(obj, key, klen, val) {
    if (klen != strlen(key))
      return fg_fail(FG_EFORMAT, "%s: a __metadata__ key contains a NUL character", st->file);
    if (!json_is_string(val) || json_string_length(val) != strlen(json_string_value(val)))
      return fg_fail(FG_EFORMAT, "%s: __metadata__ \"%s\" must be a string", st->file, key);
    char *k = strdup(key), *v = strdup(json_string_value(val));
    st->meta[2 * st->nmeta] = k;
    st->meta[2 * st->nmeta + 1] = v;
    st->nmeta++; /* counted before the check so that close frees a half-made pair */
    if (!k || !v) return fg_fail(FG_ENOMEM, "%s: out of memory for the metadata", st->file);
  }
  return 0;
}

/* Orders entries by (begin, end) so that the coverage walk sees them in file order; empty
 * tensors sort before a non-empty one at the same offset. */
static int cmp_offsets(const void *a, const void *b) {
  const st_entry *x = *(const st_entry *const *)a, *y = *(const st_entry *const *)b;
  if (x->begin != y->begin) return x->begin < y->begin ? -1 : 1;
  if (x->end != y->end) return x->end < y->end ? -1 : 1;
  return 0;
}

/* Proves that the tensors tile [0, data_len) exactly: no overlap, no hole, nothing after. */
static int check_coverage(const fg_st *st, uint64_t data_len) {
  if (st->n == 0) {
    if (data_len != 0)
      return fg_fail(FG_EFORMAT, "%s: the file has no tensors but a data section of %" PRIu64
                                 " bytes", st->file, data_len);
    return 0;
  }
  const st_entry **order = malloc((size_t)st->n * sizeof *order);
  if (!order) return fg_fail(FG_ENOMEM, "%s: out of memory checking %d tensors", st->file, st->n);
  for (int i = 0; i < st->n; i++) order[i] = &st->entries[i];
  qsort(order, (size_t)st->n, sizeof *order, cmp_offsets);
  int rc = 0;
  uint64_t pos = 0;
  const st_entry *prev = NULL;
  for (int i = 0; i < st->n && rc == 0; i++) {
    const st_entry *e = order[i];
    if (e->begin < pos)
      rc = fg_fail(FG_EFORMAT, "%s: tensors \"%s\" [%" PRIu64 ", %" PRIu64 "] and \"%s\" [%" PRIu64
                               ", %" PRIu64 "] overlap", st->file, prev->t.name, prev->begin,
                   prev->end, e->t.name, e->begin, e->end);
    else if (e->begin > pos)
      rc = fg_fail(FG_EFORMAT, "%s: bytes [%" PRIu64 ", %" PRIu64 ") of the data section belong to "
                               "no tensor (a gap before tensor \"%s\"); the format requires the "
                               "tensors to cover the data section contiguously", st->file, pos,
                   e->begin, e->t.name);
    pos = e->end;
    prev = e;
  }
  if (rc == 0 && pos != data_len)
    rc = fg_fail(FG_EFORMAT, "%s: bytes [%" PRIu64 ", %" PRIu64 ") at the end of the data section "
                             "belong to no tensor; the format requires the tensors to cover the "
                             "data section contiguously", st->file, pos, data_len);
  free(order);
  return rc;
}

/* Orders tensor pointers by name. */
static int cmp_names(const void *a, const void *b) {
  const st_entry *x = *(const st_entry *const *)a, *y = *(const st_entry *const *)b;
  return strcmp(x->t.name, y->t.name);
}

/* Parses and validates buf[0, len) into st, whose file name is already set. */
static int parse_buffer(fg_st *st, const uint8_t *buf, size_t len) {
  const char *file = st->file;
  st->bytes = buf;
  st->len = len;
  if (len < 8)
    return fg_fail(FG_EFORMAT, "%s: the file is %zu bytes, shorter than the 8-byte header length "
                               "of a safetensors file", file, len);
  uint64_t hlen = 0;
  for (int i = 7; i >= 0; i--) hlen = hlen << 8 | buf[i];
  if (hlen == 0)
    return fg_fail(FG_EFORMAT, "%s: the header length is 0; not a safetensors file", file);
  if (hlen > FG_ST_MAX_HEADER)
    return fg_fail(FG_EFORMAT, "%s: the header length %" PRIu64 " is above the limit of %zu "
                               "bytes; not a safetensors file?", file, hlen, FG_ST_MAX_HEADER);
  if (hlen > len - 8)
    return fg_fail(FG_EFORMAT, "%s: the header length %" PRIu64 " runs past the end of the file "
                               "(%zu bytes after the length field); truncated file?", file, hlen,
                   len - 8);
  const char *hdr = (const char *)buf + 8;
  uint64_t data_len = len - 8 - hlen;

  json_error_t jerr;
  /* The writer pads the header with spaces; jansson accepts trailing whitespace. */
  json_t *root = json_loadb(hdr, (size_t)hlen, JSON_REJECT_DUPLICATES, &jerr);
  if (!root)
    return fg_fail(FG_EFORMAT, "%s: the header is not valid UTF-8 JSON: %s (byte %d of the "
                               "header)", file, jerr.text, jerr.position);
  int rc = 0;
  if (!json_is_object(root)) {
    rc = fg_fail(FG_EFORMAT, "%s: the header is not a JSON object", file);
    goto out;
  }
  size_t nkeys = json_object_size(root);
  st->entries = calloc(nkeys ? nkeys : 1, sizeof *st->entries);
  st->by_name = calloc(nkeys ? nkeys : 1, sizeof *st->by_name);
  if (!st->entries || !st->by_name) {
    rc = fg_fail(FG_ENOMEM, "%s: out of memory for %zu tensors", file, nkeys);
    goto out;
  }
  const char *key;
  size_t klen;
  json_t *val;
  json_object_keylen_foreach(root, key, klen, val) {
    if (strcmp(key, "__metadata__") == 0) {
      if ((rc = parse_metadata(st, val)) != 0) goto out;
      continue;
    }
    if (klen == 0) {
      rc = fg_fail(FG_EFORMAT, "%s: a tensor has an empty name", file);
      goto out;
    }
    if (klen != strlen(key)) {
      rc = fg_fail(FG_EFORMAT, "%s: a tensor name contains a NUL character", file);
      goto out;
    }
    st_entry *e = &st->entries[st->n];
    if ((rc = parse_tensor(file, key, val, data_len, e)) != 0) goto out;
    if (!(e->t.name = strdup(key))) {
      rc = fg_fail(FG_ENOMEM, "%s: out of memory for tensor names", file);
      goto out;
    }
    st->n++;
  }
  if ((rc = check_coverage(st, data_len)) != 0) goto out;

  const uint8_t *data = buf + 8 + hlen;
  for (int i = 0; i < st->n; i++) {
    st->entries[i].t.data = data + st->entries[i].begin;
    st->by_name[i] = &st->entries[i];
  }
  qsort(st->by_name, (size_t)st->n, sizeof *st->by_name, cmp_names);
out:
  json_decref(root);
  return rc;
}

/* ---- open and close ----------------------------------------------------------------- */

void fg_st_close(fg_st *st) {
  if (!st) return;
  if (st->entries)
    for (int i = 0; i < st->n; i++) free((char *)st->entries[i].t.name);
  free(st->entries);
  free(st->by_name);
  for (int i = 0; i < 2 * st->nmeta; i++) free(st->meta[i]);
  free(st->meta);
  if (st->map) munmap(st->map, st->map_len);
  free(st->file);
  free(st);
}

/* Allocates an empty handle that names file in its messages. */
static int st_new(fg_st **out, const char *file) {
  fg_st *st = calloc(1, sizeof *st);
  if (!st || !(st->file = strdup(file))) {
    free(st);
    return fg_fail(FG_ENOMEM, "out of memory opening %s", file);
  }
  *out = st;
  return 0;
}

int fg_st_parse(fg_st **out, const void *buf, size_t len) {
  if (!out) return fg_fail(FG_EINVAL, "fg_st_parse: out is NULL");
  *out = NULL;
  if (!buf && len) return fg_fail(FG_EINVAL, "fg_st_parse: buf is NULL with len %zu", len);
  fg_st *st = NULL;
  FG_TRY(st_new(&st, "<memory>"));
  int rc = parse_buffer(st, buf, len);
  if (rc != 0) {
    fg_st_close(st);
    return rc;
  }
  *out = st;
  return 0;
}

int fg_st_open(fg_st **out, const char *path) {
  if (!out || !path) return fg_fail(FG_EINVAL, "fg_st_open: out and path must be non-NULL");
  *out = NULL;
  /* O_NONBLOCK: a FIFO given by mistake must not hang the open; it is refused below */
  int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    int e = errno;
    return fg_fail(e == ENOENT || e == ENOTDIR ? FG_ENOENT : FG_EIO, "cannot open %s: %s", path,
                   strerror(e));
  }
  struct stat sb;
  if (fstat(fd, &sb) != 0) {
    int e = errno;
    close(fd);
    return fg_fail(FG_EIO, "cannot stat %s: %s", path, strerror(e));
  }
  if (!S_ISREG(sb.st_mode)) {
    close(fd);
    return fg_fail(FG_EIO, "%s is not a regular file", path);
  }
  if ((uint64_t)sb.st_size > SIZE_MAX) {
    close(fd);
    return fg_fail(FG_EIO, "%s is too large to map on this system", path);
  }
  fg_st *st = NULL;
  int rc = st_new(&st, path);
  if (rc != 0) {
    close(fd);
    return rc;
  }
  size_t len = (size_t)sb.st_size;
  if (len >= 8) { /* mmap of 0 bytes fails; short files are refused by the parser */
    void *map = mmap(NULL, len, PROT_READ, MAP_PRIVATE, fd, 0);
    if (map == MAP_FAILED) {
      int e = errno;
      close(fd);
      fg_st_close(st);
      return fg_fail(FG_EIO, "cannot map %s (%zu bytes): %s", path, len, strerror(e));
    }
    st->map = map;
    st->map_len = len;
  }
  close(fd); /* the mapping keeps the file */
  static const uint8_t empty[8];
  rc = parse_buffer(st, st->map ? st->map : empty, len);
  if (rc != 0) {
    fg_st_close(st);
    return rc;
  }
  *out = st;
  return 0;
}

/* ---- lookup ------------------------------------------------------------------------- */

int fg_st_count(const fg_st *st) { return st ? st->n : 0; }

int fg_st_tensor_at(const fg_st *st, int i, fg_st_tensor *out) {
  if (!st || !out) return fg_fail(FG_EINVAL, "fg_st_tensor_at: st and out must be non-NULL");
  if (i < 0 || i >= st->n)
    return fg_fail(FG_EINVAL, "tensor index %d out of range: %s has %d tensors", i, st->file,
                   st->n);
  *out = st->entries[i].t;
  return 0;
}

/* bsearch comparator: the key is the name itself. */
static int cmp_key_name(const void *key, const void *elem) {
  return strcmp((const char *)key, (*(const st_entry *const *)elem)->t.name);
}

int fg_st_find(const fg_st *st, const char *name, fg_st_tensor *out) {
  if (!st || !name || !out)
    return fg_fail(FG_EINVAL, "fg_st_find: st, name and out must be non-NULL");
  st_entry *const *hit = st->n ? bsearch(name, st->by_name, (size_t)st->n, sizeof *st->by_name,
                                         cmp_key_name)
                               : NULL;
  if (!hit) return fg_fail(FG_ENOENT, "no tensor \"%s\" in %s", name, st->file);
  *out = (*hit)->t;
  return 0;
}

/* A linear scan: metadata holds a handful of keys and is read once per model load. */
const char *fg_st_metadata(const fg_st *st, const char *key) {
  if (!st || !key) return NULL;
  for (int i = 0; i < st->nmeta; i++)
    if (strcmp(st->meta[2 * i], key) == 0) return st->meta[2 * i + 1];
  return NULL;
}

/* ---- conversion to float32 ---------------------------------------------------------- */

/* Elements converted per step through an aligned stack buffer: small enough for L1. */
#define ST_CHUNK 2048

/* dst[i] = bf16 src[i] for n elements; src is bytes, possibly unaligned. bf16 is the top
 * half of a binary32, so widening is a shift. */
static void bf16_to_f32(const uint8_t *src, float *dst, size_t n) {
  uint16_t tmp[ST_CHUNK];
  for (size_t off = 0; off < n; off += ST_CHUNK) {
    size_t m = n - off < ST_CHUNK ? n - off : ST_CHUNK;
    memcpy(tmp, src + 2 * off, 2 * m);
    for (size_t i = 0; i < m; i++) {
      uint32_t bits = (uint32_t)tmp[i] << 16;
      memcpy(&dst[off + i], &bits, sizeof bits);
    }
  }
}

/* dst[i] = f16 src[i] for n elements; src is bytes, possibly unaligned. */
static void f16_to_f32(const uint8_t *src, float *dst, size_t n) {
  uint16_t tmp[ST_CHUNK];
  for (size_t off = 0; off < n; off += ST_CHUNK) {
    size_t m = n - off < ST_CHUNK ? n - off : ST_CHUNK;
    memcpy(tmp, src + 2 * off, 2 * m);
    fg_half_to_float_n(tmp, dst + off, m);
  }
}

/* Converts elements [first, first + n) of t into dst; t's dtype is already known to be
 * a float one and the range to be inside the tensor. */
static void convert_range(const fg_st_tensor *t, size_t first, size_t n, float *dst) {
  const uint8_t *p = t->data;
  switch (t->dtype) {
  case FG_ST_F32:
    if (n) memcpy(dst, p + 4 * first, 4 * n);
    break;
  case FG_ST_F16: f16_to_f32(p + 2 * first, dst, n); break;
  case FG_ST_BF16: bf16_to_f32(p + 2 * first, dst, n); break;
  default: break;
  }
}

/* FG_EFORMAT unless t is F32, F16 or BF16. */
static int check_float_dtype(const fg_st_tensor *t) {
  if (t->dtype == FG_ST_F32 || t->dtype == FG_ST_F16 || t->dtype == FG_ST_BF16) return 0;
  return fg_fail(FG_EFORMAT, "tensor \"%s\" has dtype %s%s; only F32, F16 and BF16 convert to "
                             "float32", t->name ? t->name : "?", fg_st_dtype_name(t->dtype),
                 t->dtype == FG_ST_OTHER ? " (U16, U32, U64 or F8)" : "");
}

int fg_st_read_f32(const fg_st_tensor *t, float *dst, size_t count) {
  if (!t || (!dst && count))
    return fg_fail(FG_EINVAL, "fg_st_read_f32: t and dst must be non-NULL");
  FG_TRY(check_float_dtype(t));
  if (count != t->count)
    return fg_fail(FG_EINVAL, "tensor \"%s\" has %zu elements but %zu were asked for", t->name,
                   t->count, count);
  convert_range(t, 0, count, dst);
  return 0;
}

int fg_st_read_rows_f32(const fg_st_tensor *t, size_t row0, size_t nrows, float *dst) {
  if (!t || (!dst && nrows))
    return fg_fail(FG_EINVAL, "fg_st_read_rows_f32: t and dst must be non-NULL");
  FG_TRY(check_float_dtype(t));
  if (t->ndim != 2)
    return fg_fail(FG_EINVAL, "tensor \"%s\" has %d dimensions; reading rows needs 2", t->name,
                   t->ndim);
  size_t rows = (size_t)t->shape[0], cols = (size_t)t->shape[1];
  if (row0 > rows || nrows > rows - row0)
    return fg_fail(FG_EINVAL, "rows [%zu, %zu + %zu) are outside tensor \"%s\" of %zu rows", row0,
                   row0, nrows, t->name, rows);
  /* row0 * cols <= count, which parse proved addressable */
  convert_range(t, row0 * cols, nrows * cols, dst);
  return 0;
}

void fg_st_bytes(const fg_st *st, const void **base, size_t *len) {
  *base = st->bytes;
  *len = st->len;
}
