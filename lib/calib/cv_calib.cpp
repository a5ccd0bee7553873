// Camera and hand-eye calibration with OpenCV 4.6 (calibrate.h). Every entry point catches all
// exceptions.
#include "calib/calibrate.h"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>
#include <new>
#include <vector>

extern "C" {
#include "core/error.h"
#include "core/pose.h"
}

namespace {

cv::Mat camera_matrix(const fg_intrinsics *in) {
  return (cv::Mat_<double>(3, 3) << in->fx, 0, in->cx, 0, in->fy, in->cy, 0, 0, 1);
}

cv::Mat dist_coeffs(const fg_intrinsics *in) {
  return (cv::Mat_<double>(1, 5) << in->k[0], in->k[1], in->k[2], in->k[3], 0);
}

// One view's corners as OpenCV wants them, and the board points they are.
void view_points(const fg_charuco_board *b, const fg_calib_view *v,
                 std::vector<cv::Point3f> *obj, std::vector<cv::Point2f> *img) {
  for (int k = 0; k < v->n; k++) {
    double c[3];
    fg_charuco_corner(b, v->ids[k], c);
    obj->emplace_back((float)c[0], (float)c[1], (float)c[2]);
    img->emplace_back((float)v->px[2 * k], (float)v->px[2 * k + 1]);
  }
}

// Whether the view's corners span the board's plane: not all on one line (one row or column
// of the board, or a diagonal), which leaves the board's pose, and OpenCV's homography of
// the view, undetermined. The smaller spread of the corners across their principal axes must
// be at least a quarter of a square.
bool spans_plane(const fg_charuco_board *b, const std::vector<cv::Point3f> &obj) {
  double mx = 0, my = 0;
  for (const cv::Point3f &p : obj) mx += p.x, my += p.y;
  mx /= (double)obj.size();
  my /= (double)obj.size();
  double sxx = 0, syy = 0, sxy = 0;
  for (const cv::Point3f &p : obj) {
    sxx += (p.x - mx) * (p.x - mx);
    syy += (p.y - my) * (p.y - my);
    sxy += (p.x - mx) * (p.y - my);
  }
  sxx /= (double)obj.size();
  syy /= (double)obj.size();
  sxy /= (double)obj.size();
  const double tr = sxx + syy, det = sxx * syy - sxy * sxy;
  const double lmin = tr / 2 - std::sqrt(std::max(0.0, tr * tr / 4 - det));
  return std::sqrt(std::max(0.0, lmin)) >= 0.25 * b->square_m;
}

void to_pose(const cv::Mat &rvec, const cv::Mat &tvec, double T[16]) {
  cv::Mat R;
  cv::Rodrigues(rvec, R);
  double Rd[9], t[3];
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) Rd[3 * r + c] = R.at<double>(r, c);
    t[r] = tvec.at<double>(r);
  }
  fg_pose_from_rotmat(Rd, t, T);
}

void split(const double T[16], cv::Mat *R, cv::Mat *t) {
  *R = (cv::Mat_<double>(3, 3) << T[0], T[1], T[2], T[4], T[5], T[6], T[8], T[9], T[10]);
  *t = (cv::Mat_<double>(3, 1) << T[3], T[7], T[11]);
}

int fail_cv(const char *what, const std::exception &e) {
  return fg_fail(FG_EINVAL, "%s: OpenCV: %s", what, e.what());
}

const char *const k_methods[FG_HAND_EYE_METHODS] = {"tsai", "park", "horaud", "andreff",
                                                    "daniilidis"};

// The mean of n poses (positions averaged, quaternions sign-aligned and averaged) and their
// RMS spread about it.
void mean_spread(const std::vector<std::vector<double>> &T, double mean[16], double *mm,
                 double *deg) {
  double p[3] = {0, 0, 0}, q[4] = {0, 0, 0, 0}, q0[4];
  for (size_t i = 0; i < T.size(); i++) {
    double pi[3], qi[4];
    fg_pose_to_quat(T[i].data(), pi, qi);
    if (i == 0) std::copy(qi, qi + 4, q0);
    const double s = qi[0] * q0[0] + qi[1] * q0[1] + qi[2] * q0[2] + qi[3] * q0[3] < 0 ? -1 : 1;
    for (int k = 0; k < 3; k++) p[k] += pi[k] / T.size();
    for (int k = 0; k < 4; k++) q[k] += s * qi[k];
  }
  const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (int k = 0; k < 4; k++) q[k] /= qn;
  fg_pose_from_quat(p, q, mean);
  double d2 = 0, a2 = 0;
  for (const std::vector<double> &t : T) {
    const double dx = t[3] - p[0], dy = t[7] - p[1], dz = t[11] - p[2];
    d2 += dx * dx + dy * dy + dz * dz;
    const double a = fg_pose_angle_rad(t.data(), mean);
    a2 += a * a;
  }
  *mm = std::sqrt(d2 / T.size()) * 1e3;
  *deg = std::sqrt(a2 / T.size()) * 180 / M_PI;
}

// Whether the tool's rotations between the poses make the hand-eye rotation observable: at
// least two relative rotations of 5 degrees or more about axes 15 degrees or more apart.
int observable(const double *T_base_tcp, int n) {
  std::vector<cv::Vec3d> axes;
  double largest = 0;
  for (int i = 0; i < n; i++)
    for (int j = i + 1; j < n; j++) {
      double Ti[16], rel[16], R[9], rv[3];
      fg_pose_inverse(T_base_tcp + 16 * i, Ti);
      fg_pose_compose(Ti, T_base_tcp + 16 * j, rel);
      fg_pose_get_rotmat(rel, R);
      fg_rotvec_from_rotmat(R, rv);
      const double a = std::sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]);
      largest = std::max(largest, a);
      if (a >= 5 * M_PI / 180) axes.emplace_back(rv[0] / a, rv[1] / a, rv[2] / a);
    }
  if (axes.size() < 2)
    return fg_fail(FG_EINVAL, "the robot's poses turn the tool by at most %.1f degrees from one "
                   "another: hand-eye calibration needs rotations of 5 degrees or more between "
                   "views (tilt the tool by 15 to 30 degrees about different axes)",
                   largest * 180 / M_PI);
  double widest = 0;
  for (size_t i = 0; i < axes.size(); i++)
    for (size_t j = i + 1; j < axes.size(); j++)
      widest = std::max(widest, std::acos(std::min(1.0, std::fabs(axes[i].dot(axes[j])))));
  if (widest < 15 * M_PI / 180)
    return fg_fail(FG_EINVAL, "every rotation between the robot's poses is about one axis "
                   "(within %.1f degrees): the hand-eye transform is then unobservable along "
                   "it; tilt the tool about a second axis too", widest * 180 / M_PI);
  return 0;
}

}  // namespace

extern "C" void fg_hand_eye_spread(const double *T_base_tcp, const double *T_cam_board, int n,
                                   int fixed, const double T[16], double T_fixed[16],
                                   double *spread_mm, double *spread_deg) {
  // each view's fixed frame: base->board (hand) or tcp->board (fixed)
  std::vector<std::vector<double>> fixed_T((size_t)n, std::vector<double>(16));
  for (int i = 0; i < n; i++) {
    double G[16], GX[16];
    if (fixed)
      fg_pose_inverse(T_base_tcp + 16 * i, G);
    else
      std::copy(T_base_tcp + 16 * i, T_base_tcp + 16 * i + 16, G);
    fg_pose_compose(G, T, GX);
    fg_pose_compose(GX, T_cam_board + 16 * i, fixed_T[(size_t)i].data());
  }
  mean_spread(fixed_T, T_fixed, spread_mm, spread_deg);
}

extern "C" const char *fg_hand_eye_method_name(int method) {
  return method >= 0 && method < FG_HAND_EYE_METHODS ? k_methods[method] : "?";
}

extern "C" int fg_calibrate_intrinsics(const fg_charuco_board *b, const fg_calib_view *views,
                                       int n, int w, int h, fg_intrinsics *out, double *rms_px,
                                       double *per_view_rms) {
  FG_TRY(fg_charuco_board_check(b));
  try {
    std::vector<std::vector<cv::Point3f>> obj;
    std::vector<std::vector<cv::Point2f>> img;
    std::vector<int> used;
    for (int i = 0; i < n; i++) {
      if (per_view_rms) per_view_rms[i] = NAN;
      if (views[i].n < FG_CALIB_MIN_CORNERS) continue;
      obj.emplace_back();
      img.emplace_back();
      view_points(b, &views[i], &obj.back(), &img.back());
      if (!spans_plane(b, obj.back())) {
        obj.pop_back();
        img.pop_back();
        continue;
      }
      used.push_back(i);
    }
    if ((int)used.size() < FG_CALIB_MIN_VIEWS_INTRINSICS)
      return fg_fail(FG_EINVAL, "%d of %d views show the board with %d corners or more, not "
                     "all on one line; intrinsics need %d such views", (int)used.size(), n,
                     FG_CALIB_MIN_CORNERS, FG_CALIB_MIN_VIEWS_INTRINSICS);
    cv::Mat K, D, std_in, std_ex, per_view;
    std::vector<cv::Mat> rvecs, tvecs;
    const double rms = cv::calibrateCamera(
        obj, img, cv::Size(w, h), K, D, rvecs, tvecs, std_in, std_ex, per_view,
        cv::CALIB_FIX_K3,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-12));
    out->w = w;
    out->h = h;
    out->fx = K.at<double>(0, 0);
    out->fy = K.at<double>(1, 1);
    out->cx = K.at<double>(0, 2);
    out->cy = K.at<double>(1, 2);
    for (int k = 0; k < 4; k++) out->k[k] = D.at<double>(k);
    *rms_px = rms;
    if (per_view_rms)
      for (size_t u = 0; u < used.size(); u++) per_view_rms[used[u]] = per_view.at<double>((int)u);
    if (!(std::isfinite(out->fx) && std::isfinite(out->fy) && out->fx > 0 && out->fy > 0))
      return fg_fail(FG_EINVAL, "the views do not determine the focal length (all views "
                     "of the board from one direction?); view it from several angles");
    return 0;
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "intrinsic calibration");
  } catch (const std::exception &e) {
    return fail_cv("intrinsic calibration", e);
  }
}

extern "C" int fg_calib_board_pose(const fg_charuco_board *b, const fg_calib_view *view,
                                   const fg_intrinsics *in, double T_cam_board[16],
                                   double *rms_px) {
  if (view->n < FG_CALIB_MIN_CORNERS)
    return fg_fail(FG_EINVAL, "%d board corners found; a pose needs %d", view->n,
                   FG_CALIB_MIN_CORNERS);
  try {
    std::vector<cv::Point3f> obj;
    std::vector<cv::Point2f> img;
    view_points(b, view, &obj, &img);
    if (!spans_plane(b, obj))
      return fg_fail(FG_EINVAL, "the %d board corners found lie on one line; a pose needs "
                     "them spread over the board", view->n);
    const cv::Mat K = camera_matrix(in), D = dist_coeffs(in);
    cv::Mat rvec, tvec;
    if (!cv::solvePnP(obj, img, K, D, rvec, tvec, false, cv::SOLVEPNP_IPPE))
      return fg_fail(FG_EINVAL, "no board pose fits the %d corners", view->n);
    cv::solvePnPRefineLM(obj, img, K, D, rvec, tvec);
    std::vector<cv::Point2f> back;
    cv::projectPoints(obj, rvec, tvec, K, D, back);
    double e2 = 0;
    for (size_t k = 0; k < back.size(); k++) {
      const cv::Point2f d = back[k] - img[k];
      e2 += d.dot(d);
    }
    *rms_px = std::sqrt(e2 / back.size());
    to_pose(rvec, tvec, T_cam_board);
    return 0;
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "board pose");
  } catch (const std::exception &e) {
    return fail_cv("board pose", e);
  }
}

extern "C" int fg_calibrate_hand_eye(const double *T_base_tcp, const double *T_cam_board, int n,
                                     int fixed, fg_hand_eye_result results[FG_HAND_EYE_METHODS],
                                     int *best) {
  if (n < FG_CALIB_MIN_VIEWS_HAND_EYE)
    return fg_fail(FG_EINVAL, "%d robot poses with a board pose; hand-eye calibration needs %d",
                   n, FG_CALIB_MIN_VIEWS_HAND_EYE);
  FG_TRY(observable(T_base_tcp, n));
  try {
    // the gripper's motion as OpenCV's calibrateHandEye takes it; for a fixed camera the
    // inverse robot poses, which makes its answer T_base_cam
    std::vector<cv::Mat> Rg, tg, Rc, tc;
    for (int i = 0; i < n; i++) {
      double G[16];
      if (fixed)
        fg_pose_inverse(T_base_tcp + 16 * i, G);
      else
        std::copy(T_base_tcp + 16 * i, T_base_tcp + 16 * i + 16, G);
      cv::Mat R, t;
      split(G, &R, &t);
      Rg.push_back(R);
      tg.push_back(t);
      split(T_cam_board + 16 * i, &R, &t);
      Rc.push_back(R);
      tc.push_back(t);
    }
    *best = -1;
    double best_score = INFINITY;
    for (int m = 0; m < FG_HAND_EYE_METHODS; m++) {
      fg_hand_eye_result *r = &results[m];
      *r = fg_hand_eye_result{};
      r->method = m;
      cv::Mat R, t;
      cv::calibrateHandEye(Rg, tg, Rc, tc, R, t, (cv::HandEyeCalibrationMethod)m);
      double Rd[9], td[3];
      int finite = 1;
      for (int k = 0; k < 9; k++) finite &= std::isfinite(Rd[k] = R.at<double>(k / 3, k % 3));
      for (int k = 0; k < 3; k++) finite &= std::isfinite(td[k] = t.at<double>(k));
      if (!finite) continue;
      fg_pose_from_rotmat(Rd, td, r->T);
      fg_hand_eye_spread(T_base_tcp, T_cam_board, n, fixed, r->T, r->T_fixed, &r->spread_mm,
                         &r->spread_deg);
      r->ok = 1;
      // 1 mm and 0.2 degrees weigh alike: the accuracy a grasp needs of either
      const double score = r->spread_mm + r->spread_deg / 0.2;
      if (score < best_score) {
        best_score = score;
        *best = m;
      }
    }
    if (*best < 0) return fg_fail(FG_EINVAL, "no hand-eye method found a solution");
    return 0;
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "hand-eye calibration");
  } catch (const std::exception &e) {
    return fail_cv("hand-eye calibration", e);
  }
}

namespace {

// The refinement's unknowns: the intrinsics (8, when refined), then small rotations and
// translations of the mount and of the fixed frame about where they started.
struct refine_problem {
  const fg_charuco_board *b;
  const fg_calib_view *views;
  const double *T_base_tcp;
  int n, fixed, with_in;
  fg_intrinsics in0;
  double X0[16], B0[16];
};

void apply_delta(const double T0[16], const double *d, double T[16]) {
  double R[9], D[16];
  const double t[3] = {d[3], d[4], d[5]};
  fg_rotmat_from_rotvec(d, R);
  fg_pose_from_rotmat(R, t, D);
  fg_pose_compose(T0, D, T);
}

void unpack(const refine_problem &p, const std::vector<double> &x, fg_intrinsics *in, double X[16],
            double B[16]) {
  *in = p.in0;
  size_t o = 0;
  if (p.with_in) {
    in->fx = x[0];
    in->fy = x[1];
    in->cx = x[2];
    in->cy = x[3];
    for (int k = 0; k < 4; k++) in->k[k] = x[4 + k];
    o = 8;
  }
  apply_delta(p.X0, &x[o], X);
  apply_delta(p.B0, &x[o + 6], B);
}

// Every corner's reprojection error (u and v), in view order.
void residuals(const refine_problem &p, const std::vector<double> &x, std::vector<double> *r) {
  fg_intrinsics in;
  double X[16], B[16], Xi[16];
  unpack(p, x, &in, X, B);
  fg_pose_inverse(X, Xi);
  const cv::Mat K = camera_matrix(&in), D = dist_coeffs(&in);
  r->clear();
  for (int i = 0; i < p.n; i++) {
    // hand: cam <- tcp <- base <- board; fixed: cam <- base <- tcp <- board
    double G[16], XG[16], T_cb[16];
    if (p.fixed)
      std::copy(p.T_base_tcp + 16 * i, p.T_base_tcp + 16 * i + 16, G);
    else
      fg_pose_inverse(p.T_base_tcp + 16 * i, G);
    fg_pose_compose(Xi, G, XG);
    fg_pose_compose(XG, B, T_cb);
    std::vector<cv::Point3f> obj;
    std::vector<cv::Point2f> img, back;
    view_points(p.b, &p.views[i], &obj, &img);
    if (obj.empty()) continue;
    double Rd[9];
    fg_pose_get_rotmat(T_cb, Rd);
    cv::Mat R = (cv::Mat_<double>(3, 3) << Rd[0], Rd[1], Rd[2], Rd[3], Rd[4], Rd[5], Rd[6],
                 Rd[7], Rd[8]);
    cv::Mat rvec, tvec = (cv::Mat_<double>(3, 1) << T_cb[3], T_cb[7], T_cb[11]);
    cv::Rodrigues(R, rvec);
    cv::projectPoints(obj, rvec, tvec, K, D, back);
    for (size_t k = 0; k < back.size(); k++) {
      r->push_back(back[k].x - img[k].x);
      r->push_back(back[k].y - img[k].y);
    }
  }
}

double cost(const std::vector<double> &r) {
  double c = 0;
  for (double v : r) c += v * v;
  return c;
}

}  // namespace

extern "C" int fg_calibrate_hand_eye_refine(const fg_charuco_board *b, const fg_calib_view *views,
                                            const double *T_base_tcp, int n, int fixed,
                                            int refine_intrinsics, fg_intrinsics *in,
                                            double T[16], double T_fixed[16], double *rms_px) {
  try {
    refine_problem p{b, views, T_base_tcp, n, fixed, refine_intrinsics, *in, {}, {}};
    std::copy(T, T + 16, p.X0);
    std::copy(T_fixed, T_fixed + 16, p.B0);
    std::vector<double> x(refine_intrinsics ? 20 : 12, 0.0);
    if (refine_intrinsics) {
      const double v[8] = {in->fx, in->fy, in->cx, in->cy, in->k[0], in->k[1], in->k[2], in->k[3]};
      std::copy(v, v + 8, x.begin());
    }
    std::vector<double> r, r_try;
    residuals(p, x, &r);
    if (r.size() < x.size() * 2)
      return fg_fail(FG_EINVAL, "%zu corners: too few to refine %zu unknowns", r.size() / 2,
                     x.size());
    double c = cost(r), lambda = 1e-3;
    // finite-difference steps: pixels and distortion per unit, radians and metres
    std::vector<double> h(x.size(), 1e-7);
    if (refine_intrinsics) {
      for (int k = 0; k < 4; k++) h[(size_t)k] = 1e-4;
      for (int k = 4; k < 8; k++) h[(size_t)k] = 1e-7;
    }
    const int m = (int)x.size();
    for (int it = 0; it < 100; it++) {
      cv::Mat J((int)r.size(), m, CV_64F);
      for (int j = 0; j < m; j++) {
        std::vector<double> xp = x;
        xp[(size_t)j] += h[(size_t)j];
        residuals(p, xp, &r_try);
        for (int k = 0; k < (int)r.size(); k++)
          J.at<double>(k, j) = (r_try[(size_t)k] - r[(size_t)k]) / h[(size_t)j];
      }
      const cv::Mat R(r, false);
      cv::Mat JtJ = J.t() * J, Jtr = J.t() * R;
      int improved = 0;
      for (int tries = 0; tries < 10 && !improved; tries++) {
        cv::Mat A = JtJ.clone();
        for (int j = 0; j < m; j++) A.at<double>(j, j) *= 1 + lambda;
        cv::Mat step;
        if (!cv::solve(A, -Jtr, step, cv::DECOMP_CHOLESKY)) cv::solve(A, -Jtr, step, cv::DECOMP_SVD);
        std::vector<double> xt = x;
        for (int j = 0; j < m; j++) xt[(size_t)j] += step.at<double>(j);
        residuals(p, xt, &r_try);
        const double ct = cost(r_try);
        if (ct < c) {
          const double gain = c - ct;
          x = xt;
          r = r_try;
          c = ct;
          lambda = std::max(lambda / 10, 1e-12);
          improved = 1;
          if (gain < 1e-12 * c) it = 100;
        } else {
          lambda *= 10;
        }
      }
      if (!improved) break;
    }
    unpack(p, x, in, T, T_fixed);
    *rms_px = std::sqrt(c / (r.size() / 2.0));
    return 0;
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "hand-eye refinement");
  } catch (const std::exception &e) {
    return fail_cv("hand-eye refinement", e);
  }
}
