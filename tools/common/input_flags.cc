#include "common/input_flags.h"

#include <iostream>

#include "common/common_flags.h"

namespace lpoe {
namespace tools {

bool InputsFromFlags(InputPaths* paths, InputSettings* settings) {
  const Status s = ResolveInputs(FLAGS_model, FLAGS_measurements,
                                 {FLAGS_angle_unit, FLAGS_length_unit, FLAGS_parameterization,
                                  FLAGS_verify, FLAGS_holdout, FLAGS_split},
                                 paths, settings);
  if (!s.ok()) std::cerr << "error: " << s.message() << "\n";
  return s.ok();
}

}  // namespace tools
}  // namespace lpoe
