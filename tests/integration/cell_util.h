/* Shared by the tests of the cell (cameras, cell_calibration, scan): fieldgrip-sim started in
 * its physics mode with its camera, and frames aimed at points. Every helper succeeds or fails
 * the test (tests/test.h). */
#ifndef FG_IT_CELL_UTIL_H
#define FG_IT_CELL_UTIL_H

#include <stddef.h>
#include <stdint.h>

#include "simproc.h"

/* Starts the simulator (simproc_init first) on tests/sim/cells/blocks.xml at time scale 0,
 * its camera served on a free loopback port, with the options in extra (NULL-terminated;
 * NULL: none). Returns the camera's port. */
int cu_sim_start(simproc *sim, const char *const *extra);
/* The same on the MJCF file scene (a scenegen layout's cell.xml, say). */
int cu_sim_start_scene(simproc *sim, const char *scene, const char *const *extra);

/* The orientation (w x y z) of a frame at eye whose +z points at target, its x level (world
 * z = 0) and its y towards world -z, turned by roll_deg about its z: a camera's looking at
 * target (OpenCV convention), or a tool's pointing there. */
void cu_look_at(const double eye[3], const double target[3], double roll_deg, double q[4]);

/* The simulator's camera of the scan tests: its intrinsics and distortion (--camera) and its
 * mount on the tool (--camera-mount: 3 degrees about x). */
#define CU_SCAN_CAMERA "600 598 318.2 241.4 480 360 -0.05 0.01 0.0005 -0.0007"
#define CU_SCAN_MOUNT "0.035 0.01 -0.06 0.99966 0.02618 0 0"

/* The cell of scan_grasp and bench_first_grasp: the grasp tests' scenegen layout (the trained
 * fixture's data set, of fieldgrip-scenegen at scenegen) in the simulator (simproc_init
 * first), its report written to <tmp>/physics.jsonl (copied into report, PATH_MAX bytes), at
 * time_scale (NULL: 0, motions at once), the camera CU_SCAN_CAMERA on CU_SCAN_MOUNT serving
 * features in 8-pixel patches as the data set's, with its true calibration as "wrist"; fieldgripd started with the 2F-85, that robot (its Modbus
 * timeout robot_timeout_ms) and camera, the fixture's t250 as scene "sg", and a new scene
 * "scan" over the layout's workspace at 1 cm against the simulator's grey room. The caller
 * stops sim. */
void cu_scan_cell_start(const char *scenegen, const char *time_scale, int robot_timeout_ms,
                        simproc *sim, char *report);

/* Writes that camera's true calibration as camera `name`'s into the state dir, as a
 * calibration would have left it; before h_start. */
void cu_calibration_truth(const char *name);

/* Each frame of frames (GET /v1/scenes/{s}/frames' list, OpenGL convention) against the
 * simulator's true camera pose of the image it served (its --camera-log's "rgb" lines, in
 * order from the first): the worst position error in mm and rotation error in degrees. */
struct json_t;
void cu_frame_errors(struct json_t *frames, const char *cam_log, double *worst_mm,
                     double *worst_deg);

/* Executes grasp id of scene through fieldgripd (a pick, Idempotency-Key key) and returns
 * what physics lifted, from the last line of the simulator's --report file report_path that
 * a command wrote: the object's name, or "none" (caller frees). */
char *cu_execute_lifted(const char *scene, const char *id, const char *key,
                        const char *report_path);

/* Standard base64 (padding allowed), as captures carry their images, into a malloc'd buffer;
 * its length in *len. */
uint8_t *cu_unbase64(const char *s, size_t *len);

#endif
