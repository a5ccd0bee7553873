/* Heatmap quality on a trained scenegen layout (heatmap_quality.c): issue 5's criterion per
 * object class, and issue 13's geometry when the layout was trained with depth. Asserts. */
#ifndef FG_HEATMAP_QUALITY_H
#define FG_HEATMAP_QUALITY_H

#include "layout.h"

void heatmap_quality_check(const sg_layout *L);

/* The heatmap's IoU for object k of L's gt.json: its class queried with every other class as
 * negatives, the occupied voxels scoring >= 0.5 against the object's voxels (as
 * heatmap_quality_check counts them, the cavity included). */
double heatmap_iou(const sg_layout *L, int k);

#endif
