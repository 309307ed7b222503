// The `covariance:` block of a calibrated model's YAML (docs/file_formats.md, docs/recalibration.md):
// the estimate's covariance per local frame, of its deviation xi = log(T_ref^-1 T) = (omega rad,
// v mm) in the frame's own coordinates (6x6), and per joint-space term of its values (P x P). A
// model's readers (ReadRobotModel) accept the block and leave it; ReadModelCovariance reads it
// strictly (the prior of a recalibration, lpoe/recalibration.h).
#ifndef LPOE_MODEL_COVARIANCE_H_
#define LPOE_MODEL_COVARIANCE_H_

#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct ModelCovariance {
  // Per local frame (joints, then tools), 6x6; a zero-size matrix for a frame the block omits.
  std::vector<Eigen::MatrixXd> frames;
  // Per joint-space term listed: its registry name and P x P covariance.
  std::vector<std::string> term_names;
  std::vector<Eigen::MatrixXd> terms;
  // How many models the block was estimated from (1: a calibration's own estimate; a fleet: its
  // robots).
  int models = 1;
  // The data's standard deviation per axis (mm) the estimate was weighed with (its residuals'); 0:
  // not known. A recalibration weighs its prior against it (few new rows cannot estimate it).
  double data_sigma = 0;
};

// The block's text (ending in a newline), frames named after `model`'s joints and tools.
std::string ModelCovarianceYaml(const RobotModel& model, const ModelCovariance& covariance);

// Reads the block of the model file `path` (already read as `model`): every listed frame a frame
// of the model, at most once, 36 finite numbers, symmetric (1e-9 relative) and positive
// semi-definite; terms by registry name with P*P numbers. Errors name the file and line. A file
// without the block is an error ("no covariance block").
Status ReadModelCovariance(const std::string& path, const RobotModel& model, ModelCovariance* out);

}  // namespace lpoe

#endif  // LPOE_MODEL_COVARIANCE_H_
