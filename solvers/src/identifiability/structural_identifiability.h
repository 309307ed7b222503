// Internal to lpoe_solvers: frame directions that no set of poses can identify for a given chain.
//
// The identifiable parameterization (parameterization.h) removes what every chain loses: the
// directions that commute with a joint's own motion, and a point's orientation with position data.
// Some chains lose more, whatever the poses: a tool point on the last joint's axis (a UR robot's
// tool0 measured directly) does not see the tilt of that axis about the point, because turning the
// joint never moves it; two joints about one line trade their frames. Refusing such data ("not
// identifiable") leaves the user nothing to do but change the robot; instead these directions are
// kept as given and reported, with what they trade with and, where it applies, what would identify
// them. Deficiencies of the poses themselves (a joint that never moves, too few or too similar
// configurations) are not structural and are still refused by the solvers' identifiability check.
#ifndef LPOE_SOLVERS_SRC_STRUCTURAL_IDENTIFIABILITY_H_
#define LPOE_SOLVERS_SRC_STRUCTURAL_IDENTIFIABILITY_H_

#include <Eigen/Core>
#include <vector>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {
namespace internal {

// A direction whose column, scaled to unit norm, keeps less than this fraction of its norm once
// the columns kept before it are projected out (at generic poses) is structurally unidentifiable.
// A tool 10^-4 mm off the last axis, 100 mm from the joint frame, is on the axis at this tolerance.
constexpr double kStructuralTolerance = 1e-6;

// Configurations per measured tool of the generic data set (at least the number of parameters).
constexpr int kGenericConfigurations = 60;

// The frame directions of the identifiable parameterization of `model` for data of this kind that
// no poses can determine, given which tools `data` measures (its poses are not used: the analysis
// runs on random generic configurations). Directions are kept greedily in this order: the measured
// tools' directions, then the joint frames' translation-like directions, then their rotation-like
// ones (frames in chain order); a direction that depends on those kept before it is left out. So a
// tool point on the last axis keeps its three coordinates and the axis' position, and loses the
// two tilts of the last joint frame. Each returned Direction carries its reason.
std::vector<Direction> StructurallyUnidentifiable(const RobotModel& model,
                                                  const MeasurementSet& data, bool use_orientation,
                                                  double orientation_weight);

// Leaves the directions of StructurallyUnidentifiable(reference, ...) out of `p` (frame blocks
// only, before joint blocks are added) and lists them in p->unidentifiable. `reference` has the
// chain of the model p was made for (its joints' twists); its frames may differ (the nominal model,
// where p is for the registered start). A full basis keeps the orthogonal complement of the lost
// directions (they are never solved, not even as gauge directions). Unmeasured tools are not
// touched (LeaveOutUnmeasuredTools).
void LeaveOutStructurallyUnidentifiable(const RobotModel& reference, const MeasurementSet& data,
                                        bool use_orientation, double orientation_weight,
                                        Parameterization* p);

// The decision is made at an estimate, never at the nominal model alone: where a measured point
// really sits is what the calibration finds out, and a nominal tool point on the last axis (a
// URDF's tool0) says nothing about an SMR 40 mm off it. StructureReference returns `estimate` (the
// registered start with its tool points fitted to the data, or a solution) with each measured
// tool's point that the data do not put significantly off the last joint's axis put on it: its
// distance rho from the axis is compared with kOnAxisSigmas standard deviations of a fitted
// point's offset, rms_axis * sqrt(2 / rows of that tool) (rms_axis: RMS residual per axis of the
// fit that gave the points, mm). A point 1-3 mm off the axis stays off it (a weak direction, for
// the solvers' rank and condition checks); one within the noise is on it (a structural zero).
constexpr double kOnAxisSigmas = 5.0;
RobotModel StructureReference(const RobotModel& estimate, const MeasurementSet& data,
                              double rms_axis);

// RMS residual per axis (mm) of a solve's final cost (0.5 |y|^2 over the rows of `data`).
double RmsPerAxisOfCost(double cost, const MeasurementSet& data, bool use_orientation);

// True when a and b leave out the same directions (frames and vectors, in any order).
bool SameDirections(const std::vector<Direction>& a, const std::vector<Direction>& b);

// The same with the directions given (StructurallyUnidentifiable's result): a caller reducing
// several parameterizations of one chain and data computes them once.
void LeaveOutDirections(const std::vector<Direction>& lost, Parameterization* p);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_STRUCTURAL_IDENTIFIABILITY_H_
