// Measurement kind "plane": a touch probe's tip (a ball of radius r on a tool's origin) touches a
// plane whose position is unknown (a face of a reference cube, a plate) (docs/measurements.md).
//
//   feature      [nx ny nz d]: the points x of the plane satisfy n.x = d, |n| = 1, n pointing to
//                the side the probe comes from (outward from the artefact)
//   prediction   the signed distance of the tip's centre from the plane, n.P(q) - d
//   residual     r = (n.P(q) - d - offset) * inverse_sigma       (offset: the tip's radius)
//   linearized   dr/dx_frames = n^T dP/dx,  dr/da = P^T B(n) (n <- n + B(n) a, B(n) an orthonormal
//                basis of n's tangent plane: PlaneTangentBasis),  dr/dd = -1
//
// Ceres keeps n on the unit sphere (SphereManifold x Euclidean offset); the linear solver steps in
// the 2 + 1 local coordinates above and renormalizes n. Identifiability: moving the base with every
// plane changes no contact (six directions left out); and with planes alone the robot's scale is not
// determined: scaling the robot and every plane's d together (d -> s d + (s - 1) offset) leaves every
// residual unchanged as long as each plane is touched with one offset, and nearly so otherwise. A
// calibration from planes alone holds the scale (docs/identifiability.md, "Scale").
#ifndef LPOE_PLANE_MEASUREMENT_H_
#define LPOE_PLANE_MEASUREMENT_H_

#include <cmath>

#include <Eigen/Core>

#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/position_measurement.h"

namespace lpoe {

// An orthonormal basis (3 x 2) of the plane orthogonal to the unit vector n, built from the
// coordinate axis least aligned with n (well conditioned for every n).
inline Eigen::Matrix<double, 3, 2> PlaneTangentBasis(const Eigen::Vector3d& n) {
  int k = 0;
  n.cwiseAbs().minCoeff(&k);
  const Eigen::Vector3d e = Eigen::Vector3d::Unit(k);
  const Eigen::Vector3d a = (e - n.dot(e) * n).normalized();
  Eigen::Matrix<double, 3, 2> B;
  B.col(0) = a;
  B.col(1) = n.cross(a);
  return B;
}

struct PlaneMeasurement {
  static constexpr int kResiduals = 1;
  static constexpr int kFeatureSize = 4;    // ambient: n (3), d
  static constexpr int kFeatureTangent = 3;  // local: 2 on the sphere, d
  static constexpr MeasurementKindId kKind = MeasurementKindId::kPlane;
  using Observation = double;  // the offset of the tip's centre from the plane (mm)
  static constexpr const char* kLeftOutReason =
      "probe contacts do not see the robot's base relative to the touched planes (moving the base "
      "with every plane leaves every contact unchanged): not identified, kept as given";

  double inverse_sigma = 1.0;

  template <typename T>
  static T Error(const Vector3<T>& P, const T* plane, double offset) {
    return plane[0] * P(0) + plane[1] * P(1) + plane[2] * P(2) - plane[3] - T(offset);
  }

  // Blocks: the n joint frames and the tool's frame (7 numbers each), then the plane (4).
  template <typename T, typename Motions>
  void Residual(int n, T const* const* blocks, const Motions& motions, const Observation& offset,
                T* r) const {
    const Vector3<T> P = PositionMeasurement::Predict<T>(n, blocks, motions);
    r[0] = Error<T>(P, blocks[n + 1], offset) * T(inverse_sigma);
  }

  // Analytic path (see DistanceMeasurement::Linearize): feature_row has 3 entries, the two tangent
  // directions PlaneTangentBasis(n) and d.
  double Linearize(const Eigen::Vector3d& P, const double* J_p, int cols, const double* plane,
                   const Observation& offset, double* row, double* feature_row) const {
    const Eigen::Vector3d n(plane[0], plane[1], plane[2]);
    for (int c = 0; c < cols; ++c) {
      row[c] = inverse_sigma * (n(0) * J_p[3 * c] + n(1) * J_p[3 * c + 1] + n(2) * J_p[3 * c + 2]);
    }
    const Eigen::Matrix<double, 3, 2> B = PlaneTangentBasis(n);
    feature_row[0] = inverse_sigma * P.dot(B.col(0));
    feature_row[1] = inverse_sigma * P.dot(B.col(1));
    feature_row[2] = -inverse_sigma;
    return (n.dot(P) - plane[3] - offset) * inverse_sigma;
  }

  // The plane after a local step (a1, a2, dd): n <- normalize(n + B(n) a), d <- d + dd.
  static void Plus(const double* plane, const double* step, double* out) {
    const Eigen::Vector3d n(plane[0], plane[1], plane[2]);
    const Eigen::Matrix<double, 3, 2> B = PlaneTangentBasis(n);
    const Eigen::Vector3d m = (n + B * Eigen::Vector2d(step[0], step[1])).normalized();
    out[0] = m(0);
    out[1] = m(1);
    out[2] = m(2);
    out[3] = plane[3] + step[2];
  }

  // The residual layer's projected observation (see DistanceMeasurement::Projection): the contact
  // sees n . m = -error along the plane's normal.
  static bool Projection(const Eigen::Vector3d& P, const double* feature, double offset,
                         Eigen::Vector3d* u, double* error) {
    const Eigen::Vector4d plane(feature[0], feature[1], feature[2], feature[3]);
    *u = plane.head<3>();
    *error = plane.head<3>().dot(P) - plane(3) - offset;
    return true;
  }

  // Simulation: the offset measured with the tip's centre at P (before noise): its signed distance.
  static double Simulate(const Eigen::Vector3d& P, const Eigen::Vector4d& plane) {
    return plane.head<3>().dot(P) - plane(3);
  }
};

}  // namespace lpoe

#endif  // LPOE_PLANE_MEASUREMENT_H_
