// Planning ballbar and touch-probe poses (docs/measurements.md, "Planning"): which configurations
// to measure so that a calibration from distances or plane contacts identifies the model best.
//
// Candidates: random configurations (uniform in the joint ranges) projected onto the kind's
// surface by a position-only inverse-kinematics step (InverseKinematics with a position target,
// drawn toward the random configuration in the null space): for a ballbar the ball onto the sphere
// of the bar's length around a pivot (the radially nearest point), for a probe the tip onto the
// plane offset by the probe's radius (the orthogonally nearest point; outside the touched face's
// circle, drawn in along the same direction to a random radius within it). A ballbar target more
// than 0.2 bar lengths below the pivot's equator is reflected above it (the bar would run through
// the pivot's stand), as lpoe_simulate places its balls. A projection that does not converge,
// leaves the joint limits or the cell, or ends near a singularity is dropped, and a ballbar pose
// whose distance to its pivot is not within the bar's stroke.
//
// Information: each candidate is one row of the contact calibration's whitened Jacobian
// (ContactLinearize on the candidate pool, the parameterization decided from the pool as the
// calibration decides it from its data); the directions the gauge and scale-hold rows fix are
// projected out. The selection is D-optimal on the column-scaled information (greedy, then
// one-for-one exchanges while log det improves).
#ifndef LPOE_CONTACT_PLANNING_H_
#define LPOE_CONTACT_PLANNING_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/planning.h"
#include "lpoe/planning_workflow.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct ContactPlanOptions {
  // Ballbar: the pivots (mm, the model's base frame), the bar's length and stroke (mm).
  std::vector<Eigen::Vector3d> pivots;
  double bar_length = 150;
  double stroke = 1;
  // Probe: the planes [nx ny nz d] (n.x = d, |n| = 1, the outward normal), the probe's radius, and
  // the touched face: the points within face_radius of the face's centre (the projection of
  // plane_centres[k] onto the plane; when not given, the plane's point nearest the base origin).
  std::vector<Eigen::Vector4d> planes;
  std::vector<Eigen::Vector3d> plane_centres;
  double face_radius = 40;
  double probe_radius = 3;
  int target = 0;         // the tool that is the ball / the probe tip
  double sigma = 0.002;   // the measurement's noise (mm), the rows' weight
  // Random configurations projected per pivot / plane.
  int samples_per_feature = 400;
  uint64_t seed = 1;
  CellConstraint cell;
  double min_singularity = 0.0;  // as PlanConstraints::min_singularity
};

struct ContactCandidates {
  // The candidate rows, one per feasible projected configuration: distance rows (value: the bar's
  // length) and plane rows (value: the probe's radius), with the options' sigma.
  ContactMeasurementSet set;
  ContactFeatures features;  // the given pivots and planes
  // Why projections were dropped.
  int not_converged = 0;
  int outside_limits = 0;
  int outside_cell = 0;
  int near_singular = 0;
  int below_pivot = 0;  // reached a point below the allowed part of the sphere
  int outside_stroke = 0;
};

// The candidates for the given pivots and planes (both may be given: a combined plan).
Status ContactPlanCandidates(const RobotModel& model, const ContactPlanOptions& options,
                             ContactCandidates* out);

struct ContactPlanResult {
  std::vector<int> selected;  // rows of the candidate set
  int num_parameters = 0;     // the identifiable parameters the information is over
  int exchanges = 0;
  double log_det = 0;  // log det of the column-scaled information of the plan
};

// The candidates' information rows (whitened, reduced to the directions not fixed by the gauge and
// scale rows): row c of *rows is candidate c's.
Status ContactInformationRows(const RobotModel& model, const ContactCandidates& candidates,
                              Eigen::MatrixXd* rows);

// log det of the column-scaled information of the listed rows (-inf when singular).
double ContactPlanLogDet(const Eigen::MatrixXd& rows, const std::vector<int>& selected);

// Chooses `count` candidates D-optimally (see the file comment). Fails when there are fewer
// candidates than `count`, or `count` does not exceed the number of parameters (a plan must
// identify every parameter and have rows to spare).
Status PlanContacts(const RobotModel& model, const ContactCandidates& candidates, int count,
                    int max_exchange_passes, ContactPlanResult* result);

// ---- The workflow: lpoe_plan --measurement=ballbar|plane and lpoe.plan(measurement=...) as one
// library call (as RunPlanning is for tracker plans): the candidates, the D-optimal plan of `count`
// of them and `random_draws` random plans of as many candidates (seeds seed + 1000 + k) for
// comparison. It reads and writes no file.
struct ContactPlanRequest {
  ContactPlanOptions options;  // pivots (ballbar) or planes (probe), the bar, the probe, the cell
  int count = 0;               // poses to plan
  int random_draws = 30;       // random plans compared (lpoe_plan --random_draws)
};

struct ContactPlanningResult {
  ContactCandidates candidates;
  ContactPlanResult plan;
  std::vector<double> random_log_det;  // the random plans' log det, ascending
  double random_mean_log_det = 0;      // their mean (0 without any)
  double random_best_log_det = 0;      // their largest (0 without any)
};

// The request's numbers, as lpoe_plan checks its flags (a usage error naming the flag): pivots or
// planes (not both), a bar length in (0, 1e5) mm and a stroke in [0, bar length), unit normals,
// one face centre per plane when given, a positive face radius and a probe radius not negative,
// samples per feature in [1, 100000], random draws in lpoe_plan's range (lpoe/options.h), a finite floor, count >= 1.
Status CheckContactPlanRequest(const ContactPlanRequest& request);

// The whole workflow on `model` (the request checked first; the contact tool must be one of the
// model's). On failure `failure` (optional) says which kind (kUsage: the request; kNoPlan: no
// candidates, or too few to plan `count`, the message counting why candidates were dropped).
Status RunContactPlanning(const RobotModel& model, const ContactPlanRequest& request,
                          ContactPlanningResult* result, PlanFailure* failure = nullptr);

}  // namespace lpoe

#endif  // LPOE_CONTACT_PLANNING_H_
