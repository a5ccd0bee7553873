/* Shared by the task and grasp integration tests: a scenegen data set, a coarse scene (2 cm
 * voxels, so that grasp searches stay short on two cores) trained on its features, and the
 * ground-truth grasps of gt.json as demo bodies. Like the harness, every helper asserts. */
#ifndef FG_IT_GRASP_UTIL_H
#define FG_IT_GRASP_UTIL_H

#include "training.h"

#define G_VIEWS 30
#define G_W 160
#define G_H 120
#define G_DIM 32
#define G_PATCH 8
#define G_NQ 32 /* query points of the tests' demos */

/* Makes the data set under <tmp>/imports/sg with scenegen and loads its gt.json; returns the
 * imports folder (caller frees). */
char *g_dataset(const char *scenegen);

/* Takes the data set in dir (made by scenegen with the G_* parameters) as the tests' one:
 * loads its gt.json. */
void g_dataset_at(const char *dir);

/* gt.json and the data set's folder, after g_dataset or g_dataset_at. */
json_t *g_gt(void);
const char *g_dir(void);

/* Writes the configuration: import_dirs, [train] threads 2, then extra (may be NULL). */
void g_config(const char *imports, const char *extra);

/* Creates scene name over scenegen's tabletop at 2 cm voxels and imports the data set
 * (transforms file tf, NULL for transforms.json). */
void g_scene(const char *name, const char *tf);
/* The same at voxel metres. */
void g_scene_at(const char *name, const char *tf, double voxel);

/* POSTs the import of the data set (transforms file tf, NULL for transforms.json) to
 * scene; no status is asserted. The caller frees the reply. */
h_resp *g_import(const char *scene, const char *tf);

/* Trains scene for steps and waits until done. */
void g_train(const char *scene, int steps);

/* The embedding of class name of gt.json as JSON text; caller frees. */
char *g_class_embedding(const char *name);

/* Object `name` of gt.json. */
json_t *g_object(const char *name);

/* A demo body (JSON text) for object name's ground-truth grasp on scene, with extra keys
 * (may be "") and G_NQ query points; caller frees. */
char *g_demo_body(const char *scene, const char *object, const char *extra);
/* The same with "query_points": qp (JSON text; NULL leaves the key out). */
char *g_demo_body_qp(const char *scene, const char *object, const char *qp, const char *extra);

/* The demo body of object name's ground-truth grasp on scene as a user shows it (and
 * scripts/demo.sh): the gripper open to the 2F-85's stroke (0.085 m), no query points named
 * (the daemon's default, the box between the pads); caller frees. */
char *g_demo_body_open(const char *scene, const char *object);

/* How far (metres) grasp (an item of a grasps reply) lies from object name's ground-truth
 * grasp. */
double g_grasp_error(json_t *grasp, const char *object);

/* POST path with a JSON body; the caller frees the reply. */
h_resp *g_post(const char *path, const char *body);

#endif
