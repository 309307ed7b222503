// The gravity tilt as a block kind (block_kind.h; docs/joint_errors.md, "Gravity tilt"): a
// bilinear effect with the compliance term (GravityTiltModel, lpoe/terms/joint_errors.h), whose
// blocks and columns BilinearBlockKind takes from the effect; here its result and its rule.
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

#include "calibration/block_kind.h"
#include "lpoe/terms/joint_errors.h"

namespace lpoe {
namespace internal {
namespace {

// The tilt's block of p, nullptr without one.
const BilinearBlock* TiltBlock(const Parameterization& p) {
  for (const BilinearBlock& b : p.bilinear_blocks) {
    if (std::string(b.effect->name()) == kGravityTiltName) return &b;
  }
  return nullptr;
}

class GravityTiltKind : public BilinearBlockKind {
 public:
  const char* name() const override { return kGravityTiltName; }
  const char* description() const override { return "gravity tilt"; }
  const char* partner_term() const override { return "compliance"; }
  const char* needs_partner_message() const override { return kGravityTiltNeedsCompliance; }

  // The solved tilt at the joint-space coordinates, with standard deviations from `covariance`.
  void FillResult(const Parameterization& p, const Eigen::VectorXd& joint_state,
                  const Eigen::MatrixXd& covariance, CalibrationResult* result) const override {
    const BilinearBlock* block = TiltBlock(p);
    if (block == nullptr) return;
    const auto& tilt = static_cast<const GravityTiltModel&>(*block->effect);
    GravityTiltResult* out = &result->gravity_tilt;
    const int t0 = block->offset - p.num_frame_parameters();
    out->identified = true;
    out->tilt = joint_state.size() > 0 ? Eigen::Vector2d(joint_state.segment<2>(t0))
                                       : Eigen::Vector2d::Zero();
    out->axes = tilt.axes();
    out->gravity_before = tilt.gravity();
    out->gravity_after = tilt.Tilted(out->tilt.data());
    out->standard_deviation.setZero();
    if (covariance.rows() == p.num_parameters) {
      for (int a = 0; a < 2; ++a) {
        out->standard_deviation(a) =
            std::sqrt(std::max(0.0, covariance(block->offset + a, block->offset + a)));
      }
    }
    out->message.clear();
  }

  void ScaleToAPosteriori(double factor, CalibrationResult* result) const override {
    GravityTiltResult& t = result->gravity_tilt;
    if (!(t.standard_deviation.maxCoeff() > 0)) return;
    t.a_priori_standard_deviation = t.standard_deviation;
    t.standard_deviation *= factor;
  }

  // Identifiable when the smallest kept fraction is at least `tolerance` (the joint terms' rule)
  // and each angle's standard deviation (noise estimated from r0's residuals) is at most
  // `max_sigma` (rad). Fills kept_fraction, predicted_standard_deviation, axes, gravity_before
  // and, when not identifiable, message.
  bool Identifiable(const RobotModel& start, const MeasurementSet& data,
                    const CalibrationResult& r0, bool use_orientation, double orientation_weight,
                    double tolerance, double max_sigma, CalibrationResult* result) const override {
    GravityTiltResult* out = &result->gravity_tilt;
    out->requested = true;
    auto tilt = std::make_shared<const GravityTiltModel>(start);
    out->axes = tilt->axes();
    out->gravity_before = tilt->gravity();
    out->gravity_after = tilt->gravity();
    auto refuse = [&](const std::string& why) {
      out->message =
          "gravity tilt not identifiable from these data; kept at the model's gravity (" + why +
          ")";
      return false;
    };
    Eigen::MatrixXd C;
    const Status s = BilinearInformation(tilt, data, r0, use_orientation, orientation_weight,
                                         &out->kept_fraction, &C);
    if (!s.ok()) return refuse(s.message());
    if (out->kept_fraction >= tolerance && C.rows() == 2) {
      out->predicted_standard_deviation << std::sqrt(C(0, 0)), std::sqrt(C(1, 1));
    } else {
      out->predicted_standard_deviation.setConstant(INFINITY);
    }
    std::ostringstream why;
    constexpr double kDeg = 180.0 / M_PI;
    if (out->kept_fraction < tolerance) {
      why << "its effect is not separable from the geometry and the other terms: kept fraction "
          << out->kept_fraction << " < " << tolerance;
      return refuse(why.str());
    }
    const double worst = out->predicted_standard_deviation.maxCoeff();
    if (!(worst <= max_sigma)) {
      why << "the compliance torques at these poses determine it only to " << worst * kDeg
          << " deg (1 sigma), above the limit of " << max_sigma * kDeg << " deg";
      return refuse(why.str());
    }
    out->message.clear();
    return true;
  }

  std::shared_ptr<const BilinearJointEffect> MakeEffect(const RobotModel& start) const override {
    return std::make_shared<const GravityTiltModel>(start);
  }

  // The check's analysis (kept fraction, predicted standard deviations, axes, gravity before)
  // with the solve's tilt, standard deviations and gravity after.
  void Record(const CalibrationResult& check, const CalibrationResult* solved,
              const std::string& why_not, CalibrationResult* out) const override {
    GravityTiltResult entry = check.gravity_tilt;
    if (!why_not.empty()) entry.message = why_not + "; kept at the model's gravity";
    if (solved != nullptr) {
      const GravityTiltResult& s = solved->gravity_tilt;
      entry.identified = true;
      entry.tilt = s.tilt;
      entry.standard_deviation = s.standard_deviation;
      entry.a_priori_standard_deviation = s.a_priori_standard_deviation;
      entry.gravity_after = s.gravity_after;
      entry.message.clear();
    }
    out->gravity_tilt = entry;
  }

  void ApplyToModel(const CalibrationResult& result, RobotModel* model) const override {
    if (result.gravity_tilt.identified) model->gravity = result.gravity_tilt.gravity_after;
  }

  bool Identified(const CalibrationResult& result, std::string* why_not) const override {
    if (why_not != nullptr && !result.gravity_tilt.identified) {
      *why_not = !result.gravity_tilt.message.empty()
                     ? result.gravity_tilt.message
                     : "gravity tilt not identifiable from these data; kept at the model's gravity "
                       "(the compliance calibration did not converge: " +
                           result.message + ")";
    }
    return result.gravity_tilt.identified;
  }
};

}  // namespace

const BlockKind& GravityTiltBlockKind() {
  static const GravityTiltKind kind;
  return kind;
}

}  // namespace internal
}  // namespace lpoe
