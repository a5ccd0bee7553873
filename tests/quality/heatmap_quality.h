/* Heatmap quality on a trained scenegen layout (heatmap_quality.c): issue 5's criterion per
 * object class, and issue 13's geometry when the layout was trained with depth. Asserts. */
#ifndef FG_HEATMAP_QUALITY_H
#define FG_HEATMAP_QUALITY_H

#include "layout.h"

void heatmap_quality_check(const sg_layout *L);

#endif
