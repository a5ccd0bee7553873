/* Frames whose pose comes from the robot (frames.h). */
#include "frames.h"

#include <string.h>

#include "core/error.h"
#include "core/pose.h"

void fg_cell_frame_camera(const fg_camera_calib *calib, const double T_base_cam[16],
                          fg_ingest_input *in) {
  const fg_intrinsics *k = &calib->in;
  memset(&in->camera, 0, sizeof in->camera);
  in->camera.file_path = "robot";
  /* the calibration's principal point is OpenCV's (pixel centres at integers), a frame's
   * camera counts from the pixels' corners */
  const fg_camera cam = {k->fx, k->fy, k->cx + 0.5, k->cy + 0.5, k->w, k->h, FG_CAMERA_OPENCV,
                         k->k[0], k->k[1], 0, k->k[2], k->k[3]};
  fg_transforms_frame_set_camera(&in->camera, &cam);
  memcpy(in->T_world_cam, T_base_cam, sizeof in->T_world_cam);
  fg_pose_flip_yz(in->T_world_cam); /* frames keep SPEC.md's default, OpenGL's */
}

int fg_cell_frame_upload(fg_app *app, const fg_conf *conf, fg_scene *s, fg_ingest_input *in,
                         const fg_conf_camera *cam, const double *T_base_tcp, int *index,
                         fg_frame *out) {
  fg_camera_calib cal;
  fg_cameras_calib_get(app->cameras, cam->name, &cal);
  if (!cal.has_intrinsics || !cal.has_mount)
    return fg_fail_as(FG_EINVAL, "not_calibrated", "%s is not calibrated (intrinsics and "
                      "mount): POST /v1/cameras/%s/calibrate first", cam->name, cam->name);
  double T_base_cam[16];
  if (cam->mount == FG_MOUNT_FIXED) {
    if (T_base_tcp)
      return fg_fail_as(FG_EINVAL, "invalid_request", "%s is a fixed camera: its frames need "
                        "no robot_pose", cam->name);
    memcpy(T_base_cam, cal.T_mount, sizeof T_base_cam);
  } else {
    double T_now[16];
    if (!T_base_tcp) {
      fg_robot_tcp t;
      FG_TRY(fg_robot_tcp_read(app->robot, &t));
      FG_TRY(fg_pose_from_quat(t.p_m, t.q_wxyz, T_now));
      T_base_tcp = T_now;
    }
    fg_pose_compose(T_base_tcp, cal.T_mount, T_base_cam);
    in->has_robot_pose = 1;
    memcpy(in->T_world_tcp, T_base_tcp, sizeof in->T_world_tcp);
  }
  fg_cell_frame_camera(&cal, T_base_cam, in);
  return fg_ingest_upload(app, conf, s, in, index, out);
}
