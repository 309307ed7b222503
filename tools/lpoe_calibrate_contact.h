// lpoe_calibrate with ballbar distances and touch-probe plane contacts (docs/measurements.md):
// --measurements=a.csv[,b.csv...] with files of the kinds distance and plane (and tracker
// positions to combine with them), each file with its own noise.
#ifndef LPOE_TOOLS_LPOE_CALIBRATE_CONTACT_H_
#define LPOE_TOOLS_LPOE_CALIBRATE_CONTACT_H_

namespace lpoe {
namespace tools {

// Whether this run is one for the contact kinds: --data_kind=distance|plane, several
// --measurements files, or one file whose columns are a distance or plane file's.
bool ContactCalibrationRequested();
// The whole run (flags, inputs, calibration, outputs); the tools' exit code.
int RunContactCalibration();

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_LPOE_CALIBRATE_CONTACT_H_
