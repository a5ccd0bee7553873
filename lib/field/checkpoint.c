/* Checkpoints: a field on disk (see checkpoint.h).
 *
 * File layout, version 1. Every number is little-endian and written field by field, so the
 * layout depends neither on the compiler's struct packing nor on the host's byte order; the
 * struct ckpt_header below only documents it and gives every field its offset.
 *
 *   offset  bytes  field
 *        0      8  magic "FGCKPT\0\0"
 *        8      4  u32 version (FG_CHECKPOINT_VERSION)
 *       12      4  u32 header_size (256)
 *       16     24  f64 box_min[3], metres, world frame
 *       40      8  f64 box_size, metres
 *       48     20  i32 grid: n_levels, n_features, log2_table_size, base_resolution,
 *                  finest_resolution
 *       68     20  i32 feat_grid, the same five fields
 *       88      4  i32 feature_dim
 *       92      4  i32 learn_background
 *       96      4  i32 occ_resolution (N)
 *      100      4  f32 dt, cube units
 *      104      8  i64 trained_steps
 *      112      4  u32 flags: bit 0 = hash tables in float16; other bits zero
 *      116      4  u32 n_groups (FG_FIELD_N_GROUPS = 7)
 *      120    112  7 x { u64 count (floats in the group), u32 dtype (1 float32, 2 float16),
 *                  u32 zero }, in the order of enum fg_field_param_group
 *      232      8  u64 occ_cells (N^3)
 *      240      4  f32 occupancy threshold of the last bit rebuild
 *      244      4  f32 occupancy mean density of the last bit rebuild
 *      248      8  zero
 *      256         parameter groups, in order, each `count` values of its dtype, packed (the
 *                  in-memory padding between groups is not stored). FG_FIELD_GRID and
 *                  FG_FIELD_FEAT_GRID are float16 when flags bit 0 is set, everything else is
 *                  always float32.
 *         +        occupancy bits: occ_cells / 64 u64 words (occ_cells / 8 bytes); cell c is
 *                  bit c % 64 of word c / 64
 *         +        occupancy densities: occ_cells float16 in cell order, saturated to
 *                  +-65504 so that a huge density stays finite
 *     end-4     4  u32 zlib crc32 of every byte before it
 *
 * Nothing in the file depends on the time or the host, so equal fields give equal files.
 *
 * The bits are stored rather than recomputed on load: densities are kept in float16, and a
 * threshold test on rounded densities could flip cells; restoring the bits (and the threshold
 * and mean) makes the loaded grid march exactly as the saved one did.
 *
 * A reader checks, in this order: the file is at least a header long, the magic, the version
 * (and header size), the configuration (fg_field_config_check and the header's own fields),
 * every section size against the configuration, the file's length against the sizes, the
 * CRC, and finally that every parameter is finite. The big sections (hash tables, occupancy)
 * are checked against the configuration before the field is allocated, so that a corrupt
 * header cannot make the loader allocate gigabytes. */
#include "field/checkpoint.h"

#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <zlib.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"

#define CKPT_MAGIC "FGCKPT\0\0"

enum {
  CKPT_HEADER_SIZE = 256,
  CKPT_F32 = 1, /* the numbering of fg_dtype (io/npy.h) */
  CKPT_F16 = 2,
  CKPT_FLAG_HALF_TABLES = 1u,
  IO_CHUNK = 1 << 20, /* bytes per read or write; a multiple of 8 */
};

struct ckpt_group {
  uint64_t count;    /* floats */
  uint32_t dtype;    /* CKPT_F32 or CKPT_F16 */
  uint32_t reserved; /* zero */
};

struct ckpt_header {
  char magic[8];            /*   0 */
  uint32_t version;         /*   8 */
  uint32_t header_size;     /*  12 */
  double box_min[3];        /*  16 */
  double box_size;          /*  40 */
  int32_t grid[5];          /*  48 */
  int32_t feat_grid[5];     /*  68 */
  int32_t feature_dim;      /*  88 */
  int32_t learn_background; /*  92 */
  int32_t occ_resolution;   /*  96 */
  float dt;                 /* 100 */
  int64_t trained_steps;    /* 104 */
  uint32_t flags;           /* 112 */
  uint32_t n_groups;        /* 116 */
  struct ckpt_group group[FG_FIELD_N_GROUPS]; /* 120 */
  uint64_t occ_cells;       /* 232 */
  float occ_threshold;      /* 240 */
  float occ_mean;           /* 244 */
  uint8_t reserved[8];      /* 248 */
};
_Static_assert(FG_FIELD_N_GROUPS == 7, "a new parameter group needs a new checkpoint version");
_Static_assert(sizeof(struct ckpt_header) == CKPT_HEADER_SIZE, "checkpoint header layout");
_Static_assert(offsetof(struct ckpt_header, trained_steps) == 104, "checkpoint header layout");
_Static_assert(offsetof(struct ckpt_header, group) == 120, "checkpoint header layout");
_Static_assert(offsetof(struct ckpt_header, occ_cells) == 232, "checkpoint header layout");
_Static_assert(sizeof(float) == 4 && sizeof(double) == 8, "IEEE 754 binary32 and binary64");

#define HOFF(field) offsetof(struct ckpt_header, field)

static const char *const group_names[FG_FIELD_N_GROUPS] = {
    "density grid", "density MLP",    "colour MLP",    "background",
    "feature grid", "feature MLP",    "feature output",
};

static int is_table_group(int g) { return g == FG_FIELD_GRID || g == FG_FIELD_FEAT_GRID; }

static uint32_t group_dtype(int g, uint32_t flags) {
  return is_table_group(g) && (flags & CKPT_FLAG_HALF_TABLES) ? CKPT_F16 : CKPT_F32;
}

static size_t dtype_size(uint32_t dtype) { return dtype == CKPT_F16 ? 2 : 4; }

/* ---- little-endian field access ------------------------------------------------------ */

static void put_u16(uint8_t *p, uint16_t v) {
  p[0] = (uint8_t)v;
  p[1] = (uint8_t)(v >> 8);
}
static void put_u32(uint8_t *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static void put_u64(uint8_t *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static void put_f32(uint8_t *p, float f) {
  uint32_t v;
  memcpy(&v, &f, sizeof v);
  put_u32(p, v);
}
static void put_f64(uint8_t *p, double d) {
  uint64_t v;
  memcpy(&v, &d, sizeof v);
  put_u64(p, v);
}
static uint16_t get_u16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }
static uint32_t get_u32(const uint8_t *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static uint64_t get_u64(const uint8_t *p) {
  return (uint64_t)get_u32(p) | (uint64_t)get_u32(p + 4) << 32;
}
static float get_f32(const uint8_t *p) {
  const uint32_t v = get_u32(p);
  float f;
  memcpy(&f, &v, sizeof f);
  return f;
}
static double get_f64(const uint8_t *p) {
  const uint64_t v = get_u64(p);
  double d;
  memcpy(&d, &v, sizeof d);
  return d;
}

/* float -> float16 bits, saturated to the largest finite half (NaN stays NaN). */
static uint16_t half_saturated(float v) {
  if (v > 65504.0f) v = 65504.0f;
  if (v < -65504.0f) v = -65504.0f;
  return fg_float_to_half(v);
}

/* ---- header -------------------------------------------------------------------------- */

static void grid_to_i32(const fg_hashgrid_config *c, int32_t v[5]) {
  v[0] = c->n_levels;
  v[1] = c->n_features;
  v[2] = c->log2_table_size;
  v[3] = c->base_resolution;
  v[4] = c->finest_resolution;
}

static void grid_from_i32(const int32_t v[5], fg_hashgrid_config *c) {
  c->n_levels = v[0];
  c->n_features = v[1];
  c->log2_table_size = v[2];
  c->base_resolution = v[3];
  c->finest_resolution = v[4];
}

static void header_encode(const struct ckpt_header *h, uint8_t b[CKPT_HEADER_SIZE]) {
  memset(b, 0, CKPT_HEADER_SIZE);
  memcpy(b + HOFF(magic), h->magic, 8);
  put_u32(b + HOFF(version), h->version);
  put_u32(b + HOFF(header_size), h->header_size);
  for (int k = 0; k < 3; k++) put_f64(b + HOFF(box_min) + 8 * (size_t)k, h->box_min[k]);
  put_f64(b + HOFF(box_size), h->box_size);
  for (int i = 0; i < 5; i++) {
    put_u32(b + HOFF(grid) + 4 * (size_t)i, (uint32_t)h->grid[i]);
    put_u32(b + HOFF(feat_grid) + 4 * (size_t)i, (uint32_t)h->feat_grid[i]);
  }
  put_u32(b + HOFF(feature_dim), (uint32_t)h->feature_dim);
  put_u32(b + HOFF(learn_background), (uint32_t)h->learn_background);
  put_u32(b + HOFF(occ_resolution), (uint32_t)h->occ_resolution);
  put_f32(b + HOFF(dt), h->dt);
  put_u64(b + HOFF(trained_steps), (uint64_t)h->trained_steps);
  put_u32(b + HOFF(flags), h->flags);
  put_u32(b + HOFF(n_groups), h->n_groups);
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++) {
    uint8_t *p = b + HOFF(group) + sizeof(struct ckpt_group) * (size_t)g;
    put_u64(p + offsetof(struct ckpt_group, count), h->group[g].count);
    put_u32(p + offsetof(struct ckpt_group, dtype), h->group[g].dtype);
    put_u32(p + offsetof(struct ckpt_group, reserved), h->group[g].reserved);
  }
  put_u64(b + HOFF(occ_cells), h->occ_cells);
  put_f32(b + HOFF(occ_threshold), h->occ_threshold);
  put_f32(b + HOFF(occ_mean), h->occ_mean);
}

static void header_decode(const uint8_t b[CKPT_HEADER_SIZE], struct ckpt_header *h) {
  memset(h, 0, sizeof *h);
  memcpy(h->magic, b + HOFF(magic), 8);
  h->version = get_u32(b + HOFF(version));
  h->header_size = get_u32(b + HOFF(header_size));
  for (int k = 0; k < 3; k++) h->box_min[k] = get_f64(b + HOFF(box_min) + 8 * (size_t)k);
  h->box_size = get_f64(b + HOFF(box_size));
  for (int i = 0; i < 5; i++) {
    h->grid[i] = (int32_t)get_u32(b + HOFF(grid) + 4 * (size_t)i);
    h->feat_grid[i] = (int32_t)get_u32(b + HOFF(feat_grid) + 4 * (size_t)i);
  }
  h->feature_dim = (int32_t)get_u32(b + HOFF(feature_dim));
  h->learn_background = (int32_t)get_u32(b + HOFF(learn_background));
  h->occ_resolution = (int32_t)get_u32(b + HOFF(occ_resolution));
  h->dt = get_f32(b + HOFF(dt));
  h->trained_steps = (int64_t)get_u64(b + HOFF(trained_steps));
  h->flags = get_u32(b + HOFF(flags));
  h->n_groups = get_u32(b + HOFF(n_groups));
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++) {
    const uint8_t *p = b + HOFF(group) + sizeof(struct ckpt_group) * (size_t)g;
    h->group[g].count = get_u64(p + offsetof(struct ckpt_group, count));
    h->group[g].dtype = get_u32(p + offsetof(struct ckpt_group, dtype));
    h->group[g].reserved = get_u32(p + offsetof(struct ckpt_group, reserved));
  }
  h->occ_cells = get_u64(b + HOFF(occ_cells));
  h->occ_threshold = get_f32(b + HOFF(occ_threshold));
  h->occ_mean = get_f32(b + HOFF(occ_mean));
}

/* ---- save ---------------------------------------------------------------------------- */

/* Buffered output through the atomic file, with the running CRC. After a failed write the
 * writer keeps accepting data and drops it; the caller checks `err` once at the end. */
typedef struct ckpt_writer {
  FILE *fp;
  uLong crc;
  uint8_t *buf; /* IO_CHUNK bytes, owned by the caller */
  size_t n;     /* bytes pending in buf */
  int err;      /* errno of the first failed write, 0 while none failed */
} ckpt_writer;

static void writer_flush(ckpt_writer *w) {
  if (w->n > 0 && w->err == 0) {
    w->crc = crc32_z(w->crc, w->buf, w->n);
    if (fwrite(w->buf, 1, w->n, w->fp) != w->n) w->err = errno ? errno : EIO;
  }
  w->n = 0;
}

/* Room for `bytes` (at most IO_CHUNK) more bytes at the end of the buffer. */
static uint8_t *writer_room(ckpt_writer *w, size_t bytes) {
  if (w->n + bytes > IO_CHUNK) writer_flush(w);
  uint8_t *p = w->buf + w->n;
  w->n += bytes;
  return p;
}

/* src (n) as float32 or as saturated float16. */
static void write_floats(ckpt_writer *w, const float *src, size_t n, uint32_t dtype) {
  const size_t es = dtype_size(dtype), per = IO_CHUNK / es;
  for (size_t i = 0; i < n; i += per) {
    const size_t m = n - i < per ? n - i : per;
    uint8_t *p = writer_room(w, m * es);
    if (dtype == CKPT_F16)
      for (size_t e = 0; e < m; e++) put_u16(p + 2 * e, half_saturated(src[i + e]));
    else
      for (size_t e = 0; e < m; e++) put_f32(p + 4 * e, src[i + e]);
  }
}

static void write_words(ckpt_writer *w, const uint64_t *src, size_t n) {
  const size_t per = IO_CHUNK / 8;
  for (size_t i = 0; i < n; i += per) {
    const size_t m = n - i < per ? n - i : per;
    uint8_t *p = writer_room(w, m * 8);
    for (size_t e = 0; e < m; e++) put_u64(p + 8 * e, src[i + e]);
  }
}

/* The first non-finite parameter of f: 0 when there is none, else 1 with its group and index. */
static int find_non_finite(const fg_field *f, int *group, size_t *index) {
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++) {
    size_t n;
    const float *p = fg_field_group_const(f, g, &n);
    for (size_t i = 0; i < n; i++)
      if (!isfinite(p[i])) {
        *group = g;
        *index = i;
        return 1;
      }
  }
  return 0;
}

int fg_checkpoint_save(const fg_field *f, const char *path, int half_tables) {
  if (!f || !path) return fg_fail(FG_EINVAL, "fg_checkpoint_save: no field or path");
  if (half_tables != 0 && half_tables != 1)
    return fg_fail(FG_EINVAL, "fg_checkpoint_save: half_tables must be 0 or 1, got %d",
                   half_tables);
  if (f->trained_steps < 0)
    return fg_fail(FG_EINVAL, "cannot save checkpoint %s: trained_steps is negative (%lld)",
                   path, (long long)f->trained_steps);
  /* A file the loader would refuse is worse than none: the old checkpoint stays in place. */
  int bad_g;
  size_t bad_i;
  if (find_non_finite(f, &bad_g, &bad_i))
    return fg_fail(FG_EINVAL, "cannot save checkpoint %s: parameter %zu of the %s group is "
                              "not finite (training diverged?)",
                   path, bad_i, group_names[bad_g]);

  const fg_field_config *cfg = &f->cfg;
  const int N = fg_occgrid_resolution(f->occ);
  const size_t n_cells = (size_t)N * (size_t)N * (size_t)N;
  struct ckpt_header h;
  memset(&h, 0, sizeof h);
  memcpy(h.magic, CKPT_MAGIC, 8);
  h.version = FG_CHECKPOINT_VERSION;
  h.header_size = CKPT_HEADER_SIZE;
  memcpy(h.box_min, cfg->box_min, sizeof h.box_min);
  h.box_size = cfg->box_size;
  grid_to_i32(&cfg->grid, h.grid);
  grid_to_i32(&cfg->feat_grid, h.feat_grid);
  h.feature_dim = cfg->feature_dim;
  h.learn_background = cfg->learn_background;
  h.occ_resolution = cfg->occ_resolution;
  h.dt = cfg->dt;
  h.trained_steps = f->trained_steps;
  h.flags = half_tables ? CKPT_FLAG_HALF_TABLES : 0;
  h.n_groups = FG_FIELD_N_GROUPS;
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++) {
    h.group[g].count = f->group_len[g];
    h.group[g].dtype = group_dtype(g, h.flags);
  }
  h.occ_cells = n_cells;
  h.occ_threshold = fg_occgrid_threshold(f->occ);
  h.occ_mean = fg_occgrid_mean_density(f->occ);
  uint8_t hb[CKPT_HEADER_SIZE];
  header_encode(&h, hb);

  ckpt_writer w = {.crc = crc32_z(0L, Z_NULL, 0), .buf = malloc(IO_CHUNK)};
  if (!w.buf) return fg_fail(FG_ENOMEM, "out of memory saving checkpoint %s", path);
  fg_atomic_file af;
  int rc = fg_atomic_file_open(&af, path);
  if (rc < 0) {
    free(w.buf);
    return rc;
  }
  w.fp = af.fp;
  memcpy(writer_room(&w, sizeof hb), hb, sizeof hb);
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++) {
    size_t n;
    const float *p = fg_field_group_const(f, g, &n);
    write_floats(&w, p, n, h.group[g].dtype);
  }
  write_words(&w, fg_occgrid_bits(f->occ), n_cells / 64);
  write_floats(&w, fg_occgrid_density(f->occ), n_cells, CKPT_F16);
  writer_flush(&w);
  uint8_t cb[4];
  put_u32(cb, (uint32_t)w.crc);
  if (w.err == 0 && fwrite(cb, 1, sizeof cb, af.fp) != sizeof cb) w.err = errno ? errno : EIO;
  free(w.buf);
  if (w.err != 0) {
    fg_atomic_file_abort(&af);
    return fg_fail(fg_io_error(w.err), "writing checkpoint %s failed: %s", path, strerror(w.err));
  }
  return fg_atomic_file_commit(&af);
}

/* ---- load ---------------------------------------------------------------------------- */

/* Chunked input with the running CRC. */
typedef struct ckpt_reader {
  FILE *fp;
  const char *path;
  uLong crc;
  uint8_t *buf; /* IO_CHUNK bytes, owned by the caller */
} ckpt_reader;

/* Reads exactly n (at most IO_CHUNK) bytes into r->buf; with_crc adds them to the CRC. */
static int reader_fill(ckpt_reader *r, size_t n, int with_crc) {
  if (fread(r->buf, 1, n, r->fp) != n) {
    if (ferror(r->fp))
      return fg_fail(FG_EIO, "reading checkpoint %s failed: %s", r->path, strerror(errno));
    return fg_fail(FG_EFORMAT, "checkpoint %s is truncated (it shrank while being read)",
                   r->path);
  }
  if (with_crc) r->crc = crc32_z(r->crc, r->buf, n);
  return 0;
}

/* dst (n) from float32 or float16 values. */
static int read_floats(ckpt_reader *r, float *dst, size_t n, uint32_t dtype) {
  const size_t es = dtype_size(dtype), per = IO_CHUNK / es;
  for (size_t i = 0; i < n; i += per) {
    const size_t m = n - i < per ? n - i : per;
    FG_TRY(reader_fill(r, m * es, 1));
    if (dtype == CKPT_F16)
      for (size_t e = 0; e < m; e++) dst[i + e] = fg_half_to_float(get_u16(r->buf + 2 * e));
    else
      for (size_t e = 0; e < m; e++) dst[i + e] = get_f32(r->buf + 4 * e);
  }
  return 0;
}

static int read_words(ckpt_reader *r, uint64_t *dst, size_t n) {
  const size_t per = IO_CHUNK / 8;
  for (size_t i = 0; i < n; i += per) {
    const size_t m = n - i < per ? n - i : per;
    FG_TRY(reader_fill(r, m * 8, 1));
    for (size_t e = 0; e < m; e++) dst[i + e] = get_u64(r->buf + 8 * e);
  }
  return 0;
}

/* The configuration and the header's own fields; fills *cfg. */
static int check_config(const struct ckpt_header *h, const char *path, fg_field_config *cfg) {
  memset(cfg, 0, sizeof *cfg);
  memcpy(cfg->box_min, h->box_min, sizeof cfg->box_min);
  cfg->box_size = h->box_size;
  grid_from_i32(h->grid, &cfg->grid);
  grid_from_i32(h->feat_grid, &cfg->feat_grid);
  cfg->feature_dim = h->feature_dim;
  cfg->learn_background = h->learn_background;
  cfg->occ_resolution = h->occ_resolution;
  cfg->dt = h->dt;
  if (fg_field_config_check(cfg) < 0) {
    char why[256];
    snprintf(why, sizeof why, "%s", fg_error_detail());
    return fg_fail(FG_EFORMAT, "checkpoint %s has an invalid configuration: %s", path, why);
  }
  /* fg_field_config_check ignores the feature grid when D = 0, but fg_field_alloc still
   * multiplies its level and feature counts: keep that product in range. */
  if (cfg->feat_grid.n_levels < 0 || cfg->feat_grid.n_levels > 4096 ||
      cfg->feat_grid.n_features < 0 || cfg->feat_grid.n_features > 4096)
    return fg_fail(FG_EFORMAT, "checkpoint %s has an invalid configuration: feature grid with "
                               "%d levels of %d features",
                   path, cfg->feat_grid.n_levels, cfg->feat_grid.n_features);
  if (h->trained_steps < 0)
    return fg_fail(FG_EFORMAT, "checkpoint %s has an invalid header: trained_steps %lld", path,
                   (long long)h->trained_steps);
  if (h->flags & ~(uint32_t)CKPT_FLAG_HALF_TABLES)
    return fg_fail(FG_EFORMAT, "checkpoint %s has an invalid header: unknown flags 0x%x", path,
                   h->flags);
  return 0;
}

static int size_mismatch(const char *path, const char *what, uint64_t stored, size_t want) {
  return fg_fail(FG_EFORMAT, "checkpoint %s has a size mismatch: the %s section holds %llu "
                             "values but its configuration gives %zu",
                 path, what, (unsigned long long)stored, want);
}

/* The sections that dominate the allocation, against the configuration alone. */
static int check_big_sizes(const struct ckpt_header *h, const fg_field_config *cfg,
                           const char *path) {
  if (h->n_groups != FG_FIELD_N_GROUPS)
    return fg_fail(FG_EFORMAT, "checkpoint %s has a size mismatch: %u parameter groups, this "
                               "build has %d",
                   path, h->n_groups, FG_FIELD_N_GROUPS);
  size_t n_grid = 0, n_feat = 0;
  FG_TRY(fg_hashgrid_layout(&cfg->grid, NULL, &n_grid)); /* checked: cannot fail */
  if (cfg->feature_dim > 0) FG_TRY(fg_hashgrid_layout(&cfg->feat_grid, NULL, &n_feat));
  if (h->group[FG_FIELD_GRID].count != n_grid)
    return size_mismatch(path, group_names[FG_FIELD_GRID], h->group[FG_FIELD_GRID].count, n_grid);
  if (h->group[FG_FIELD_FEAT_GRID].count != n_feat)
    return size_mismatch(path, group_names[FG_FIELD_FEAT_GRID],
                         h->group[FG_FIELD_FEAT_GRID].count, n_feat);
  const size_t N = (size_t)cfg->occ_resolution, n_cells = N * N * N;
  if (h->occ_cells != n_cells) return size_mismatch(path, "occupancy", h->occ_cells, n_cells);
  return 0;
}

/* Every group of the allocated field against the header. */
static int check_group_sizes(const struct ckpt_header *h, const fg_field *f, const char *path) {
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++) {
    if (h->group[g].count != f->group_len[g])
      return size_mismatch(path, group_names[g], h->group[g].count, f->group_len[g]);
    const uint32_t want = group_dtype(g, h->flags);
    if (h->group[g].dtype != want)
      return fg_fail(FG_EFORMAT, "checkpoint %s: the %s group has dtype %u, expected %u "
                                 "(1 float32, 2 float16)",
                     path, group_names[g], h->group[g].dtype, want);
  }
  return 0;
}

/* The header, the sections and the CRC of an open file, into a new field. */
static int load_from(ckpt_reader *r, unsigned long long file_size, fg_field **out) {
  const char *path = r->path;
  if (file_size < CKPT_HEADER_SIZE)
    return fg_fail(FG_EFORMAT, "checkpoint %s is truncated: %llu bytes, shorter than its %d-byte "
                               "header",
                   path, file_size, CKPT_HEADER_SIZE);
  FG_TRY(reader_fill(r, CKPT_HEADER_SIZE, 1));
  struct ckpt_header h;
  header_decode(r->buf, &h);
  if (memcmp(h.magic, CKPT_MAGIC, 8) != 0)
    return fg_fail(FG_EFORMAT, "%s is not a fieldgrip checkpoint (bad magic)", path);
  if (h.version != FG_CHECKPOINT_VERSION || h.header_size != CKPT_HEADER_SIZE)
    return fg_fail(FG_EFORMAT, "checkpoint %s has version %u (header %u bytes); this build reads "
                               "version %d; retrain the scene or use a matching fieldgrip",
                   path, h.version, h.header_size, FG_CHECKPOINT_VERSION);
  fg_field_config cfg;
  FG_TRY(check_config(&h, path, &cfg));
  FG_TRY(check_big_sizes(&h, &cfg, path));

  const size_t n_cells = (size_t)h.occ_cells, n_words = n_cells / 64; /* checked above */
  fg_field *f;
  FG_TRY(fg_field_alloc(&f, &cfg));
  uint64_t *bits = NULL;
  unsigned long long want = CKPT_HEADER_SIZE;
  int bad_g;
  size_t bad_i;
  int rc = check_group_sizes(&h, f, path);
  if (rc < 0) goto error;
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++)
    want += f->group_len[g] * dtype_size(h.group[g].dtype);
  want += n_words * 8 + n_cells * 2 + 4;
  if (file_size != want) {
    rc = fg_fail(FG_EFORMAT, "checkpoint %s is %llu bytes but its header declares %llu; it is %s",
                 path, file_size, want,
                 file_size < want ? "truncated" : "followed by stray bytes");
    goto error;
  }
  bits = malloc(n_words * sizeof *bits);
  if (!bits) {
    rc = fg_fail(FG_ENOMEM, "out of memory loading checkpoint %s", path);
    goto error;
  }
  for (int g = 0; g < FG_FIELD_N_GROUPS && rc == 0; g++)
    rc = read_floats(r, fg_field_group(f, g, NULL), f->group_len[g], h.group[g].dtype);
  if (rc == 0) rc = read_words(r, bits, n_words);
  if (rc == 0) rc = read_floats(r, fg_occgrid_density(f->occ), n_cells, CKPT_F16);
  if (rc == 0) rc = reader_fill(r, 4, 0);
  if (rc < 0) goto error;
  if (get_u32(r->buf) != (uint32_t)r->crc) {
    rc = fg_fail(FG_EFORMAT, "checkpoint %s is corrupt: CRC mismatch (stored %08x, computed "
                             "%08x); delete it and retrain the scene",
                 path, get_u32(r->buf), (uint32_t)r->crc);
    goto error;
  }
  if (find_non_finite(f, &bad_g, &bad_i)) {
    rc = fg_fail(FG_EFORMAT, "checkpoint %s holds a non-finite parameter (%s group, index %zu)",
                 path, group_names[bad_g], bad_i);
    goto error;
  }
  rc = fg_occgrid_set_bits(f->occ, bits, 1);
  if (rc < 0) goto error;
  fg_occgrid_set_stats(f->occ, h.occ_threshold, h.occ_mean);
  f->trained_steps = h.trained_steps;
  free(bits);
  *out = f;
  return 0;
error:
  free(bits);
  fg_field_free(f);
  return rc;
}

int fg_checkpoint_load(const char *path, fg_field **out) {
  if (!path || !out) return fg_fail(FG_EINVAL, "fg_checkpoint_load: no path or output");
  *out = NULL;
  FILE *fp = fopen(path, "rb");
  if (!fp) {
    const int e = errno;
    return fg_fail(e == ENOENT ? FG_ENOENT : FG_EIO, "cannot open checkpoint %s: %s", path,
                   strerror(e));
  }
  struct stat st;
  if (fstat(fileno(fp), &st) != 0 || !S_ISREG(st.st_mode)) {
    fclose(fp);
    return fg_fail(FG_EIO, "checkpoint %s is not a regular file", path);
  }
  ckpt_reader r = {.fp = fp, .path = path, .crc = crc32_z(0L, Z_NULL, 0), .buf = malloc(IO_CHUNK)};
  int rc = r.buf ? load_from(&r, (unsigned long long)st.st_size, out)
                 : fg_fail(FG_ENOMEM, "out of memory loading checkpoint %s", path);
  free(r.buf);
  fclose(fp);
  return rc;
}
