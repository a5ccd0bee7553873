/* Views of a scenegen data set for the render checks; see views.h. */
#include "views.h"

#include <math.h>

#include "core/error.h"
#include "harness.h"
#include "io/image.h"

int v_best_view(const char *dir, int views, int w, int h, int label, uint8_t **mask,
                size_t *count) {
  int best_view = -1;
  size_t best_count = 0;
  uint8_t *best_mask = NULL;
  for (int v = 0; v < views; v++) {
    char *path = h_fmt("%s/masks/%04d.png", dir, v);
    size_t len;
    char *png = h_read_file(path, &len);
    ASSERT(png != NULL);
    fg_image img;
    const float bg[3] = {0, 0, 0};
    ASSERT_OK(fg_image_decode(png, len, bg, &img));
    ASSERT_EQ(img.w, w);
    ASSERT_EQ(img.h, h);
    uint8_t *m = malloc((size_t)w * h);
    ASSERT(m != NULL);
    size_t n = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) {
      m[i] = (uint8_t)lrintf(img.rgb[3 * i] * 255.0f);
      n += m[i] == label;
    }
    if (n > best_count) {
      free(best_mask);
      best_mask = m, best_count = n, best_view = v;
    } else {
      free(m);
    }
    fg_image_release(&img);
    free(png);
    free(path);
  }
  ASSERT(best_view >= 0);
  *mask = best_mask;
  *count = best_count;
  return best_view;
}

char *v_frame_camera(json_t *frames, int view, int w, int h) {
  json_t *fr = json_array_get(JGET(frames, "frames"), (size_t)view);
  char *m = json_dumps(JGET(fr, "transform_matrix"), JSON_COMPACT | JSON_REAL_PRECISION(17));
  char *cam = h_fmt("{\"transform_matrix\": %s, \"fl_x\": %.17g, \"fl_y\": %.17g, \"cx\": %.17g, "
                    "\"cy\": %.17g, \"w\": %d, \"h\": %d}", m, JNUM(frames, "fl_x"),
                    JNUM(frames, "fl_y"), JNUM(frames, "cx"), JNUM(frames, "cy"), w, h);
  free(m);
  return cam;
}
