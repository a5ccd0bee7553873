/* A short training on a scenegen tabletop: the held-out views reach a PSNR floor, and the
 * rendered features of held-out views point the way of the ground-truth class embeddings on
 * object pixels (mean cosine >= 0.9), as the heatmaps of later issues need.
 * argv[1]: the fieldgrip-scenegen program. */
#include "testutil.h"

#include "core/fsutil.h"
#include "core/half.h"
#include "field/image.h"
#include "field/model.h"
#include "field/train.h"
#include "gt.h"
#include "io/dataset.h"
#include "io/image.h"

#define STEPS 400
#define PSNR_FLOOR 24.0
#define COSINE_FLOOR 0.9
#define ERODE 4 /* half the feature patch */

int main(int argc, char **argv) {
  ASSERT(argc == 2);
  char *dir = sg_test_tmpdir("train");
  const char *args[] = {"--out", dir, "--views", "30", "--width", "160", "--height", "120",
                        "--dim", "32", "--patch", "8", "--holdout", "0", NULL};
  ASSERT_EQ(sg_test_run(argv[1], args), 0);
  char *transforms = fg_path_join(dir, "transforms.json"), *gt_path = fg_path_join(dir, "gt.json");
  sg_gt gt;
  ASSERT_OK(sg_gt_load(gt_path, &gt));
  fg_ingest_opts io = {.background_rgb = {gt.background_rgb[0], gt.background_rgb[1],
                                          gt.background_rgb[2]}};
  fg_frame *frames;
  size_t n;
  ASSERT_OK(fg_dataset_load(transforms, &io, 2, &frames, &n));
  ASSERT_EQ(n, 30);

  /* The tabletop workspace of SPEC.md's example configuration. */
  const double ws_min[3] = {0.10, -0.45, 0.005}, ws_max[3] = {0.80, 0.45, 0.35};
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, ws_min, ws_max, 2.0, gt.feature_dim));
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, 1));
  fg_train_opts o;
  fg_train_opts_default(&o);
  o.n_threads = 2;
  o.holdout_every = 10; /* views 0, 10, 20 */
  o.target_samples = 1 << 15;
  memcpy(o.background, gt.background_rgb, sizeof o.background);
  fg_trainer *t;
  ASSERT_OK(fg_trainer_new(&t, f, frames, n, &o));
  ASSERT_EQ(fg_trainer_n_heldout(t), 3);
  fg_train_stats st;
  for (int s = 0; s < STEPS; s++) ASSERT_OK(fg_trainer_step(t, &st));
  double psnr;
  ASSERT_OK(fg_trainer_eval(t, 1, &psnr));
  printf("after %d steps: loss %.5f, feature loss %.5f, held-out PSNR %.2f dB\n", STEPS, st.loss,
         st.loss_feat, psnr);
  ASSERT(psnr >= PSNR_FLOOR);

  /* Features of the held-out views on object pixels (mask labels 2..5 = object + 2). */
  const int D = gt.feature_dim;
  double sum = 0.0, sum_target = 0.0, sum_in = 0.0;
  long count = 0, count_in = 0;
  for (int view = 0; view < 30; view += 10) {
    const fg_frame *fr = &frames[view];
    const int w = fr->cam.w, h = fr->cam.h;
    char name[64];
    snprintf(name, sizeof name, "masks/%04d.png", view);
    char *png;
    size_t len;
    sg_test_read(dir, name, &png, &len);
    fg_image mask;
    const float black[3] = {0, 0, 0};
    ASSERT_OK(fg_image_decode(png, len, black, &mask));
    free(png);
    ASSERT(mask.w == w && mask.h == h);
    float *feat = malloc((size_t)w * h * D * sizeof(float));
    ASSERT(feat);
    ASSERT_OK(fg_field_render_camera(f, fr->T_world_cam, &fr->cam, o.background, NULL, NULL,
                                     NULL, feat, 2));
    for (int p = 0; p < w * h; p++) {
      const int label = (int)lroundf(mask.rgb[3 * p] * 255.0f);
      if (label < 2) continue;
      /* Interior: every pixel within half a patch shows the same object. */
      int interior = 1;
      for (int dy = -ERODE; interior && dy <= ERODE; dy++)
        for (int dx = -ERODE; dx <= ERODE; dx++) {
          const int x = p % w + dx, y = p / w + dy;
          interior &= x >= 0 && x < w && y >= 0 && y < h &&
                      (int)lroundf(mask.rgb[3 * (y * w + x)] * 255.0f) == label;
        }
      const float *e = gt.embeddings + (size_t)gt.objects[label - 2].class_id * D;
      double dot = 0, na = 0, nb = 0;
      for (int k = 0; k < D; k++) {
        dot += (double)feat[(size_t)p * D + k] * e[k];
        na += (double)feat[(size_t)p * D + k] * feat[(size_t)p * D + k];
        nb += (double)e[k] * e[k];
      }
      const double cosv = na > 0 ? dot / sqrt(na * nb) : 0.0;
      sum += cosv;
      count++;
      if (interior) sum_in += cosv, count_in++;
      /* The same for the frame's own patch feature at that pixel: what supervision gave. */
      const int cy = (p / w) * fr->feat_h / h, cx = (p % w) * fr->feat_w / w;
      const uint16_t *tf = (const uint16_t *)fr->feat + ((size_t)cy * fr->feat_w + cx) * D;
      double tdot = 0, tn = 0;
      for (int k = 0; k < D; k++) {
        const double v = fg_half_to_float(tf[k]);
        tdot += v * e[k];
        tn += v * v;
      }
      sum_target += tdot / sqrt(tn * nb);
    }
    free(feat);
    fg_image_release(&mask);
  }
  ASSERT(count_in > 300);
  const double mean_all = sum / (double)count, mean_target = sum_target / (double)count;
  const double mean_in = sum_in / (double)count_in;
  printf("mean cosine with the class embeddings: %.4f over %ld object pixels (the views' own "
         "patch features: %.4f), %.4f over the %ld pixels at least %d px inside an object\n",
         mean_all, count, mean_target, mean_in, count_in, ERODE);
  /* Inside objects the field must be right; at their silhouettes, where one patch feature
   * covers object and table, it must be at least as right as the views' own features. */
  ASSERT(mean_in >= COSINE_FLOOR);
  ASSERT(mean_all >= mean_target);

  fg_trainer_free(t);
  fg_field_free(f);
  fg_dataset_free(frames, n);
  sg_gt_free(&gt);
  fg_rmtree(dir);
  free(dir);
  free(transforms);
  free(gt_path);
  printf("ok\n");
  return 0;
}
