// The plausible range of every number of a model file: the readers (YAML, URDF, the
// joint-space terms, the residual layer) refuse a value outside it with the file and line, so that
// a model read is one whose predictions are finite (docs/file_formats.md, "Ranges").
#ifndef LPOE_MODEL_LIMITS_H_
#define LPOE_MODEL_LIMITS_H_

namespace lpoe {

// Lengths (mm): joint and tool origins, the registration, twists, limits, the payload's centre.
constexpr double kMaxModelLengthMm = 1e5;
// Angles given as roll, pitch, yaw (rad).
constexpr double kMaxModelAngleRad = 100;
// Gravity's magnitude (m/s^2) and the payload's mass (kg).
constexpr double kMaxModelGravity = 100;
constexpr double kMaxModelPayloadKg = 1e4;
// Any number of a joint-space term's block, as read; and the largest joint offset the terms may
// add at any configuration within the limits (rad for a revolute joint, mm for a prismatic one).
constexpr double kMaxJointTermValue = 1e9;
constexpr double kMaxJointTermOffset = 0.2;
constexpr double kMaxJointTermOffsetMm = 20;
// The residual layer: length scales (rad or mm), standard deviations (mm), inducing inputs (count;
// the variance matrix is count^2 numbers), joint values of the inducing inputs, and the largest
// correction or variance its weights can add (|w| s_f^2 in mm, |W| s_f^4 in mm^2).
constexpr double kMinLayerLengthScale = 1e-6;
constexpr double kMaxLayerLengthScale = 1e6;
constexpr double kMinLayerStd = 1e-9;
constexpr double kMaxLayerStd = 1e3;
constexpr int kMaxLayerInducing = 4096;
constexpr double kMaxLayerJointValue = 1e4;
constexpr double kMaxLayerWeightMm = 1e6;
constexpr double kMaxLayerVarianceMm2 = 1e12;

}  // namespace lpoe

#endif  // LPOE_MODEL_LIMITS_H_
