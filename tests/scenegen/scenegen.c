/* fieldgrip-scenegen: renders a procedural tabletop (scene.h) from cameras on a hemisphere
 * and writes an instant-ngp / nerfstudio data set with patch features and ground truth:
 *
 *   DIR/images/NNNN.png      8-bit RGB, sRGB-encoded
 *   DIR/masks/NNNN.png       8-bit grey, pixel = class index of the ray through its centre
 *                            (0 background, 1 table, 2 mug, 3 bowl, 4 box, 5 ball: an
 *                            object's "class" in gt.json)
 *   DIR/features/NNNN.npy    float16 [ceil(H/P), ceil(W/P), D], unit vectors
 *   DIR/depth/NNNN.png       with --depth png: 16-bit grey, z-depth of the pixel centre's ray
 *                            in millimetres (rounded), 0 where it hits nothing
 *   DIR/depth/NNNN.npy       with --depth npy: float32 [H, W], the same in metres
 *   DIR/transforms.json      training views; DIR/transforms_test.json the held-out ones
 *                            (view i when i % holdout == 0; absent when none is held out)
 *   DIR/gt.json              poses, shapes, grasps and class embeddings (layout in gt.h)
 *   DIR/cell.xml             the table and the objects as a MuJoCo MJCF model, convex parts
 *                            at the gt poses, for a simulator to grasp in (cell.h)
 *
 * The same arguments give the same bytes, whatever the number of threads. */
#include <errno.h>
#include <getopt.h>
#include <inttypes.h>
#include <jansson.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "cell.h"
#include "core/pose.h"
#include "gt.h"
#include "io/image.h"
#include "io/npy.h"
#include "scene.h"

static void usage(FILE *f) {
  fprintf(f,
          "usage: fieldgrip-scenegen --out DIR [--seed N] [--embedding-seed N] [--views N]\n"
          "                          [--width W] [--height H]\n"
          "                          [--dim D] [--patch P] [--noise S] [--holdout K]\n"
          "                          [--depth none|png|npy] [--remove NAME]\n"
          "                          [--move NAME,DX,DY]\n"
          "  --out DIR     data set folder (created; existing files are replaced)\n"
          "  --seed N      object layout, cameras' start, embeddings, noise (default 0)\n"
          "  --embedding-seed N  class embeddings from N instead of --seed, so that\n"
          "                layouts share one feature space (default: --seed)\n"
          "  --views N     cameras on the hemisphere (default 60)\n"
          "  --width W, --height H   image size in pixels (default 320x240)\n"
          "  --dim D       feature dimension, at least %d (default 64)\n"
          "  --patch P     feature cell size in pixels (default 16)\n"
          "  --noise S     expected norm of the noise on a unit class embedding; each\n"
          "                component gets std S/sqrt(D) (default 0.05)\n"
          "  --holdout K   view i goes to transforms_test.json when i %% K == 0; 0: none\n"
          "                (default 10)\n"
          "  --depth F     depth maps as an RGB-D camera gives them (z along the optical\n"
          "                axis): none, png (16-bit millimetres) or npy (float32 metres)\n"
          "                in DIR/depth (default none)\n"
          "  --remove NAME the same layout without the object NAME (mug, bowl, box, ball);\n"
          "                may be given again\n"
          "  --move NAME,DX,DY  the same layout with NAME moved DX, DY metres along the\n"
          "                table (world x and y); it must stay on the table and apart\n"
          "                from the others. The cameras stay\n",
          SG_N_CLASSES);
}

/* ---------------------------------------------------------------- arguments */

/* --depth's values, indexed by sg_depth_format; also the depth files' extensions. */
static const char *const depth_names[] = {"none", "png", "npy"};

static int parse_int(const char *opt, const char *s, int lo, int hi, int *out) {
  char *end;
  errno = 0;
  long v = strtol(s, &end, 10);
  if (errno || end == s || *end || v < lo || v > hi) {
    fprintf(stderr, "fieldgrip-scenegen: %s wants an integer in %d..%d, got \"%s\"\n", opt, lo,
            hi, s);
    return -1;
  }
  *out = (int)v;
  return 0;
}

/* The index k of the object named by name[0..len) (class SG_CLASS_MUG + k), or -1. */
static int object_index(const char *name, size_t len) {
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    const char *n = sg_class_names[SG_CLASS_MUG + k];
    if (strlen(n) == len && strncmp(n, name, len) == 0) return k;
  }
  return -1;
}

static int parse_args(int argc, char **argv, sg_config *cfg, const char **out_dir) {
  static const struct option opts[] = {
      {"out", required_argument, NULL, 'o'},     {"seed", required_argument, NULL, 's'},
      {"views", required_argument, NULL, 'n'},   {"width", required_argument, NULL, 'W'},
      {"height", required_argument, NULL, 'H'},  {"dim", required_argument, NULL, 'd'},
      {"patch", required_argument, NULL, 'p'},   {"noise", required_argument, NULL, 'e'},
      {"holdout", required_argument, NULL, 'k'}, {"help", no_argument, NULL, 'h'},
      {"embedding-seed", required_argument, NULL, 'E'},
      {"depth", required_argument, NULL, 'Z'},
      {"remove", required_argument, NULL, 'R'},  {"move", required_argument, NULL, 'M'},
      {NULL, 0, NULL, 0},
  };
  sg_config_default(cfg);
  *out_dir = NULL;
  int c;
  while ((c = getopt_long(argc, argv, "", opts, NULL)) != -1) {
    switch (c) {
    case 'o': *out_dir = optarg; break;
    case 's': {
      char *end;
      errno = 0;
      unsigned long long v = strtoull(optarg, &end, 10);
      /* gt.json stores the seed as a JSON integer, which jansson keeps in a signed 64-bit. */
      if (errno || end == optarg || *end || optarg[0] == '-' || v > INT64_MAX) {
        fprintf(stderr, "fieldgrip-scenegen: --seed wants an integer in 0..%" PRId64 "\n",
                INT64_MAX);
        return -1;
      }
      cfg->seed = v;
      break;
    }
    case 'E': {
      char *end;
      errno = 0;
      unsigned long long v = strtoull(optarg, &end, 10);
      if (errno || end == optarg || *end || optarg[0] == '-' || v > INT64_MAX) {
        fprintf(stderr, "fieldgrip-scenegen: --embedding-seed wants an integer in 0..%" PRId64
                "\n", INT64_MAX);
        return -1;
      }
      cfg->embedding_seed = (int64_t)v;
      break;
    }
    case 'n':
      if (parse_int("--views", optarg, 1, 9999, &cfg->n_views)) return -1;
      break;
    case 'W':
      if (parse_int("--width", optarg, 1, 8192, &cfg->w)) return -1;
      break;
    case 'H':
      if (parse_int("--height", optarg, 1, 8192, &cfg->h)) return -1;
      break;
    case 'd':
      if (parse_int("--dim", optarg, SG_N_CLASSES, 4096, &cfg->dim)) return -1;
      break;
    case 'p':
      if (parse_int("--patch", optarg, 1, 8192, &cfg->patch)) return -1;
      break;
    case 'e': {
      char *end;
      errno = 0;
      double v = strtod(optarg, &end);
      if (errno || end == optarg || *end || !(v >= 0 && v <= 100)) {
        fprintf(stderr, "fieldgrip-scenegen: --noise wants a number in 0..100, got \"%s\"\n",
                optarg);
        return -1;
      }
      cfg->noise = v;
      break;
    }
    case 'k':
      if (parse_int("--holdout", optarg, 0, 9999, &cfg->holdout)) return -1;
      break;
    case 'Z': {
      size_t k = 0;
      while (k < sizeof depth_names / sizeof depth_names[0] && strcmp(optarg, depth_names[k]))
        k++;
      if (k == sizeof depth_names / sizeof depth_names[0]) {
        fprintf(stderr, "fieldgrip-scenegen: --depth wants none, png or npy, got \"%s\"\n",
                optarg);
        return -1;
      }
      cfg->depth = (sg_depth_format)k;
      break;
    }
    case 'R': {
      const int k = object_index(optarg, strlen(optarg));
      if (k < 0) {
        fprintf(stderr, "fieldgrip-scenegen: --remove wants mug, bowl, box or ball, got \"%s\"\n",
                optarg);
        return -1;
      }
      cfg->removed |= 1u << k;
      break;
    }
    case 'M': {
      const char *comma = strchr(optarg, ',');
      const int k = comma ? object_index(optarg, (size_t)(comma - optarg)) : -1;
      double dx = 0, dy = 0;
      char tail;
      if (k < 0 || sscanf(comma + 1, "%lf,%lf%c", &dx, &dy, &tail) != 2 || !isfinite(dx) ||
          !isfinite(dy) || fabs(dx) > 1 || fabs(dy) > 1) {
        fprintf(stderr, "fieldgrip-scenegen: --move wants NAME,DX,DY (an object and metres "
                "up to 1 in x and y), got \"%s\"\n", optarg);
        return -1;
      }
      cfg->moved_xy[k][0] = dx;
      cfg->moved_xy[k][1] = dy;
      break;
    }
    case 'h': usage(stdout); exit(0);
    default: usage(stderr); return -1;
    }
  }
  if (optind < argc) {
    fprintf(stderr, "fieldgrip-scenegen: unexpected argument \"%s\"\n", argv[optind]);
    return -1;
  }
  if (!*out_dir) {
    usage(stderr);
    return -1;
  }
  return 0;
}

/* ---------------------------------------------------------------- output helpers */

static int write_in(const char *dir, const char *name, const void *buf, size_t len) {
  char *path = fg_path_join(dir, name);
  if (!path) return fg_fail(FG_ENOMEM, "out of memory");
  int rc = fg_write_file_atomic(path, buf, len);
  free(path);
  return rc;
}

static int write_json(const char *dir, const char *name, const json_t *j) {
  char *text = json_dumps(j, JSON_INDENT(2) | JSON_PRESERVE_ORDER);
  if (!text) return fg_fail(FG_ENOMEM, "out of memory formatting %s", name);
  size_t len = strlen(text);
  /* A final newline, as text files have. */
  char *buf = realloc(text, len + 2);
  if (!buf) {
    free(text);
    return fg_fail(FG_ENOMEM, "out of memory formatting %s", name);
  }
  buf[len] = '\n';
  buf[len + 1] = 0;
  int rc = write_in(dir, name, buf, len + 1);
  free(buf);
  return rc;
}

static json_t *vec_json(const double *v, int n) {
  json_t *a = json_array();
  for (int i = 0; i < n; i++) json_array_append_new(a, json_real(v[i]));
  return a;
}

static json_t *matrix_json(const double T[16]) {
  json_t *m = json_array();
  for (int i = 0; i < 4; i++) json_array_append_new(m, vec_json(T + 4 * i, 4));
  return m;
}

static json_t *pose_json(const double T[16]) {
  double p[3], q[4];
  fg_pose_to_quat(T, p, q);
  json_t *j = json_object();
  json_object_set_new(j, "position", vec_json(p, 3));
  json_object_set_new(j, "quaternion", vec_json(q, 4));
  json_object_set_new(j, "matrix", matrix_json(T));
  return j;
}

/* ---------------------------------------------------------------- views */

typedef struct buffers {
  uint8_t *rgb, *mask;
  float *feat;
  uint16_t *feat_h16;
  float *depth_m;      /* (h, w); NULL without --depth */
  uint16_t *depth_mm;  /* (h, w); NULL unless --depth png */
} buffers;

/* Millimetres of a z-depth for a 16-bit PNG, rounded to nearest (halves away from zero).
 * Depths beyond the 65.535 m a uint16 holds become 0, invalid, as RGB-D cameras report what
 * is out of their range; no ray of this scene goes that far. */
static uint16_t depth_to_mm(float z_m) {
  long mm = lround((double)z_m * 1000.0);
  return mm > 0 && mm <= UINT16_MAX ? (uint16_t)mm : 0;
}

static int write_depth(const sg_scene *sc, const char *dir, int i, buffers *b) {
  const int W = sc->cfg.w, H = sc->cfg.h;
  const size_t n = (size_t)W * H;
  char name[64];
  uint8_t *enc = NULL;
  size_t len = 0;
  if (sc->cfg.depth == SG_DEPTH_PNG) {
    for (size_t p = 0; p < n; p++) b->depth_mm[p] = depth_to_mm(b->depth_m[p]);
    FG_TRY(fg_image_encode_png(b->depth_mm, W, H, 1, 16, &enc, &len));
  } else {
    const size_t shape[2] = {(size_t)H, (size_t)W};
    FG_TRY(fg_npy_encode(FG_DTYPE_F32, 2, shape, b->depth_m, &enc, &len));
  }
  snprintf(name, sizeof name, "depth/%04d.%s", i, depth_names[sc->cfg.depth]);
  int rc = write_in(dir, name, enc, len);
  free(enc);
  return rc;
}

static int write_view(const sg_scene *sc, const char *dir, int i, buffers *b) {
  const int W = sc->cfg.w, H = sc->cfg.h;
  char name[64];
  uint8_t *enc = NULL;
  size_t len = 0;
  sg_scene_render(sc, i, b->rgb, b->mask, b->depth_m);

  FG_TRY(fg_image_encode_png(b->rgb, W, H, 3, 8, &enc, &len));
  snprintf(name, sizeof name, "images/%04d.png", i);
  int rc = write_in(dir, name, enc, len);
  free(enc);
  if (rc) return rc;

  FG_TRY(fg_image_encode_png(b->mask, W, H, 1, 8, &enc, &len));
  snprintf(name, sizeof name, "masks/%04d.png", i);
  rc = write_in(dir, name, enc, len);
  free(enc);
  if (rc) return rc;

  if (sc->cfg.depth != SG_DEPTH_NONE) FG_TRY(write_depth(sc, dir, i, b));

  FG_TRY(sg_scene_features(sc, i, b->mask, b->feat));
  size_t n = (size_t)sc->feat_h * sc->feat_w * sc->cfg.dim;
  fg_float_to_half_n(b->feat, b->feat_h16, n);
  const size_t shape[3] = {(size_t)sc->feat_h, (size_t)sc->feat_w, (size_t)sc->cfg.dim};
  FG_TRY(fg_npy_encode(FG_DTYPE_F16, 3, shape, b->feat_h16, &enc, &len));
  snprintf(name, sizeof name, "features/%04d.npy", i);
  rc = write_in(dir, name, enc, len);
  free(enc);
  return rc;
}

/* ---------------------------------------------------------------- JSON files */

static json_t *transforms_json(const sg_scene *sc, int held_out) {
  const fg_camera *cam = &sc->cam;
  json_t *root = json_object();
  json_object_set_new(root, "camera_model", json_string("PINHOLE"));
  json_object_set_new(root, "fl_x", json_real(cam->fl_x));
  json_object_set_new(root, "fl_y", json_real(cam->fl_y));
  json_object_set_new(root, "cx", json_real(cam->cx));
  json_object_set_new(root, "cy", json_real(cam->cy));
  json_object_set_new(root, "w", json_integer(cam->w));
  json_object_set_new(root, "h", json_integer(cam->h));
  json_object_set_new(root, "camera_angle_x", json_real(2 * atan(0.5 * cam->w / cam->fl_x)));
  /* nerfstudio's name for metres per unit of an integer depth image. */
  if (sc->cfg.depth == SG_DEPTH_PNG)
    json_object_set_new(root, "depth_unit_scale_factor", json_real(0.001));
  json_t *frames = json_array();
  for (int i = 0; i < sc->cfg.n_views; i++) {
    int test = sc->cfg.holdout > 0 && i % sc->cfg.holdout == 0;
    if (test != held_out) continue;
    char path[64];
    json_t *f = json_object();
    snprintf(path, sizeof path, "images/%04d.png", i);
    json_object_set_new(f, "file_path", json_string(path));
    snprintf(path, sizeof path, "features/%04d.npy", i);
    json_object_set_new(f, "features_path", json_string(path));
    if (sc->cfg.depth != SG_DEPTH_NONE) {
      snprintf(path, sizeof path, "depth/%04d.%s", i, depth_names[sc->cfg.depth]);
      json_object_set_new(f, "depth_file_path", json_string(path));
    }
    json_object_set_new(f, "transform_matrix", matrix_json(sc->T_world_cam + 16 * (size_t)i));
    json_array_append_new(frames, f);
  }
  json_object_set_new(root, "frames", frames);
  return root;
}

static json_t *gt_json(const sg_scene *sc) {
  const sg_config *cfg = &sc->cfg;
  json_t *root = json_object();
  json_object_set_new(root, "seed", json_integer((json_int_t)cfg->seed));
  json_object_set_new(root, "embedding_seed",
                      json_integer((json_int_t)(cfg->embedding_seed >= 0 ? cfg->embedding_seed
                                                                          : (int64_t)cfg->seed)));
  double bg[3] = {sc->background_rgb[0], sc->background_rgb[1], sc->background_rgb[2]};
  json_object_set_new(root, "background_rgb", vec_json(bg, 3));
  json_object_set_new(root, "width", json_integer(cfg->w));
  json_object_set_new(root, "height", json_integer(cfg->h));
  json_object_set_new(root, "views", json_integer(cfg->n_views));
  json_object_set_new(root, "feature_dim", json_integer(cfg->dim));
  json_object_set_new(root, "patch", json_integer(cfg->patch));
  json_t *grid = json_array();
  json_array_append_new(grid, json_integer(sc->feat_h));
  json_array_append_new(grid, json_integer(sc->feat_w));
  json_object_set_new(root, "feature_grid", grid);
  json_object_set_new(root, "noise", json_real(cfg->noise));
  json_object_set_new(root, "holdout", json_integer(cfg->holdout));
  /* Only with depth maps, so that a data set without them keeps the bytes it always had. */
  if (cfg->depth != SG_DEPTH_NONE)
    json_object_set_new(root, "depth", json_string(depth_names[cfg->depth]));
  json_object_set_new(root, "look_at", vec_json(sc->look_at_world, 3));
  json_object_set_new(root, "camera_radius", json_real(sc->camera_radius_m));
  json_t *light = json_object();
  json_object_set_new(light, "direction", vec_json(sc->light_dir_world, 3));
  json_object_set_new(light, "ambient", json_real(sc->ambient));
  json_object_set_new(root, "light", light);
  json_t *table = json_object();
  json_object_set_new(table, "min", vec_json(sc->table_min, 3));
  json_object_set_new(table, "max", vec_json(sc->table_max, 3));
  json_object_set_new(root, "table", table);

  json_t *classes = json_array();
  for (int k = 0; k < SG_N_CLASSES; k++) {
    json_t *c = json_object();
    json_object_set_new(c, "name", json_string(sg_class_names[k]));
    json_t *e = json_array();
    for (int i = 0; i < cfg->dim; i++)
      json_array_append_new(e, json_real(sc->embeddings[(size_t)k * cfg->dim + i]));
    json_object_set_new(c, "embedding", e);
    json_array_append_new(classes, c);
  }
  json_object_set_new(root, "classes", classes);

  json_t *objects = json_array();
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    const sg_object *ob = &sc->objects[k];
    if (!ob->present) continue;
    json_t *o = json_object();
    json_object_set_new(o, "name", json_string(ob->name));
    json_object_set_new(o, "class", json_integer(ob->class_id));
    json_object_set_new(o, "pose", pose_json(ob->shape.T_world_obj));
    double lo[3], hi[3], size[3], mn[3], mx[3];
    sg_shape_local_bounds(&ob->shape, lo, hi);
    for (int i = 0; i < 3; i++) size[i] = hi[i] - lo[i];
    json_object_set_new(o, "size", vec_json(size, 3));
    sg_shape_world_aabb(&ob->shape, mn, mx);
    json_t *aabb = json_object();
    json_object_set_new(aabb, "min", vec_json(mn, 3));
    json_object_set_new(aabb, "max", vec_json(mx, 3));
    json_object_set_new(o, "aabb", aabb);
    json_object_set_new(o, "shape", sg_shape_to_json(&ob->shape));
    json_object_set_new(o, "albedo", vec_json(ob->albedo, 3));
    json_t *grasp = pose_json(ob->T_world_grasp);
    json_object_set_new(grasp, "width", json_real(ob->grasp_width_m));
    json_object_set_new(o, "grasp", grasp);
    json_array_append_new(objects, o);
  }
  json_object_set_new(root, "objects", objects);
  json_object_set_new(root, "masks", json_string("masks/NNNN.png"));
  json_object_set_new(root, "mask_values",
                      json_string("pixel = class index (0 background, 1 table, 2 mug, 3 bowl, "
                                  "4 box, 5 ball) of the ray through the pixel's centre; an "
                                  "object's value is its \"class\""));
  if (cfg->depth == SG_DEPTH_PNG) {
    json_object_set_new(root, "depth_maps", json_string("depth/NNNN.png"));
    json_object_set_new(root, "depth_values",
                        json_string("uint16 z-depth (along the optical axis, not along the ray) "
                                    "of the ray through the pixel's centre, in millimetres, "
                                    "rounded; 0 where the ray hits nothing"));
  } else if (cfg->depth == SG_DEPTH_NPY) {
    json_object_set_new(root, "depth_maps", json_string("depth/NNNN.npy"));
    json_object_set_new(root, "depth_values",
                        json_string("float32 [height, width] z-depth (along the optical axis, "
                                    "not along the ray) of the ray through the pixel's centre, "
                                    "in metres; 0 where the ray hits nothing"));
  }
  return root;
}

/* ---------------------------------------------------------------- cell.xml */

static int write_cell(const sg_scene *sc, const char *dir) {
  char *xml;
  size_t len;
  FG_TRY(sg_cell_xml(sc, &xml, &len));
  int rc = write_in(dir, "cell.xml", xml, len);
  free(xml);
  return rc;
}

/* ---------------------------------------------------------------- main */

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int make_dirs(const char *dir, sg_depth_format depth) {
  static const char *const subdirs[] = {"images", "masks", "features", "depth"};
  const size_t n = sizeof subdirs / sizeof subdirs[0] - (depth == SG_DEPTH_NONE);
  FG_TRY(fg_mkdir_p(dir));
  for (size_t i = 0; i < n; i++) {
    char *p = fg_path_join(dir, subdirs[i]);
    if (!p) return fg_fail(FG_ENOMEM, "out of memory");
    int rc = fg_mkdir_p(p);
    free(p);
    FG_TRY(rc);
  }
  return 0;
}

/* Views are independent: with enough of them, each thread renders, encodes and writes whole
 * views (PNG compression and file writes then run in parallel too); with fewer views than
 * threads, views go one at a time and the renderer spreads each one's rows over the threads.
 * Either way a view's bytes depend on nothing but the view. */
static int write_views(const sg_scene *sc, const char *dir) {
  const size_t px = (size_t)sc->cfg.w * sc->cfg.h;
  const size_t nf = (size_t)sc->feat_h * sc->feat_w * sc->cfg.dim;
  const int n = sc->cfg.n_views;
  int first_err = 0, first_view = n;
  char detail[512] = "";
#pragma omp parallel if (n >= 2 * omp_get_max_threads())
  {
    const sg_depth_format depth = sc->cfg.depth;
    buffers b = {malloc(px * 3),
                 malloc(px),
                 malloc(nf * sizeof(float)),
                 malloc(nf * sizeof(uint16_t)),
                 depth != SG_DEPTH_NONE ? malloc(px * sizeof(float)) : NULL,
                 depth == SG_DEPTH_PNG ? malloc(px * sizeof(uint16_t)) : NULL};
    int alloc_rc = (!b.rgb || !b.mask || !b.feat || !b.feat_h16 ||
                    (depth != SG_DEPTH_NONE && !b.depth_m) ||
                    (depth == SG_DEPTH_PNG && !b.depth_mm))
                       ? FG_ENOMEM
                       : 0;
#pragma omp for schedule(dynamic, 1)
    for (int i = 0; i < n; i++) {
      int rc = alloc_rc ? fg_fail(alloc_rc, "out of memory") : write_view(sc, dir, i, &b);
      if (rc != 0) {
        /* Report the lowest failing view, whichever thread saw it first. */
#pragma omp critical(scenegen_error)
        if (i < first_view) {
          first_view = i;
          first_err = rc;
          snprintf(detail, sizeof detail, "view %d: %s", i, fg_error_detail());
        }
      }
    }
    free(b.rgb);
    free(b.mask);
    free(b.feat);
    free(b.feat_h16);
    free(b.depth_m);
    free(b.depth_mm);
  }
  if (first_err) return fg_fail(first_err, "%s", detail);
  return 0;
}

static int generate(const sg_scene *sc, const char *dir) {
  FG_TRY(make_dirs(dir, sc->cfg.depth));
  FG_TRY(write_views(sc, dir));
  int rc;
  json_t *j = transforms_json(sc, 0);
  rc = write_json(dir, "transforms.json", j);
  json_decref(j);
  FG_TRY(rc);
  if (sc->cfg.holdout > 0) {
    j = transforms_json(sc, 1);
    rc = write_json(dir, "transforms_test.json", j);
    json_decref(j);
    FG_TRY(rc);
  }
  j = gt_json(sc);
  rc = write_json(dir, "gt.json", j);
  json_decref(j);
  FG_TRY(rc);
  return write_cell(sc, dir);
}

int main(int argc, char **argv) {
  sg_config cfg;
  const char *dir;
  if (parse_args(argc, argv, &cfg, &dir) != 0) return 2;
  double t0 = now_s();
  sg_scene sc;
  int rc = sg_scene_build(&sc, &cfg);
  if (rc != 0) {
    fprintf(stderr, "fieldgrip-scenegen: %s\n", fg_error_detail());
    return rc == FG_EINVAL ? 2 : 1;
  }
  rc = generate(&sc, dir);
  sg_scene_free(&sc);
  if (rc != 0) {
    fprintf(stderr, "fieldgrip-scenegen: %s: %s\n", fg_strerror(rc), fg_error_detail());
    return 1;
  }
  printf("fieldgrip-scenegen: %d views %dx%d, features %dx%dx%d, seed %" PRIu64
         ", %.2f s -> %s\n",
         cfg.n_views, cfg.w, cfg.h, (cfg.h + cfg.patch - 1) / cfg.patch,
         (cfg.w + cfg.patch - 1) / cfg.patch, cfg.dim, cfg.seed, now_s() - t0, dir);
  return 0;
}
