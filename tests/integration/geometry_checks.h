/* The geometry endpoint's checks (geometry_checks.c), run by test_heatmap on its trained
 * scene "sg": one training serves the heatmap's checks and these. Like the harness, every
 * check asserts instead of returning an error. */
#ifndef FG_IT_GEOMETRY_CHECKS_H
#define FG_IT_GEOMETRY_CHECKS_H

#include <jansson.h>

/* The scenegen data set scene "sg" was imported from (t_scene_from_dataset). */
typedef struct geometry_data_set {
  const char *dir;      /* its folder: masks/NNNN.png */
  json_t *frames;       /* its transforms.json */
  int views, w, h, dim; /* frames, their size, the feature dimension */
} geometry_data_set;

/* The geometry of untrained scene `scene` is 409 not_trained (naming the train route), an
 * unknown scene's 404. */
void geometry_checks_untrained(const char *scene);

/* After training: mesh, points, another voxel size, bad parameters and the normal render
 * (see geometry_checks.c). Reads the voxel cache a heatmap of "sg" built, or builds it. */
void geometry_checks(const geometry_data_set *ds);

#endif
