// Measurement kind "distance": a ballbar measures the distance between the centre of the ball on
// the tool (a tool's origin, as a tracker's SMR) and a fixed pivot whose position is unknown
// (docs/measurements.md).
//
//   prediction   d_model = |P(q) - c_pivot|,   P(q) = T_0,1(0) exp(s_1^ q_1) ... p_tool
//   residual     r = (d_model - d_measured) * inverse_sigma              (1 row, autodiff path)
//   linearized   dr/dx_frames = u^T dP/dx,  dr/dc = -u^T,  u = (P - c) / |P - c|
//
// The pivot is a parameter block of 3 (mm, the robot's base frame). Identifiability: moving the
// robot's base together with every pivot by one rigid motion changes no distance, so the data do
// not see the base's pose relative to the pivots: six directions the calibration leaves out
// (docs/identifiability.md). The robot's scale is seen (a distance is a length).
#ifndef LPOE_DISTANCE_MEASUREMENT_H_
#define LPOE_DISTANCE_MEASUREMENT_H_

#include <cmath>

#include <Eigen/Core>

#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/position_measurement.h"

namespace lpoe {

struct DistanceMeasurement {
  static constexpr int kResiduals = 1;
  static constexpr int kFeatureSize = 3;
  static constexpr int kFeatureTangent = 3;  // the pivot's local coordinates: its xyz
  static constexpr MeasurementKindId kKind = MeasurementKindId::kDistance;
  using Observation = double;  // the measured distance (mm)
  static constexpr const char* kLeftOutReason =
      "ballbar distances do not see the robot's base relative to the pivots (moving the base with "
      "every pivot leaves every distance unchanged): not identified, kept as given";

  double inverse_sigma = 1.0;

  template <typename T>
  static T Error(const Vector3<T>& P, const T* pivot, double distance) {
    const Vector3<T> d(P(0) - pivot[0], P(1) - pivot[1], P(2) - pivot[2]);
    using std::sqrt;
    return sqrt(d.squaredNorm()) - T(distance);
  }

  // Blocks: the n joint frames and the tool's frame (7 numbers each, position_measurement.h), then
  // the pivot (3).
  template <typename T, typename Motions>
  void Residual(int n, T const* const* blocks, const Motions& motions, const Observation& measured,
                T* r) const {
    const Vector3<T> P = PositionMeasurement::Predict<T>(n, blocks, motions);
    r[0] = Error<T>(P, blocks[n + 1], measured) * T(inverse_sigma);
  }

  // Analytic path: P and its frame Jacobian dP/dx (3 x cols, column-major, leading dimension 3,
  // from BasisJacobian::Position) give the whitened residual (returned), its frame row (cols) and
  // its pivot row (3).
  double Linearize(const Eigen::Vector3d& P, const double* J_p, int cols, const double* pivot,
                   const Observation& measured, double* row, double* feature_row) const {
    const Eigen::Vector3d d = P - Eigen::Vector3d(pivot[0], pivot[1], pivot[2]);
    const double length = d.norm();
    const Eigen::Vector3d u = length > 0 ? Eigen::Vector3d(d / length) : Eigen::Vector3d::Zero();
    for (int c = 0; c < cols; ++c) {
      row[c] = inverse_sigma * (u(0) * J_p[3 * c] + u(1) * J_p[3 * c + 1] + u(2) * J_p[3 * c + 2]);
    }
    for (int k = 0; k < 3; ++k) feature_row[k] = -inverse_sigma * u(k);
    return (length - measured) * inverse_sigma;
  }

  // The residual layer's projected observation (docs/residual_layer.md, "Projected observations"):
  // |P + m - c| - d ~ |P - c| - d + u . m, so the row sees u . m = -error along the unit u. False
  // when u is not defined (the ball at its pivot).
  static bool Projection(const Eigen::Vector3d& P, const double* pivot, double distance,
                         Eigen::Vector3d* u, double* error) {
    const Eigen::Vector3d d = P - Eigen::Vector3d(pivot[0], pivot[1], pivot[2]);
    const double length = d.norm();
    if (!(length > 0)) return false;
    *u = d / length;
    *error = length - distance;
    return true;
  }

  // Simulation: what the bar reads with the ball at P (before noise).
  static double Simulate(const Eigen::Vector3d& P, const Eigen::Vector3d& pivot) {
    return (P - pivot).norm();
  }
};

}  // namespace lpoe

#endif  // LPOE_DISTANCE_MEASUREMENT_H_
