/* The API's JSON views of a scene and a frame (SPEC.md "Scenes", "Frames"). */
#ifndef FG_DAEMON_API_VIEWS_H
#define FG_DAEMON_API_VIEWS_H

#include <jansson.h>

#include "io/frame.h"
#include "state/store.h"

/* The scene object of the API. */
json_t *fg_json_scene(const fg_scene_info *info);

/* The frame object of the API. */
json_t *fg_json_frame(const fg_frame *frame, int index);

#endif
