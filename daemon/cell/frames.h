/* Frames whose pose comes from the robot (SPEC.md: an upload's meta with "camera": NAME and
 * "robot_pose"): the camera's calibration gives the intrinsics and the mount, the robot's TCP
 * pose (given, or read now) the rest. Scans store their frames the same way. */
#ifndef FG_DAEMON_CELL_FRAMES_H
#define FG_DAEMON_CELL_FRAMES_H

#include "cameras.h"
#include "state/ingest.h"

/* Fills in's camera (intrinsics and OpenCV distortion) and pose (OpenGL convention, as
 * frames keep it) from calib and the camera's pose in the base frame (OpenCV convention). */
void fg_cell_frame_camera(const fg_camera_calib *calib, const double T_base_cam[16],
                          fg_ingest_input *in);

/* Ingests in (its image, features, depth, capture) into scene s as a frame of camera cam at
 * the TCP pose T_base_tcp, or at the TCP pose read now when T_base_tcp is NULL (a hand camera,
 * whose frame keeps that pose as its robot pose; a fixed camera needs none). Failures:
 * not_calibrated, invalid_request (a robot pose for a fixed camera), the robot's
 * (fg_robot_tcp_read), and fg_ingest_upload's. */
int fg_cell_frame_upload(fg_app *app, const fg_conf *conf, fg_scene *s, fg_ingest_input *in,
                         const fg_conf_camera *cam, const double *T_base_tcp, int *index,
                         fg_frame *out);

#endif
