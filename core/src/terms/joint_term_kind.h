// A registry entry of a joint-space term (lpoe/terms/joint_term.h): everything the library knows about one
// term, in the term's own source file. The registry (joint_term_registry.inc) lists the entries; the
// rest of the library reaches them through joint_term.h's name-based functions, through
// JointErrorOffsets (prediction) and through the YAML reader and writer (joint_errors_yaml.cc).
//
// Adding a term: one source file in core/src that defines a JointTermKind and a function returning
// it, plus one line in joint_term_registry.inc (see gear_ratio_term.cc for a short example).
#ifndef LPOE_CORE_SRC_JOINT_TERM_KIND_H_
#define LPOE_CORE_SRC_JOINT_TERM_KIND_H_

#include <yaml-cpp/yaml.h>

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace internal {

class JointErrorsYamlReader;  // joint_errors_yaml.h

class JointTermKind {
 public:
  virtual ~JointTermKind() = default;

  // The registry name: the `--joint_errors` item, the YAML key under `joint_errors`, the prefix of
  // the solvers' parameter names.
  virtual const char* name() const = 0;
  // P on `model` and the readable name of each parameter ("joint2.sin1").
  virtual int NumParameters(const RobotModel& model) const = 0;
  virtual std::vector<std::string> ParameterNames(const RobotModel& model) const = 0;
  // The joint each parameter moves (P values), -1 for a parameter that may move several joints
  // (JointTerm::ParameterJoint).
  virtual std::vector<int> ParameterJoints(const RobotModel& model) const = 0;

  // Y(q) on `model`'s own joint origins: resized to num_joints x P and overwritten. Entries below
  // kJointErrorRoundingCutoff of the largest |Y| must be exact zeros.
  virtual void Regressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y) const = 0;
  // Optional fast path when every ParameterJoints entry is >= 0: y[k] = Y(joint of k, k) (P values,
  // equal to Regressor's). Returns false (the default) when not provided.
  virtual bool RegressorValues(const RobotModel& model, const double* q, double* y) const {
    (void)model;
    (void)q;
    (void)y;
    return false;
  }
  // dq[j] += (Y(q) theta)_j for a model that carries the term (prediction, IK, simulation): Y on
  // the joint origins model.joint_errors.regressor_origins when given, else the model's own. The
  // default evaluates RegressorValues (or Regressor) on the model and ignores regressor_origins:
  // right for a term whose regressor does not depend on the geometry.
  virtual void AddOffsets(const RobotModel& model, const std::vector<double>& theta,
                          const double* q, double* dq) const;

  // YAML: the value of the key name() under `joint_errors` (`line`: the key's line). Fills theta
  // (P values; entries the file leaves out are zero). Errors name the line
  // (JointErrorsYamlReader::Error).
  virtual Status ReadYaml(const JointErrorsYamlReader& reader, const YAML::Node& node, int line,
                          std::vector<double>* theta) const = 0;
  // The term's block under `joint_errors:`, comment lines and "  <name>:" included, every line
  // ending in '\n', numbers with 17 significant digits (AppendYamlNumber).
  virtual std::string WriteYaml(const RobotModel& model,
                                const std::vector<double>& theta) const = 0;

  // Simulation: the term's truth values for the simulated robot `model` from `physics` (its
  // physical description, or physics.seed for a term that draws its own values).
  virtual std::vector<double> Simulate(const RobotModel& model,
                                       const JointErrorPhysics& physics) const = 0;
  // Folds the joint-zero errors `joint_zero` (SimulateMeasurements: the robot moves to q + zero) into
  // the commanded angle: rewrites theta so that the term at q predicts what it did at q + zero, and
  // adds to extra_zero[j] any constant joint offset the rewrite leaves over (FoldJointZeros turns
  // joint j's origin by zero_j + extra_zero_j). The default: nothing to rewrite (a term whose offsets
  // do not depend on the joint values' origin, such as compliance).
  virtual void FoldJointZeros(const RobotModel& model, const std::vector<double>& joint_zero,
                              std::vector<double>* theta, std::vector<double>* extra_zero) const {
    (void)model;
    (void)joint_zero;
    (void)theta;
    (void)extra_zero;
  }
};

// The registry's entries, in registry order.
const std::vector<const JointTermKind*>& JointTermKinds();
// The entry named `name`, nullptr when there is none.
const JointTermKind* FindJointTermKind(const std::string& name);

// Per-joint YAML helpers shared by the terms' writers.
void AppendYamlNumber(double v, std::string* out);  // 17 significant digits (parse_util)
void AppendYamlList(const double* v, int n, std::string* out);  // "[a, b, c]"
bool AllZero(const double* v, int n);
std::string YamlQuotedName(const std::string& name);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_CORE_SRC_JOINT_TERM_KIND_H_
