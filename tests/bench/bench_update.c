/* Updates against retraining (issue 39): after a pick changed the scene, how many steps and
 * seconds a field needs to meet the update test's quality again when it goes on from the old
 * field, against one trained from scratch on the new views, side by side, with and without
 * depth maps.
 *
 * Layouts. scenegen's seed --seed (default 0; another seed's box may have no room to move)
 * before; after, the same layout with the mug taken away and the box moved 10 cm (--remove
 * mug --move box,0.10,0), the cameras where they were: 30 views of 160 x 120, 32-d features in 4-pixel patches, 2^15 samples a step on
 * --threads threads, as tests/quality/layout.h trains them. Before: --steps steps from
 * scratch. After, two trainings on the new views, each looked at every --every steps up to
 * --max:
 *   update   from the field before (fg_field_copy_for_update: "init": "current");
 *   focus    the same, with --focus percent of the rays drawn where the views changed
 *            (fg_trainer_focus; --focus 0 leaves this run out);
 *   scratch  from random weights.
 * At each look: the share of the mug's voxels (where it stood, 1 cm; those 1.5 cm above the
 * table) that are free (alpha < 0.1), and the moved box's heatmap IoU (its class against the
 * others, tests/quality's heatmap_iou). The quality, tests/quality's update check: >= 95 % of the mug's voxels free
 * and the box's IoU at most 0.05 below the scratch field's at --max. Seconds are the steps'
 * own (not the looks').
 *
 * Usage: bench_update --scenegen PROGRAM [--seed N] [--steps N] [--max N] [--every N]
 *                     [--threads N] [--depth both|with|without] [--focus PERCENT]
 * Defaults: seed 0, 1500 steps before, up to 1500 after, every 50, 2 threads, both, focus 50.
 * Output, per look:
 *   bench=update_look depth=yes|no mode=update|focus|scratch step=.. seconds=.. removed_free=..
 *   box_iou=..
 * and per depth mode:
 *   bench=update depth=.. update_steps=.. update_s=.. focus_steps=.. focus_s=.. scratch_steps=..
 *   scratch_s=.. step_ratio=.. time_ratio=.. (scratch over update; "none" when a training
 *   never met it) focus=.. focus_time_ratio=.. (scratch over focus)
 *   pass=yes|no (the update as fieldgripd makes it, with the focus unless --focus 0, met the
 *   quality in fewer steps than the scratch training) */
#include "testutil.h"

#include <getopt.h>
#include <math.h>

#include "grasps.h"
#include "gtvox.h"
#include "heatmap_quality.h"
#include "layout.h"
#include "query/heatmap.h"

#define MAX_LOOKS 256
#define REMOVED_FREE 0.95
#define IOU_SLACK 0.05

typedef struct look {
  int step;
  double seconds, removed_free, box_iou;
} look;

typedef struct opts {
  const char *scenegen, *seed;
  int steps, max, every, threads, with, without;
  float focus;
} opts;

/* The share of the voxels of owner == k whose alpha is below the occupancy threshold, of those
 * whose centre lies 1.5 cm above the table's top (the layer the table's surface shares is
 * solid in any field), as tests/quality's update check counts. */
static double free_share(const sg_layout *L, const signed char *owner, int k) {
  const float *a = fg_voxel_features_alpha(L->vf);
  const fg_voxel_grid *g = fg_voxel_features_grid(L->vf);
  const size_t N = fg_voxel_grid_count(g), nx = (size_t)g->nx, ny = (size_t)g->ny;
  size_t n = 0, f = 0;
  for (size_t i = 0; i < N; i++) {
    double c[3];
    fg_voxel_grid_centre(g, (int)(i % nx), (int)(i / nx % ny), (int)(i / (nx * ny)), c);
    if (owner[i] != k || c[2] < L->gt.table_max[2] + 0.015) continue;
    n++;
    f += a[i] < FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
  }
  return n ? (double)f / (double)n : NAN;
}

/* Trains the changed layout from init (NULL: scratch) up to o->max steps, looking every
 * o->every; returns the number of looks. */
static int run(const opts *o, int depth, const fg_field *init, float focus,
               const signed char *mug_owner, int mug, const char *mode, look *looks) {
  static const char *const edit[] = {"--remove", "mug", "--move", "box,0.10,0", NULL};
  const sg_layout_spec spec = {o->seed, o->seed, depth, 0, o->max, o->threads, edit, init, focus};
  sg_layout L;
  sg_layout_prepare(o->scenegen, &spec, &L);
  const int box_k = sg_object_index(&L.gt, "box");
  int n = 0;
  while (L.steps_done < o->max && n < MAX_LOOKS) {
    sg_layout_steps(&L, o->every);
    sg_layout_voxels(&L);
    look *l = &looks[n++];
    l->step = L.steps_done;
    l->seconds = L.train_s;
    l->removed_free = free_share(&L, mug_owner, mug);
    l->box_iou = heatmap_iou(&L, box_k);
    printf("bench=update_look depth=%s mode=%s step=%d seconds=%.2f removed_free=%.4f "
           "box_iou=%.4f\n", depth ? "yes" : "no", mode, l->step, l->seconds, l->removed_free,
           l->box_iou);
    fflush(stdout);
  }
  sg_layout_free(&L);
  return n;
}

/* The first look that meets the quality, or -1. */
static int first_met(const look *v, int n, double iou_ref) {
  for (int i = 0; i < n; i++)
    if (v[i].removed_free >= REMOVED_FREE && v[i].box_iou >= iou_ref - IOU_SLACK) return i;
  return -1;
}

static void mode_pair(const opts *o, int depth) {
  const sg_layout_spec before_spec = {o->seed, o->seed, depth, 0, o->steps, o->threads, NULL,
                                      NULL};
  sg_layout B;
  sg_layout_train(o->scenegen, &before_spec, &B);
  const fg_voxel_grid g = *fg_voxel_features_grid(B.vf);
  const size_t N = fg_voxel_grid_count(&g);
  signed char *owner = malloc(N), *cavity = malloc(N);
  ASSERT(owner && cavity);
  sg_gt_voxelise(&B.gt, &g, owner, cavity);
  const int mug = sg_object_index(&B.gt, "mug");
  static look up[MAX_LOOKS], fo[MAX_LOOKS], sc[MAX_LOOKS];
  const int nu = run(o, depth, B.field, 0.0f, owner, mug, "update", up);
  const int nf = o->focus > 0.0f ? run(o, depth, B.field, o->focus, owner, mug, "focus", fo) : 0;
  const int ns = run(o, depth, NULL, 0.0f, owner, mug, "scratch", sc);
  ASSERT(ns > 0);
  const double iou_ref = sc[ns - 1].box_iou;
  const int iu = first_met(up, nu, iou_ref), is = first_met(sc, ns, iou_ref);
  const int iff = first_met(fo, nf, iou_ref);
  char su[64] = "update_steps=none update_s=none", ss[64] = "scratch_steps=none scratch_s=none";
  char sf[64] = "focus_steps=none focus_s=none";
  char ratio_steps[32] = "none", ratio_s[32] = "none", ratio_f[32] = "none";
  if (iu >= 0)
    snprintf(su, sizeof su, "update_steps=%d update_s=%.2f", up[iu].step, up[iu].seconds);
  if (iff >= 0)
    snprintf(sf, sizeof sf, "focus_steps=%d focus_s=%.2f", fo[iff].step, fo[iff].seconds);
  if (is >= 0)
    snprintf(ss, sizeof ss, "scratch_steps=%d scratch_s=%.2f", sc[is].step, sc[is].seconds);
  if (iu >= 0 && is >= 0) {
    snprintf(ratio_steps, sizeof ratio_steps, "%.2f", (double)sc[is].step / up[iu].step);
    snprintf(ratio_s, sizeof ratio_s, "%.2f", sc[is].seconds / up[iu].seconds);
  }
  if (iff >= 0 && is >= 0)
    snprintf(ratio_f, sizeof ratio_f, "%.2f", sc[is].seconds / fo[iff].seconds);
  /* the update as fieldgripd runs it: with the focus when there is one */
  const look *best = o->focus > 0.0f ? (iff >= 0 ? &fo[iff] : NULL) : (iu >= 0 ? &up[iu] : NULL);
  const int pass = best && (is < 0 || best->step < sc[is].step);
  printf("bench=update depth=%s seed=%s before_steps=%d box_iou_ref=%.4f %s %s %s step_ratio=%s "
         "time_ratio=%s focus=%.2f focus_time_ratio=%s pass=%s\n", depth ? "yes" : "no",
         o->seed, o->steps, iou_ref, su, sf, ss, ratio_steps, ratio_s, o->focus, ratio_f,
         pass ? "yes" : "no");
  fflush(stdout);
  free(owner);
  free(cavity);
  sg_layout_free(&B);
}

static int parse_int(const char *s, int lo, int hi) {
  char *end;
  long v = strtol(s, &end, 10);
  if (*end || v < lo || v > hi) {
    fprintf(stderr, "bench_update: \"%s\" is not a whole number from %d to %d\n", s, lo, hi);
    exit(2);
  }
  return (int)v;
}

int main(int argc, char **argv) {
  opts o = {NULL, "0", 1500, 1500, 50, 2, 1, 1, 0.5f};
  static const struct option lo[] = {
      {"scenegen", required_argument, NULL, 'g'}, {"seed", required_argument, NULL, 's'},
      {"steps", required_argument, NULL, 'n'},    {"max", required_argument, NULL, 'm'},
      {"every", required_argument, NULL, 'e'},    {"threads", required_argument, NULL, 't'},
      {"depth", required_argument, NULL, 'd'},    {"focus", required_argument, NULL, 'f'},
      {NULL, 0, NULL, 0}};
  int c;
  while ((c = getopt_long(argc, argv, "", lo, NULL)) != -1) {
    switch (c) {
    case 'g': o.scenegen = optarg; break;
    case 's': o.seed = optarg; break;
    case 'n': o.steps = parse_int(optarg, 1, 100000); break;
    case 'm': o.max = parse_int(optarg, 1, 100000); break;
    case 'e': o.every = parse_int(optarg, 1, 100000); break;
    case 't': o.threads = parse_int(optarg, 1, 256); break;
    case 'f': o.focus = (float)parse_int(optarg, 0, 100) / 100.0f; break;
    case 'd':
      o.with = strcmp(optarg, "without") != 0;
      o.without = strcmp(optarg, "with") != 0;
      if (strcmp(optarg, "both") && strcmp(optarg, "with") && strcmp(optarg, "without")) {
        fprintf(stderr, "bench_update: --depth wants both, with or without\n");
        return 2;
      }
      break;
    default:
      fprintf(stderr, "usage: bench_update --scenegen PROGRAM [--seed N] [--steps N] [--max N] "
              "[--every N] [--threads N] [--depth both|with|without] [--focus PERCENT]\n");
      return 2;
    }
  }
  if (!o.scenegen) {
    fprintf(stderr, "bench_update: --scenegen PROGRAM is required\n");
    return 2;
  }
  if (o.max / o.every > MAX_LOOKS) {
    fprintf(stderr, "bench_update: --max / --every is over %d looks\n", MAX_LOOKS);
    return 2;
  }
  setvbuf(stdout, NULL, _IOLBF, 0);
  if (o.without) mode_pair(&o, 0);
  if (o.with) mode_pair(&o, 1);
  return 0;
}
