// libFuzzer target: the URScript program parser (solvers/src/programs/program_urscript.cc) and the rewriter
// on arbitrary bytes; the properties are fuzz_program.h's.
#include <cstddef>
#include <cstdint>

#include "fuzz_program.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  lpoe::fuzz::FuzzProgram(data, size, lpoe::ProgramLanguage::kUrScript);
  return 0;
}
