/* Grasp questions on trained layouts (layout.h), shared by the quality test's grasp checks
 * (test_scenegen_quality.c) and the physics benchmark (tests/bench/bench_grasp_physics.c):
 * the language query of a class, F3RM's task retrieval, the language mask of the search, and
 * a grasp's errors against the truth with the object's symmetries. Like layout.h, every
 * helper asserts instead of returning an error. */
#ifndef SG_GRASPS_H
#define SG_GRASPS_H

#include <stdint.h>

#include "layout.h"

#define SG_MASK_SCORE 0.5f   /* the language mask: heatmap score >= this (as fieldgripd's) */
#define SG_QUERY_TEMP 0.1f   /* the query's softmax temperature with negatives */

/* The index in gt.json's objects of the object called name (fails the run when none is). */
int sg_object_index(const sg_gt *gt, const char *name);

/* The query "name" on layout gt's vocabulary: the class embedding as the positive, every other
 * class as a negative. The caller releases *q (fg_query_release). */
void sg_class_query(const sg_gt *gt, const char *name, fg_query *q);

/* F3RM's retrieval by language: the index of the task, of n_tasks with embeddings Z[k]
 * (n_q, D), whose mean query-point feature is nearest q (D); sims (n_tasks, may be NULL)
 * receives every task's cosine. */
int sg_task_retrieve(float *const Z[], int n_tasks, int n_q, int D, const float *q,
                     double *sims);

/* The candidate mask of a search by language on layout L: 1 where the heatmap of q scores
 * at least SG_MASK_SCORE (at candidate alpha 0.1), into mask (the grid's voxel count), the
 * caller's. */
void sg_language_mask(const sg_layout *L, const fg_query *q, uint8_t *mask);

/* The distance (metres) and angle (degrees) of the gripper pose T from truth, both world
 * frame, for a grasp of object k of gt, with the symmetries that leave the grasp the same:
 * the parallel gripper turned by 180 degrees about its approach axis, and the object's own
 * (the box turned by 180 degrees about its vertical axis; the bowl turned about its axis
 * by any angle, so that a pinch anywhere on its rim counts at the rim; the ball in any
 * orientation, so only the position counts and the angle is 0). The mug has none: its
 * handle tells its sides apart. */
void sg_grasp_errors(const sg_gt *gt, int k, const double truth[16], const double T[16],
                     double *dist_m, double *angle_deg);

#endif
