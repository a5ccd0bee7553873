/* Checkpoints: save -> load gives the same field to the bit (parameters, occupancy bits and
 * everything derived from them, configuration, trained_steps) for a field with features and
 * one without; saving again gives the same bytes; float16 tables give a smaller file and
 * parameters equal to the float16 rounding of the tables; every kind of corruption is refused
 * with FG_EFORMAT and a detail naming it; a missing file is FG_ENOENT. Prints the size of a
 * default-sized checkpoint (D = 512 and D = 0). */
#include "field/checkpoint.h"

#include <stdint.h>
#include <sys/stat.h>
#include <zlib.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "field/occupancy.h"
#include "test.h"

/* Offsets of the header fields the corruption cases touch (the layout in checkpoint.c). */
enum {
  OFF_VERSION = 8,
  OFF_OCC_RESOLUTION = 96,
  OFF_GROUPS = 120,
  GROUP_ENTRY = 16,
  HEADER_SIZE = 256,
};

static const double WS_MIN[3] = {0.10, -0.45, 0.005}, WS_MAX[3] = {0.80, 0.45, 0.35};

static char tmp_root[256];

static char *tmp_path(const char *name) {
  char *p = fg_path_join(tmp_root, name);
  if (!p) FG_TEST_FAIL("out of memory");
  return p;
}

static long long file_size(const char *path) {
  struct stat st;
  ASSERT_EQ(stat(path, &st), 0);
  return (long long)st.st_size;
}

static void put_u32(uint8_t *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static uint64_t get_u64(const uint8_t *p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; i--) v = v << 8 | p[i];
  return v;
}

static void put_u64(uint8_t *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* Rewrites the trailing CRC so that only the deliberate change is wrong. */
static void fix_crc(uint8_t *buf, size_t len) {
  put_u32(buf + len - 4, (uint32_t)crc32_z(crc32_z(0L, Z_NULL, 0), buf, len - 4));
}

/* A small field: 2^12-entry tables and a 16^3 occupancy grid, with a non-trivial grid,
 * background and step count. */
static fg_field *small_field(int feature_dim, int learn_background, uint64_t seed) {
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, WS_MIN, WS_MAX, 2.0, feature_dim));
  cfg.grid.log2_table_size = 12;
  cfg.feat_grid.log2_table_size = 12;
  cfg.occ_resolution = 16;
  cfg.learn_background = learn_background;
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, seed));
  size_t n;
  float *bg = fg_field_group(f, FG_FIELD_BACKGROUND, &n);
  for (size_t i = 0; i < n; i++) bg[i] = 0.01f * (float)i - 0.2f;
  const int N = fg_occgrid_resolution(f->occ);
  float *dens = fg_occgrid_density(f->occ);
  for (int32_t c = 0; c < N * N * N; c++) {
    const int x = c % N, y = (c / N) % N, z = c / (N * N);
    /* a blob plus scattered cells, densities with digits that float16 rounds */
    const int in = (x - 8) * (x - 8) + (y - 7) * (y - 7) + (z - 9) * (z - 9) < 20 || c % 37 == 0;
    dens[c] = in ? 3.0f + 0.123457f * (float)(c % 101) : 0.001f * (float)(c % 7);
  }
  fg_occgrid_update_bits(f->occ, fg_occgrid_density_threshold(cfg.dt), 1);
  ASSERT(fg_occgrid_n_occupied(f->occ) > 0);
  ASSERT(fg_occgrid_n_occupied(f->occ) < N * N * N);
  f->trained_steps = 123457;
  return f;
}

static void assert_same_config(const fg_field_config *a, const fg_field_config *b) {
  /* fg_field_config has no padding (4 doubles, 13 ints and a float: 88 bytes) */
  ASSERT_EQ(sizeof *a, 88);
  ASSERT(memcmp(a, b, sizeof *a) == 0);
}

static void assert_same_bits(const fg_field *a, const fg_field *b) {
  const int N = fg_occgrid_resolution(a->occ);
  ASSERT_EQ(fg_occgrid_resolution(b->occ), N);
  const size_t n_words = (size_t)N * N * N / 64;
  ASSERT(memcmp(fg_occgrid_bits(a->occ), fg_occgrid_bits(b->occ), n_words * 8) == 0);
  ASSERT_EQ(fg_occgrid_n_occupied(a->occ), fg_occgrid_n_occupied(b->occ));
  const float ta = fg_occgrid_threshold(a->occ), tb = fg_occgrid_threshold(b->occ);
  const float ma = fg_occgrid_mean_density(a->occ), mb = fg_occgrid_mean_density(b->occ);
  ASSERT(memcmp(&ta, &tb, sizeof ta) == 0);
  ASSERT(memcmp(&ma, &mb, sizeof ma) == 0);
  /* densities: float16 rounding of the saved ones */
  const float *da = fg_occgrid_density(a->occ), *db = fg_occgrid_density(b->occ);
  for (size_t c = 0; c < n_words * 64; c++)
    ASSERT_EQ(fg_float_to_half(da[c]), fg_float_to_half(db[c]));
  for (size_t c = 0; c < n_words * 64; c++)
    ASSERT(db[c] == fg_half_to_float(fg_float_to_half(da[c])));
}

/* The rank table and coarse levels are rebuilt: occupied-cell draws and the DDA marcher give
 * the same results on both grids. */
static void assert_same_derived(const fg_field *a, const fg_field *b) {
  enum { M = 512, R = 64, CAP = R * 1024 };
  int32_t ca[M], cb[M], na, nb;
  static float xa[3 * M], xb[3 * M];
  ASSERT_OK(fg_occgrid_update_points(a->occ, 1000, 7, 256, M, ca, xa, M, &na, 1));
  ASSERT_OK(fg_occgrid_update_points(b->occ, 1000, 7, 256, M, cb, xb, M, &nb, 1));
  ASSERT_EQ(na, nb);
  ASSERT(memcmp(ca, cb, sizeof ca) == 0);
  static float o[3 * R], d[3 * R];
  for (int r = 0; r < R; r++) {
    o[3 * r + 0] = -0.2f;
    o[3 * r + 1] = 0.1f + 0.8f * (float)r / R;
    o[3 * r + 2] = 0.3f + 0.005f * (float)r;
    const float dx = 1.0f, dy = 0.05f * (float)(r % 5) - 0.1f, dz = 0.02f;
    const float inv = 1.0f / sqrtf(dx * dx + dy * dy + dz * dz);
    d[3 * r + 0] = dx * inv;
    d[3 * r + 1] = dy * inv;
    d[3 * r + 2] = dz * inv;
  }
  static int32_t off_a[R], cnt_a[R], off_b[R], cnt_b[R];
  static float pa[3 * CAP], pb[3 * CAP], dta[CAP], dtb[CAP], tta[CAP], ttb[CAP];
  int32_t sa, sb;
  const float dt = a->cfg.dt;
  ASSERT_OK(fg_occgrid_march(a->occ, R, o, d, dt, 1024, 3, 5, CAP, off_a, cnt_a, pa, dta, tta,
                             &sa, 1));
  ASSERT_OK(fg_occgrid_march(b->occ, R, o, d, dt, 1024, 3, 5, CAP, off_b, cnt_b, pb, dtb, ttb,
                             &sb, 1));
  ASSERT_EQ(sa, sb);
  ASSERT(sa > 0);
  ASSERT(memcmp(cnt_a, cnt_b, sizeof cnt_a) == 0);
  ASSERT(memcmp(pa, pb, 3 * (size_t)sa * sizeof(float)) == 0);
  ASSERT(memcmp(tta, ttb, (size_t)sa * sizeof(float)) == 0);
}

static void assert_files_equal(const char *p1, const char *p2) {
  char *a, *b;
  size_t la, lb;
  ASSERT_OK(fg_read_file(p1, (size_t)1 << 30, &a, &la));
  ASSERT_OK(fg_read_file(p2, (size_t)1 << 30, &b, &lb));
  ASSERT_EQ(la, lb);
  ASSERT(memcmp(a, b, la) == 0);
  free(a);
  free(b);
}

/* save -> load: bit-identical; save the loaded field again: byte-identical file. */
static void test_roundtrip(int feature_dim, int learn_background) {
  fg_field *f = small_field(feature_dim, learn_background, 42);
  char *p1 = tmp_path("a.fgc"), *p2 = tmp_path("b.fgc");
  ASSERT_OK(fg_checkpoint_save(f, p1, 0));
  fg_field *g;
  ASSERT_OK(fg_checkpoint_load(p1, &g));
  assert_same_config(&f->cfg, &g->cfg);
  ASSERT_EQ(g->n_params, f->n_params);
  for (int k = 0; k < FG_FIELD_N_GROUPS; k++) {
    ASSERT_EQ(g->group_len[k], f->group_len[k]);
    ASSERT_EQ(g->group_offset[k], f->group_offset[k]);
  }
  ASSERT(memcmp(f->params, g->params, f->n_params * sizeof(float)) == 0); /* padding too */
  ASSERT_EQ(g->trained_steps, f->trained_steps);
  assert_same_bits(f, g);
  assert_same_derived(f, g);
  ASSERT_OK(fg_checkpoint_save(g, p2, 0));
  assert_files_equal(p1, p2);
  ASSERT_OK(fg_checkpoint_save(f, p2, 0)); /* over an existing file, same bytes */
  assert_files_equal(p1, p2);
  /* the sizes: header, packed groups, bits, float16 densities, CRC */
  size_t want = HEADER_SIZE + 4;
  for (int k = 0; k < FG_FIELD_N_GROUPS; k++) want += 4 * f->group_len[k];
  const size_t n_cells = 16 * 16 * 16;
  want += n_cells / 8 + n_cells * 2;
  ASSERT_EQ(file_size(p1), want);
  fg_field_free(g);
  fg_field_free(f);
  free(p1);
  free(p2);
}

/* A field loaded back has the configuration that its workspace gives (what an update checks
 * before it goes on from the field), and each difference is named. */
static void test_config_same(void) {
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, WS_MIN, WS_MAX, 2.0, 8));
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, 3));
  char *p = tmp_path("same.fgc");
  ASSERT_OK(fg_checkpoint_save(f, p, 1));
  fg_field *g;
  ASSERT_OK(fg_checkpoint_load(p, &g));
  char why[256] = "x";
  ASSERT_EQ(fg_field_config_same(&g->cfg, &cfg, why, sizeof why), 1);
  ASSERT_STREQ(why, "");
  struct {
    fg_field_config c;
    const char *says;
  } differ[6];
  for (int i = 0; i < 6; i++) differ[i].c = cfg;
  differ[0].c.box_min[2] += 2e-6;
  differ[0].says = "box";
  differ[1].c.box_size *= 1.5;
  differ[1].says = "box";
  differ[2].c.feature_dim = 512;
  differ[2].says = "512";
  differ[3].c.feat_grid.finest_resolution = 256;
  differ[3].says = "hash grids";
  differ[4].c.learn_background = 1;
  differ[4].says = "background";
  differ[5].c.occ_resolution = 64;
  differ[5].says = "occupancy";
  for (int i = 0; i < 6; i++) {
    ASSERT_EQ(fg_field_config_same(&g->cfg, &differ[i].c, why, sizeof why), 0);
    if (!strstr(why, differ[i].says)) FG_TEST_FAIL("difference %d: \"%s\"", i, why);
  }
  /* within a micrometre is the same box; without features the feature grid does not count */
  fg_field_config near = cfg;
  near.box_min[0] += 5e-7;
  ASSERT_EQ(fg_field_config_same(&cfg, &near, NULL, 0), 1);
  fg_field_config a = cfg, b = cfg;
  a.feature_dim = b.feature_dim = 0;
  b.feat_grid.n_levels = 3;
  ASSERT_EQ(fg_field_config_same(&a, &b, NULL, 0), 1);
  fg_field_free(g);
  fg_field_free(f);
  free(p);
}

/* A copy to update: the parameters and configuration, a fully occupied grid, no steps. */
static void test_copy_for_update(void) {
  fg_field *f = small_field(8, 1, 42);
  fg_field *g;
  ASSERT_OK(fg_field_copy_for_update(f, &g));
  assert_same_config(&f->cfg, &g->cfg);
  ASSERT_EQ(g->n_params, f->n_params);
  ASSERT(memcmp(f->params, g->params, f->n_params * sizeof(float)) == 0);
  ASSERT_EQ(g->trained_steps, 0);
  const int N = fg_occgrid_resolution(g->occ);
  ASSERT_EQ(fg_occgrid_n_occupied(g->occ), (int64_t)N * N * N);
  ASSERT(fg_occgrid_n_occupied(f->occ) < (int64_t)N * N * N); /* the source's is untouched */
  fg_field_free(g);
  fg_field_free(f);
}

/* half_tables = 1: smaller, tables rounded to float16, everything else exact. */
static void test_half_tables(void) {
  fg_field *f = small_field(8, 1, 7);
  char *p32 = tmp_path("f32.fgc"), *p16 = tmp_path("f16.fgc");
  ASSERT_OK(fg_checkpoint_save(f, p32, 0));
  ASSERT_OK(fg_checkpoint_save(f, p16, 1));
  const size_t tables = f->group_len[FG_FIELD_GRID] + f->group_len[FG_FIELD_FEAT_GRID];
  ASSERT_EQ(file_size(p32) - file_size(p16), 2 * tables);
  fg_field *g;
  ASSERT_OK(fg_checkpoint_load(p16, &g));
  assert_same_config(&f->cfg, &g->cfg);
  for (int k = 0; k < FG_FIELD_N_GROUPS; k++) {
    size_t n;
    const float *a = fg_field_group_const(f, k, &n), *b = fg_field_group_const(g, k, NULL);
    ASSERT_EQ(g->group_len[k], n);
    if (k == FG_FIELD_GRID || k == FG_FIELD_FEAT_GRID) {
      int differs = 0;
      for (size_t i = 0; i < n; i++) {
        const float r = fg_half_to_float(fg_float_to_half(a[i]));
        ASSERT(memcmp(&b[i], &r, sizeof r) == 0);
        differs |= b[i] != a[i];
      }
      ASSERT(differs); /* the rounding did happen */
    } else {
      ASSERT(memcmp(a, b, n * sizeof(float)) == 0);
    }
  }
  ASSERT_EQ(g->trained_steps, f->trained_steps);
  assert_same_bits(f, g);
  /* a half-table file is deterministic too */
  char *p16b = tmp_path("f16b.fgc");
  ASSERT_OK(fg_checkpoint_save(g, p16b, 1));
  assert_files_equal(p16, p16b);
  fg_field_free(g);
  fg_field_free(f);
  free(p32);
  free(p16);
  free(p16b);
}

/* Writes len bytes of buf to name, loads it and expects FG_EFORMAT with substr. */
static void expect_refused(const char *name, const uint8_t *buf, size_t len, const char *substr) {
  char *p = tmp_path(name);
  ASSERT_OK(fg_write_file_atomic(p, buf, len));
  fg_field *g = (fg_field *)1;
  ASSERT_ERR(fg_checkpoint_load(p, &g), FG_EFORMAT, substr);
  ASSERT(g == NULL);
  printf("  %-14s %s\n", name, fg_error_detail());
  free(p);
}

static void test_corruption(void) {
  fg_field *f = small_field(8, 1, 3);
  char *path = tmp_path("good.fgc");
  ASSERT_OK(fg_checkpoint_save(f, path, 0));
  char *orig;
  size_t len;
  ASSERT_OK(fg_read_file(path, (size_t)1 << 30, &orig, &len));
  uint8_t *buf = malloc(len + 16);
  ASSERT(buf != NULL);
#define RESET() memcpy(buf, orig, len)

  RESET();
  expect_refused("short-header", buf, 100, "truncated");
  RESET();
  expect_refused("short-body", buf, len - 1000, "truncated");
  RESET();
  memset(buf + len, 0, 16);
  expect_refused("stray-bytes", buf, len + 16, "stray bytes");
  RESET();
  buf[len / 2] ^= 0x40;
  expect_refused("flipped-byte", buf, len, "CRC mismatch");
  RESET();
  buf[0] = 'X';
  expect_refused("bad-magic", buf, len, "not a fieldgrip checkpoint");
  RESET();
  put_u32(buf + OFF_VERSION, 99);
  fix_crc(buf, len);
  expect_refused("version-99", buf, len, "version 99");
  ASSERT_STRCONTAINS(fg_error_detail(), "reads version 1");
  RESET();
  put_u32(buf + OFF_OCC_RESOLUTION, 17);
  fix_crc(buf, len);
  expect_refused("bad-config", buf, len, "invalid configuration");
  RESET();
  put_u32(buf + HEADER_SIZE + 4 * 5, 0x7fc00000u); /* float 5 of the density grid: NaN */
  fix_crc(buf, len);
  expect_refused("nan-param", buf, len, "non-finite");
  RESET();
  put_u32(buf + HEADER_SIZE + 4 * 5, 0x7f800000u); /* +inf */
  fix_crc(buf, len);
  expect_refused("inf-param", buf, len, "non-finite");
  /* a small group and a table group one float longer (the table one is refused before the
   * field is allocated), then the occupancy section */
  uint8_t *count = buf + OFF_GROUPS + GROUP_ENTRY * FG_FIELD_DENSITY;
  RESET();
  put_u64(count, get_u64(count) + 1);
  fix_crc(buf, len);
  expect_refused("group-size", buf, len, "size mismatch");
  ASSERT_STRCONTAINS(fg_error_detail(), "density MLP");
  count = buf + OFF_GROUPS + GROUP_ENTRY * FG_FIELD_FEAT_GRID;
  RESET();
  put_u64(count, get_u64(count) - 1);
  fix_crc(buf, len);
  expect_refused("table-size", buf, len, "size mismatch");
  ASSERT_STRCONTAINS(fg_error_detail(), "feature grid");
  RESET();
  put_u32(buf + OFF_GROUPS + GROUP_ENTRY * FG_FIELD_GRID + 8, 2); /* float16, flag unset */
  fix_crc(buf, len);
  expect_refused("dtype", buf, len, "dtype");
  /* the original still loads */
  RESET();
  fg_field *g;
  ASSERT_OK(fg_checkpoint_load(path, &g));
  fg_field_free(g);
#undef RESET

  char *missing = tmp_path("no-such.fgc");
  g = (fg_field *)1;
  ASSERT_ERR(fg_checkpoint_load(missing, &g), FG_ENOENT, "no-such.fgc");
  ASSERT(g == NULL);
  ASSERT_ERR(fg_checkpoint_load(tmp_root, &g), FG_EIO, "not a regular file");

  /* a field with a NaN is not saved, and the previous file stays */
  fg_field_group(f, FG_FIELD_COLOUR, NULL)[3] = NAN;
  ASSERT_ERR(fg_checkpoint_save(f, path, 0), FG_EINVAL, "not finite");
  ASSERT_OK(fg_checkpoint_load(path, &g));
  fg_field_free(g);

  free(missing);
  free(buf);
  free(orig);
  free(path);
  fg_field_free(f);
}

/* The size of a default-sized checkpoint (tabletop workspace, field_scale 2). */
static long long default_size(int feature_dim, int half_tables) {
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, WS_MIN, WS_MAX, 2.0, feature_dim));
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, 1));
  char *p = tmp_path("default.fgc");
  ASSERT_OK(fg_checkpoint_save(f, p, half_tables));
  const long long size = file_size(p);
  if (feature_dim == 512 && half_tables == 0) { /* the largest: check it loads */
    fg_field *g;
    ASSERT_OK(fg_checkpoint_load(p, &g));
    ASSERT(memcmp(f->params, g->params, f->n_params * sizeof(float)) == 0);
    fg_field_free(g);
  }
  printf("default checkpoint, D = %3d, %s tables: %lld bytes (%.1f MB; %zu parameters)\n",
         feature_dim, half_tables ? "float16" : "float32", size, (double)size / 1e6,
         f->n_params);
  ASSERT_EQ(remove(p), 0);
  free(p);
  fg_field_free(f);
  return size;
}

int main(void) {
  snprintf(tmp_root, sizeof tmp_root, "/tmp/fg_test_checkpoint.XXXXXX");
  ASSERT(mkdtemp(tmp_root) != NULL);
  test_roundtrip(8, 1);
  test_roundtrip(0, 0);
  test_roundtrip(0, 1);
  test_half_tables();
  test_corruption();
  test_config_same();
  test_copy_for_update();
  const long long d512 = default_size(512, 0);
  default_size(512, 1);
  default_size(0, 0);
  default_size(0, 1);
  ASSERT(d512 <= 60000000);
  ASSERT_OK(fg_rmtree(tmp_root));
  printf("checkpoint: all passed\n");
  return 0;
}
