/* Ingest: frames into a scene from encoded images, with their camera, pose and, optionally,
 * features and a depth map; one uploaded frame, or a data set folder on this machine
 * (transforms.json) read in parallel. Images and image depth maps are decoded by the app's
 * decoder, in a child process.
 *
 * Failures carry their reason (core/error.h): unsupported_media_type, invalid_image,
 * invalid_camera, invalid_features, invalid_depth, invalid_pose, invalid_request,
 * invalid_transforms, forbidden_path, path_not_found, scene_not_found, internal_error, and a
 * failed write's (fg_state_write_failed). Nothing is stored on failure. */
#ifndef FG_DAEMON_STATE_INGEST_H
#define FG_DAEMON_STATE_INGEST_H

#include <stddef.h>

#include "app.h"
#include "store.h"

#include "io/frame.h"
#include "io/npy.h"
#include "io/transforms.h"

/* The largest image, feature or depth file an import reads. */
#define FG_INGEST_MAX_FILE (512u << 20)

/* One frame as it arrives. */
typedef struct fg_ingest_input {
  const void *image;            /* encoded: PNG, JPEG, OpenEXR or TIFF */
  size_t image_len;
  fg_transforms_frame camera;   /* may still lack what only the image's size gives */
  double T_world_cam[16];
  const fg_npy *features;       /* NULL: none */
  const void *depth;            /* an encoded depth map (.npy or an image); NULL: none */
  size_t depth_len;
  double depth_scale;           /* metres per unit of an integer depth image */
  const char *source;           /* the frame's name: its file */
  int64_t capture;              /* the capture it joins (store.h); 0: the newest */
  int has_robot_pose;           /* 1: T_world_tcp is the robot's TCP pose at the frame */
  double T_world_tcp[16];
} fg_ingest_input;

/* Ingests one uploaded frame into scene s; *index gets its number and *out the frame as stored
 * (fg_frame_clear; out->capture is the capture it joined). When the fault is the frame's
 * depth map, the message starts with "frame '<source>': depth: ". */
int fg_ingest_upload(fg_app *app, const fg_conf *conf, fg_scene *s, const fg_ingest_input *in,
                     int *index, fg_frame *out);

/* A frame an import skipped: its transforms.json entry and why. */
typedef struct fg_import_skip {
  size_t frame;
  const char *file_path; /* the result's */
  char reason[768];
} fg_import_skip;

typedef struct fg_import_result {
  size_t imported, with_depth, depth_missing;
  int first;              /* the number of the first frame imported */
  int64_t capture;        /* the capture the frames joined */
  fg_import_skip *skipped; /* (n_skipped) in file order */
  size_t n_skipped;
  fg_transforms t;        /* the data set as read (file paths of the skipped frames) */
} fg_import_result;

/* Imports the data set in folder `path` (absolute, or relative to the first import folder
 * that has it; inside [state] import_dirs) described by its file `transforms` into scene s,
 * its frames into `capture` (0: the newest). A frame whose image is missing or whose depth
 * map cannot be used is skipped, with the reason; any other failure of a frame fails the
 * import ("frame i (file): ...; nothing was imported"). *out: fg_import_result_release. */
int fg_ingest_import(fg_app *app, const fg_conf *conf, fg_scene *s, const char *path,
                     const char *transforms, int64_t capture, fg_import_result *out);

/* Accepts a zeroed struct. */
void fg_import_result_release(fg_import_result *r);

#endif
