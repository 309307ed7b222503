// The machine-readable calibration report (JSON; schema in the README).
#ifndef LPOE_TOOLS_REPORT_H_
#define LPOE_TOOLS_REPORT_H_

#include <string>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/calibration.h"
#include "lpoe/io.h"
#include "lpoe/plausibility.h"
#include "lpoe/registration.h"
#include "lpoe/statistics.h"

namespace lpoe {
namespace tools {

struct FoldResult {
  int fold = 0;
  int identification_rows = 0;
  std::string termination;
  ErrorStatistics verification_after;
};

struct RunSummary {
  std::string model_path, measurements_path, verification_source;
  std::string solver, parameterization, data_kind, angle_unit;
  CsvReadReport skipped;
  bool registered = false;
  RegistrationReport registration;
  CalibrationResult result;
  IdentifiabilityReport identifiability;
  ErrorStatistics identification_before, identification_after;
  bool has_verification = false;
  ErrorStatistics verification_before, verification_after;
  double robust_sigma = 0;
  std::vector<Outlier> outliers;
  std::vector<FoldResult> folds;
  Verdict verdict;  // plausibility of the result (lpoe/plausibility.h)
  std::vector<std::string> outputs;  // files written
};

// Pretty-printed JSON, numbers with full precision, keys in a fixed order.
std::string RunSummaryToJson(const RunSummary& summary);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_REPORT_H_
