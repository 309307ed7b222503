// Calibration from ballbar distances and touch-probe plane contacts, alone or with tracker
// positions (docs/measurements.md, docs/identifiability.md "Distances and planes"). The robot's
// local frames are estimated as in every calibration (the identifiable frame blocks of
// parameterization.h, position data: the tools' rotations are never seen) together with the
// features the rows refer to: one block of 3 per ballbar pivot, one block per plane (a unit normal
// on the sphere and an offset). Both solvers minimise the same whitened cost:
//
//   CalibrateContactsLinear  Levenberg-Marquardt on the analytic rows (Linearize of the kinds;
//                            a plane steps in 2 + 1 local coordinates)
//   CalibrateContactsCeres   Ceres on the kinds' templated residuals (autodiff; Se3Manifold on the
//                            frames, SphereManifold x Euclidean on a plane)
//
// What the data cannot determine is decided from the data (MakeContactParameterization): the null
// space of the column-scaled Jacobian at the start (with the scale hold's row when the scale is
// held) is left out from the base: the first joint frame's directions it moves, then what is left
// (the first joint's zero and height) held on the features by linear rows (gauge_rows), so that
// both solvers minimise the same constrained cost whatever path they take. With no row that
// measures a length (planes alone) the robot's scale is held at the start model's (a Gaussian
// prior of standard deviation `scale_sigma` on ScaleOf, the predicted points' size, which the
// general prior on parameters can carry once it exists; docs/identifiability.md, "Scale").
#ifndef LPOE_CONTACT_CALIBRATION_H_
#define LPOE_CONTACT_CALIBRATION_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct ContactFeatures {
  std::vector<Eigen::Vector3d> pivots;  // mm, the model's base frame
  std::vector<Eigen::Vector4d> planes;  // [nx ny nz d], n.x = d, |n| = 1
  // The joint-space terms' values theta (ambient, term->num_parameters() each), one per
  // ContactParameterization::frames.joint_blocks; missing or empty: zero. Not features of the
  // workcell, but state the solvers carry with them (the predictions use q_eff, joint_term.h).
  std::vector<Eigen::VectorXd> joint_theta;
};

enum class ScaleHold { kAuto, kOn, kOff };
// "auto", "on", "off".
bool ParseScaleHold(const std::string& text, ScaleHold* hold);

struct ContactCalibrationOptions {
  int max_iterations = 100;
  // Stop when a Gauss-Newton step promises (linear solver) or makes (Ceres) a decrease of less
  // than this fraction of the cost.
  double function_tolerance = 1e-12;
  // kAuto: hold the scale when no row measures a length (planes alone).
  ScaleHold hold_scale = ScaleHold::kAuto;
  // The hold as a prior: standard deviation of the scale functional S (relative; 1e-6 holds it to
  // a micrometre per metre).
  double scale_sigma = 1e-6;
  // A singular value of the column-scaled Jacobian below this fraction of the largest is a null
  // direction (the rigid motions are exactly null: their singular values are round-off).
  double null_tolerance = 1e-8;
  // Joint-space terms (joint_term.h, MakeJointTerm on the nominal model), one block each after the
  // frame blocks. Each is reduced to the combinations the data separate from the frames, the
  // pivots and planes and the earlier terms (as the tracker solvers do: the Schur complement in the
  // column-scaled normal matrix at the start, kept when its scaled singular value is at least
  // joint_term_tolerance); the rest is listed in frames.unidentifiable with the reason.
  std::vector<std::shared_ptr<const JointTerm>> joint_terms;
  double joint_term_tolerance = 1e-4;
};

// The calibration's unknowns: the frame blocks (with the directions left out and why) and the
// joint-space blocks (frames.joint_blocks, after the frame columns), then the pivots (3 each),
// then the planes (3 local coordinates each).
struct ContactParameterization {
  Parameterization frames;
  int num_pivots = 0;
  int num_planes = 0;
  int pivot_offset = 0;
  int plane_offset = 0;
  int num_parameters = 0;
  bool scale_held = false;
  Eigen::Matrix3Xd scale_weights;  // ScaleWeights of the nominal model and the data, when held
  std::string scale_reason;  // why the scale is held or seen
  int num_base_directions = 0;  // directions left out or held because the base is not seen
  std::string base_reason;
  // The base's directions that frame blocks cannot leave out path-independently (the first joint's
  // zero and height, which the identifiable parameterization carries in the second frame) are held
  // on the features instead: linear functions of the features' ambient values (pivots' xyz,
  // planes' [n d], in that order), gauge_rows * f = gauge_values, as rows of weight
  // 1 / gauge_sigma (mm) -- a prior of the same form as the scale hold's.
  Eigen::MatrixXd gauge_rows;   // k x (3 pivots + 4 planes)
  Eigen::VectorXd gauge_values;
  double gauge_sigma = 1e-6;
  int num_gauge_rows() const { return static_cast<int>(gauge_rows.rows()); }
};

struct ContactCalibrationResult {
  bool ok = false;
  std::string message;
  std::string solver;  // "linear", "ceres"
  RobotModel model;
  ContactFeatures features;
  ContactParameterization parameterization;
  int iterations = 0;
  double initial_cost = 0;
  double cost = 0;
  std::vector<double> errors;  // per row: mm (distance, plane: signed; position: |e|)
  // The joint-space terms' identified values (also in model.joint_errors, with the nominal
  // model's joint origins as regressor_origins: predicting with `model` reproduces the residuals).
  std::vector<JointTermValues> joint_terms;
  double scale = 1;            // ScaleOf(model, nominal, data)
};

// The features fitted to the start model's predictions: a sphere per pivot (its rows' distances),
// a plane per plane (the centroid and the least-spread direction of its points, oriented towards
// the robot's base, d set by the rows' offsets). Fails when a pivot has fewer than 4 rows or a
// plane fewer than 3, or their points are degenerate.
Status InitialContactFeatures(const RobotModel& model, const ContactMeasurementSet& data,
                              ContactFeatures* features);

// The start both contact solvers share: a result named after `solver` at the nominal model, the
// features' initial values and the parameterization decided from the data. False, with the
// reason in result->message, when either cannot be made.
bool StartContactCalibration(const RobotModel& nominal, const ContactMeasurementSet& data,
                             const ContactCalibrationOptions& options, const char* solver,
                             ContactCalibrationResult* result);

// The scale functional: the size of the robot as seen at the rows' configurations, relative to
// the nominal model's,
//   S(model) = sum_j (Pn_j - mean Pn) . P_j / sum_j |Pn_j - mean Pn|^2
// with P_j, Pn_j the rows' predicted tool points on `model` and `nominal`: 1 for the nominal
// model, s for the nominal scaled by s. A function of the predictions (not of how the frames
// represent them), so the hold is the same constraint for every solver whatever path it takes
// through the frames' equivalent representations.
double ScaleOf(const RobotModel& model, const RobotModel& nominal,
               const ContactMeasurementSet& data);
// The weights (Pn_j - mean Pn) / sum_j |Pn_j - mean Pn|^2 of S, one column per row.
Eigen::Matrix3Xd ScaleWeights(const RobotModel& nominal, const ContactMeasurementSet& data);

// Decides the parameterization from the data (see the file comment).
Status MakeContactParameterization(const RobotModel& model, const ContactFeatures& features,
                                   const ContactMeasurementSet& data,
                                   const ContactCalibrationOptions& options,
                                   ContactParameterization* p);

// The whitened residuals (rows in order: 1 per distance or plane row, 3 per position row; then the
// gauge rows on the features; then the scale hold's row when held) and, when J is not null, their
// Jacobian in p's coordinates. (`nominal` is not used: the scale hold's weights are in p.)
void ContactLinearize(const RobotModel& model, const ContactFeatures& features,
                      const ContactParameterization& p, const RobotModel& nominal,
                      const ContactMeasurementSet& data, const ContactCalibrationOptions& options,
                      Eigen::VectorXd* r, Eigen::MatrixXd* J);

// Per row, mm (see ContactCalibrationResult::errors); at q_eff when `model` carries joint errors,
// plus the correction of a residual layer it carries (at the commanded q, as PredictToolPosition).
std::vector<double> ContactErrors(const RobotModel& model, const ContactFeatures& features,
                                  const ContactMeasurementSet& data);

// The features' ambient values in the order of ContactParameterization::gauge_rows.
Eigen::VectorXd FeatureVector(const ContactFeatures& features);

// The features after a step of p's feature coordinates and joint-space blocks (x has
// p.num_parameters entries).
void ApplyFeatureStep(const ContactParameterization& p, const Eigen::VectorXd& x,
                      ContactFeatures* features);

// The result's joint_terms from features.joint_theta, stored in result->model.joint_errors with
// `nominal`'s joint origins (the geometry the terms' regressors were evaluated on).
void StoreContactJointTerms(const ContactParameterization& p, const ContactFeatures& features,
                            const RobotModel& nominal, ContactCalibrationResult* result);
// The end both contact solvers share, at the solution in result->model and result->features: the
// joint terms stored (StoreContactJointTerms), the rows' errors (ContactErrors) and the scale
// (ScaleOf against `nominal`).
void FinishContactCalibration(const RobotModel& nominal, const ContactMeasurementSet& data,
                              ContactCalibrationResult* result);

ContactCalibrationResult CalibrateContactsLinear(const RobotModel& nominal,
                                                 const ContactMeasurementSet& data,
                                                 const ContactCalibrationOptions& options);
ContactCalibrationResult CalibrateContactsCeres(const RobotModel& nominal,
                                                const ContactMeasurementSet& data,
                                                const ContactCalibrationOptions& options);

}  // namespace lpoe

#endif  // LPOE_CONTACT_CALIBRATION_H_
