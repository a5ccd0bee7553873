/* Views of a scenegen data set for the render checks of test_heatmap and geometry_checks:
 * the training view whose mask shows the most of a label, and a frame's camera as the JSON
 * the render endpoint takes. Like the harness, these assert instead of returning an error. */
#ifndef FG_IT_VIEWS_H
#define FG_IT_VIEWS_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>

/* Of views 0..views-1 of the data set in dir (masks/NNNN.png, each w x h; scenegen's labels:
 * 0 background, 1 the table, 2 + k object k), the one whose mask has the most pixels of
 * label; returns it, with its mask (w * h labels, the caller frees) and that count. */
int v_best_view(const char *dir, int views, int w, int h, int label, uint8_t **mask,
                size_t *count);

/* Frame `view` of transforms.json (frames) as a camera JSON object text (transform_matrix,
 * fl_x, fl_y, cx, cy, w, h); the caller frees. */
char *v_frame_camera(json_t *frames, int view, int w, int h);

#endif
