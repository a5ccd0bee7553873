/* A trained scenegen layout for the quality checks (tests/quality): one generated tabletop,
 * its field trained in-process and its voxel features, which the heatmap checks (issue 5, and
 * issue 13 with depth) and the grasp checks (issue 12) share where they can, so that no
 * layout is trained twice.
 *
 * Every layout: 30 views of 160 x 120 with 32-d features in 4-pixel patches, 1500 steps of
 * 2^15 samples on 2 threads over the tabletop workspace of SPEC.md's example configuration,
 * voxel features at 1 cm. What differs is in sg_layout_spec (a benchmark may ask for other
 * steps and threads). Like the harness, every helper asserts instead of returning an error. */
#ifndef SG_LAYOUT_H
#define SG_LAYOUT_H

#include <stddef.h>

#include "field/model.h"
#include "field/train.h"
#include "gt.h"
#include "io/dataset.h"
#include "query/voxfeat.h"

#define SG_LAYOUT_STEPS 1500
#define SG_LAYOUT_VIEWS 30
#define SG_LAYOUT_THREADS 2

typedef struct sg_layout_spec {
  const char *seed;           /* scenegen's --seed */
  const char *embedding_seed; /* its --embedding-seed: the class embeddings (one vocabulary
                                 for layouts that share it, as frames of one feature
                                 extractor have) */
  int depth;                  /* 1: 16-bit depth maps (an RGB-D capture), trained with depth */
  int holdout_every;          /* the trainer's: 10 holds views 0, 10 and 20 out; 0 none */
  int steps;                  /* training steps; 0: SG_LAYOUT_STEPS (a benchmark's budget) */
  int threads;                /* training and voxel threads; 0: SG_LAYOUT_THREADS */
  const char *const *edit;    /* scenegen's --remove and --move (NULL-terminated; NULL for
                                 none): the layout after the scene changed */
  const fg_field *init;       /* NULL: a new field; else go on from it (an update:
                                 fg_field_copy_for_update) */
  float focus;                /* with init: the share of rays drawn where the views changed
                                 (fg_trainer_focus); 0 none */
} sg_layout_spec;

typedef struct sg_layout {
  sg_layout_spec spec;
  char *dir;                /* the data set: gt.json, masks/ */
  sg_gt gt;
  fg_frame *frames;         /* all 30, the held-out ones included */
  size_t n_frames;
  fg_field *field;
  float background[3];      /* the trainer's background colour */
  fg_voxel_features *vf;    /* 1 cm voxels over the workspace */
  double train_s;           /* the training's wall time so far, seconds */
  fg_trainer *trainer;      /* between sg_layout_prepare and the end of sg_layout_train */
  int steps_done;
  float loss;               /* the last step's */
} sg_layout;

/* Generates the layout of spec with fieldgrip-scenegen (the program's path), trains it and
 * builds its voxel features; prints the training's time and loss. The data set's folder
 * (L->dir) holds scenegen's cell.xml too. */
void sg_layout_train(const char *scenegen, const sg_layout_spec *spec, sg_layout *L);

/* sg_layout_train in parts, for a benchmark that looks at the field as it trains: the data
 * set, its frames and the field with its trainer; n more steps (timed into train_s); the
 * voxel features of the field as it is now (built again at each call). */
void sg_layout_prepare(const char *scenegen, const sg_layout_spec *spec, sg_layout *L);
void sg_layout_steps(sg_layout *L, int n);
void sg_layout_voxels(sg_layout *L);

/* Releases everything and removes the data set's folder. */
void sg_layout_free(sg_layout *L);

#endif
