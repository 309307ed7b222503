// Measurements of the kinds that measure no point in a tracker's frame (docs/measurements.md):
// ballbar distances (distance_measurement.h) and touch-probe contacts on planes
// (plane_measurement.h), possibly combined with tracker positions (position_measurement.h) from
// other files. Every row has its own noise (the file's --sigma or the row's `sigma` column) and
// refers to a named feature (a pivot, a plane) whose position is unknown and estimated.
#ifndef LPOE_CONTACT_MEASUREMENTS_H_
#define LPOE_CONTACT_MEASUREMENTS_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/io/io.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct ContactRow {
  MeasurementKindId kind = MeasurementKindId::kDistance;
  int feature = 0;  // index into the set's pivots or planes (distance, plane rows)
  int target = 0;   // the tool whose origin is the ball's / probe tip's centre (or the SMR)
  // distance: the bar's length (mm); plane: the offset of the point from the plane (the probe
  // tip's radius, mm); position: unused.
  double value = 0;
  double sigma = 1;  // standard deviation of the measurement (mm; per axis for position rows)
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // position rows: the measured point
  int file = 0;          // index into ContactMeasurementSet::files
  int64_t line = 0;      // 1-based line of that file, 0 when generated
};

struct ContactMeasurementSet {
  int num_joints = 0;
  std::vector<double> q;  // row-major, num_joints per row
  std::vector<ContactRow> rows;
  std::vector<std::string> pivots;  // names of the distance rows' features
  std::vector<std::string> planes;  // names of the plane rows' features
  std::vector<std::string> files;   // sources, for messages

  int size() const { return static_cast<int>(rows.size()); }
  const double* joints(int row) const { return q.data() + static_cast<size_t>(row) * num_joints; }
  // The index of the feature `name` of `kind` (distance: pivots, plane: planes), added if new.
  int Feature(MeasurementKindId kind, const std::string& name);
  // Rows of each kind.
  int Count(MeasurementKindId kind) const;
  // Appends `other`'s rows (same joint count), merging features by name and files.
  void Append(const ContactMeasurementSet& other);
  // The rows listed, with every feature and file kept (indices unchanged).
  ContactMeasurementSet Subset(const std::vector<int>& rows) const;
  // "file:line" of a row.
  std::string Where(int row) const;
};

// Tracker rows as position rows of a contact set (pose rows keep only their positions), each with
// noise `sigma` (mm per axis).
ContactMeasurementSet ContactSetFromPositions(const MeasurementSet& data, double sigma,
                                              const std::string& source);

struct ContactCsvOptions {
  CsvOptions units;
  // The kind the file must have; null: detected from its columns (measurement_kinds.h).
  const MeasurementKindInfo* kind = nullptr;
  // The noise of rows without a `sigma` column (mm); 0: the file must have one.
  double sigma = 0;
};

// Reads a distance or plane CSV (docs/file_formats.md): q1..qN (or the joint names), then
//   distance[,pivot][,target][,sigma]      or      plane[,offset][,target][,sigma]
// (any order, any other column ignored). Every error names the file and line. `text` is the whole
// file (ReadContactMeasurements reads it, at most 256 MiB).
Status ParseContactMeasurementsCsv(const std::string& text, const std::string& source,
                                   const RobotModel& model, const ContactCsvOptions& options,
                                   ContactMeasurementSet* out);
Status ReadContactMeasurements(const std::string& path, const RobotModel& model,
                               const ContactCsvOptions& options, ContactMeasurementSet* out);
// The kind of a CSV file from its header (the first line that is not a comment); null with a
// message naming the file and line when none or two kinds match.
Status DetectMeasurementFileKind(const std::string& path, const MeasurementKindInfo** kind);

// Writes a distance or plane set as CSV (one kind: the rows of `kind` only), with a sigma column.
std::string ContactMeasurementsCsv(const RobotModel& model, const ContactMeasurementSet& data,
                                   MeasurementKindId kind);

// Simulation (lpoe_simulate --measurement=ballbar|plane). `truth` predicts what is measured at
// the commanded joint values (FoldJointZeros of the actual robot; with joint-space terms, at its
// effective joint values: the distance is read there, and the probe stops where the true tip
// touches). Configurations are drawn around
// a seed configuration per pivot / per face and moved by Gauss-Newton until the ball (probe tip)
// sits where it must; rows that do not converge or leave the joint limits are drawn again.
struct BallbarSimulationOptions {
  int count = 300;
  double bar_length = 150;  // mm
  double stroke = 1;        // mm: the bar's length varies by up to this around bar_length
  double noise = 0.002;     // mm
  int num_pivots = 3;
  std::vector<Eigen::Vector3d> pivots;  // given pivots (else placed in the workspace)
  int target = 0;
  uint64_t seed = 1;
};
struct PlaneSimulationOptions {
  int count = 300;
  double probe_radius = 3;  // mm
  double noise = 0.003;     // mm
  double cube_size = 100;   // mm: three faces (+x, +y, +z) of an axis-aligned cube
  bool cube_given = false;
  Eigen::Vector3d cube_centre = Eigen::Vector3d::Zero();  // else placed in the workspace
  int target = 0;
  uint64_t seed = 1;
};
// The true pivots / planes ([nx ny nz d]: n.x = d, n the outward normal) go to `truth_features`.
Status SimulateBallbar(const RobotModel& truth, const BallbarSimulationOptions& options,
                       ContactMeasurementSet* out, std::vector<Eigen::Vector3d>* pivots);
Status SimulatePlaneContacts(const RobotModel& truth, const PlaneSimulationOptions& options,
                             ContactMeasurementSet* out, std::vector<Eigen::Vector4d>* planes);

}  // namespace lpoe

#endif  // LPOE_CONTACT_MEASUREMENTS_H_
