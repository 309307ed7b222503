// The problem's decisions are declared once (lpoe/problem_options.h): both solvers' options and the
// problem's options contain them as a base, with one set of defaults, and either solver hands the
// same decisions to the CalibrationProblem it builds.
#include "lpoe/problem_options.h"

#include <cstdlib>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include <gtest/gtest.h>

#include "calibration/solve_on_problem.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/linear_solver.h"
#include "lpoe/options.h"
#include "lpoe/problem_builder.h"
#include "loaded_cobot6.h"

namespace lpoe {
namespace {
namespace problem_options_test {

static_assert(std::is_base_of<ProblemDefinitionOptions, LinearSolverOptions>::value,
              "the linear solver's decisions are the shared ones");
static_assert(std::is_base_of<ProblemCostOptions, CeresSolverOptions>::value,
              "Ceres's decisions and cost are the shared ones");
static_assert(std::is_base_of<ProblemCostOptions, CalibrationProblemOptions>::value,
              "the problem's decisions and cost are the shared ones");
static_assert(!std::is_base_of<ProblemCostOptions, LinearSolverOptions>::value,
              "the linear solver has no sigma or loss (its cost is in mm^2)");

constexpr int kRows = 60;
constexpr double kNoiseSigma = 0.03;  // mm per axis, docs/conventions.md

// The decisions of `a` and `b` are the same (shared pointers: the same objects).
void ExpectSameDecisions(const ProblemDefinitionOptions& a, const ProblemDefinitionOptions& b) {
  EXPECT_EQ(a.parameterization, b.parameterization);
  EXPECT_EQ(a.use_orientation, b.use_orientation);
  EXPECT_EQ(a.orientation_weight, b.orientation_weight);
  EXPECT_EQ(a.structure_reference, b.structure_reference);
  ASSERT_EQ(a.joint_terms.size(), b.joint_terms.size());
  for (size_t i = 0; i < a.joint_terms.size(); ++i) EXPECT_EQ(a.joint_terms[i], b.joint_terms[i]);
  EXPECT_EQ(a.joint_term_tolerance, b.joint_term_tolerance);
  EXPECT_EQ(a.bilinear_effects, b.bilinear_effects);
  EXPECT_EQ(a.initial_joint_terms.size(), b.initial_joint_terms.size());
  EXPECT_EQ(a.prior, b.prior);
}

// The documented defaults (options.h's table for the flags; the headers for the rest) are those of
// every options struct, and a solver's share of the problem's options is the problem's default.
TEST(ProblemOptions, DefaultsAreTheDocumentedOnesEverywhere) {
  const CalibrationProblemOptions problem;
  EXPECT_EQ(problem.parameterization, ParameterizationKind::kIdentifiable);
  EXPECT_FALSE(problem.use_orientation);
  EXPECT_EQ(problem.orientation_weight, 1000.0);
  EXPECT_EQ(problem.joint_term_tolerance, 1e-4);
  EXPECT_EQ(problem.structure_reference, nullptr);
  EXPECT_EQ(problem.prior, nullptr);
  EXPECT_EQ(problem.sigma, OptionDefault("lpoe_calibrate", "sigma"));
  EXPECT_EQ(problem.loss_scale, OptionDefault("lpoe_calibrate", "loss_scale"));
  EXPECT_EQ(problem.loss, std::string(OptionDefaultText("lpoe_calibrate", "loss")));
  EXPECT_EQ(problem.rows_per_block, 1);

  const CalibrationProblemOptions from_linear = internal::LinearProblemOptions(LinearSolverOptions());
  const CalibrationProblemOptions from_ceres =
      internal::CeresProblemOptions(CeresSolverOptions(), kRows);
  ExpectSameDecisions(from_linear, problem);
  ExpectSameDecisions(from_ceres, problem);
  for (const CalibrationProblemOptions* o : {&from_linear, &from_ceres}) {
    EXPECT_EQ(o->sigma, problem.sigma);
    EXPECT_EQ(o->loss, problem.loss);
    EXPECT_EQ(o->loss_scale, problem.loss_scale);
    EXPECT_EQ(o->rows_per_block, 1);  // below CeresSolverOptions::kBatchFromRows
  }
  EXPECT_EQ(internal::CeresProblemOptions(CeresSolverOptions(), CeresSolverOptions::kBatchFromRows)
                .rows_per_block,
            1024);
}

// Both solvers' options with the same decisions (none of them the default) build problems with the
// same options() and the same solved parameters; Ceres's sigma and loss reach its problem only.
TEST(ProblemOptions, BothSolversBuildTheSameProblem) {
  const testing::LoadedCobot6 d = testing::MakeLoadedCobot6(kRows, kNoiseSigma, 3);
  std::shared_ptr<const JointTerm> compliance;
  ASSERT_TRUE(MakeJointTerm("compliance", d.nominal, &compliance).ok());

  ProblemDefinitionOptions decisions;
  decisions.orientation_weight = 250.0;  // unused by position data, but carried
  decisions.structure_reference = &d.nominal;
  decisions.joint_terms = {compliance};
  decisions.joint_term_tolerance = 1e-3;
  decisions.prior = std::make_shared<const ParameterPrior>();

  LinearSolverOptions linear;
  linear.max_iterations = 7;  // how to solve: not the problem's
  static_cast<ProblemDefinitionOptions&>(linear) = decisions;
  CeresSolverOptions ceres;
  ceres.max_iterations = 9;
  static_cast<ProblemDefinitionOptions&>(ceres) = decisions;
  ceres.sigma = kNoiseSigma;
  ceres.loss = "huber";
  ceres.loss_scale = 0.2;

  const CalibrationProblemOptions lo = internal::LinearProblemOptions(linear);
  const CalibrationProblemOptions co = internal::CeresProblemOptions(ceres, d.data.size());
  ExpectSameDecisions(lo, decisions);
  ExpectSameDecisions(co, decisions);
  EXPECT_EQ(lo.sigma, 1.0);
  EXPECT_EQ(lo.loss, "none");
  EXPECT_EQ(co.sigma, kNoiseSigma);
  EXPECT_EQ(co.loss, "huber");
  EXPECT_EQ(co.loss_scale, 0.2);

  ASSERT_TRUE(ValidateCalibrationProblem(d.nominal, d.data, lo).ok());
  ASSERT_TRUE(ValidateCalibrationProblem(d.nominal, d.data, co).ok());
  const CalibrationProblem from_linear(d.nominal, d.data, lo);
  const CalibrationProblem from_ceres(d.nominal, d.data, co);
  ExpectSameDecisions(from_linear.options(), from_ceres.options());
  EXPECT_EQ(from_linear.options().joint_term_tolerance, 1e-3);
  EXPECT_EQ(from_ceres.options().sigma, kNoiseSigma);
  EXPECT_EQ(from_linear.options().sigma, 1.0);
  // The same parameters solved: frames and the compliance combinations the data separate.
  const Parameterization& pl = from_linear.parameterization();
  const Parameterization& pc = from_ceres.parameterization();
  ASSERT_EQ(pl.num_parameters, pc.num_parameters);
  ASSERT_EQ(pl.parameters.size(), pc.parameters.size());
  for (size_t k = 0; k < pl.parameters.size(); ++k)
    EXPECT_EQ(pl.parameters[k].name, pc.parameters[k].name);
  EXPECT_EQ(pl.unidentifiable.size(), pc.unidentifiable.size());
}

}  // namespace problem_options_test
}  // namespace
}  // namespace lpoe
