/* Grasp planning: what F3RM answers to "do task T" or "grasp the mug", on one grasp field.
 *
 * A plan picks the task (the one named, or the one whose demos look most like a language
 * query: F3RM's retrieval by fg_grasp_task_similarity), masks the candidates to where the
 * query's heatmap score reaches FG_GRASP_PLAN_MASK_SCORE, opens the gripper to the task's
 * width (at most its stroke), searches (fg_grasp_search) and backs every pose off along its
 * approach to the pre-grasp pose the robot comes in from. */
#ifndef FG_GRASP_PLAN_H
#define FG_GRASP_PLAN_H

#include "grasp/grasp.h"
#include "query/query.h"

#define FG_GRASP_PLAN_MASK_SCORE 0.5f /* candidates where the query's score reaches this */

/* A task as the plan reads it; the arrays stay the caller's for the call. */
typedef struct fg_grasp_task {
  const char *name;
  int place;              /* 1: a placement, which lets go and does not lift */
  int n_points;           /* N_q */
  int dim;                /* D */
  const float *p_gripper; /* (N_q, 3) query points, gripper frame, metres */
  const float *Z;         /* (N_q, D) the task embedding: its demos' mean */
  double width_m;         /* the demos' mean opening */
  double approach_m;      /* the demos' mean approach: the pre-grasp's distance */
} fg_grasp_task;

typedef struct fg_grasp_plan_request {
  const fg_grasp_task *tasks; /* the task (retrieve 0: tasks[0]) or those to retrieve from */
  int n_tasks;
  int retrieve;               /* 1: the task of tasks most like the query */
  const fg_query *query;      /* NULL: none; else it masks the candidates */
  int language_weight;        /* 1: the cost is J_lang with the query (grasp.h) */
  fg_grasp_options opt;       /* the search's; the plan sets width_m, approach_m and
                               * candidate_mask, and retreat_m to 0 for a placement */
} fg_grasp_plan_request;

typedef struct fg_grasp_retrieval {
  int task;     /* index in the request's tasks */
  double score; /* fg_grasp_task_similarity with the query */
} fg_grasp_retrieval;

typedef struct fg_grasp_plan {
  int task;                       /* index in the request's tasks of the task searched */
  fg_grasp_retrieval *retrieval;  /* (n_retrieval) best first, ties by name; NULL without */
  int n_retrieval;
  double width_m;                 /* the opening the poses were checked at */
  double approach_m;              /* the task's */
  double (*T_world_pre)[16];      /* (result.n) each pose backed off approach_m along -z */
  fg_grasp_result result;
} fg_grasp_plan;

/* Plans request r on grasp field gf into *out (fg_grasp_plan_release), also when the search
 * finds nothing (result.n 0 with a reason). Retrieval ranks the tasks of the query's D whose
 * similarity is defined. FG_ENOENT when none can be retrieved; FG_EINVAL with a detail for a
 * request that cannot be searched (no task, a task or query of another D than the field's,
 * a language weight without a query) and the search's errors; FG_ENOMEM. On failure *out
 * holds nothing to release. */
int fg_grasp_plan_run(const fg_grasp_field *gf, const fg_grasp_plan_request *r,
                      fg_grasp_plan *out);

/* Frees what *p owns and zeroes it; accepts a zeroed struct. */
void fg_grasp_plan_release(fg_grasp_plan *p);

#endif
