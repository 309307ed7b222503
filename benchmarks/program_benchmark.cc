// Robot programs: parsing is linear in the text. A Polyscope-style URScript program of N
// waypoints (`global Waypoint_k_p=p[...]` and a movel of it, the form that grew quadratically:
// 10,000 lines 1.6 s, 40,000 lines over 2 minutes) and a RAPID module of N robtargets with a MoveL
// each, parsed into their target records; N = 10^4, 4 x 10^4 and 10^5. Google Benchmark's fitted
// complexity (_BigO, _RMS) and the time per target show the growth; scripts/benchmarks.sh reports
// the time per target at each N. Google Benchmark repeats the 10^4 parse many times in one
// process, so that size runs on memory the allocator already holds; from 4 x 10^4 on one parse
// takes long enough that it runs once, on fresh memory (a third of its time is the system backing
// it with pages). A single parse, which is what a tool does, costs the same per target at every
// size (10^4 and 10^5 URScript targets: 18 to 29 us a target on the 2-core machine).
#include <cstdio>
#include <string>

#include <benchmark/benchmark.h>

#include "lpoe/program.h"

namespace lpoe {
namespace {

std::string Num(double x) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.6f", x);
  return b;
}

std::string UrScriptProgram(int n) {
  std::string head = "def Program():\n  set_tcp(p[0.0, 0.0, 0.15, 0.0, 0.0, 0.0])\n";
  std::string body;
  for (int k = 0; k < n; ++k) {
    const double a = 0.001 * (k % 1000);
    const std::string name = "Waypoint_" + std::to_string(k) + "_p";
    head += "  global " + name + "=p[" + Num(0.3 + a * 0.1) + ", " + Num(-0.2 + a * 0.05) + ", " +
            Num(0.4) + ", 0.0, 3.1, 0.0]\n";
    body += "  movel(" + name + ", a=1.2, v=0.25)\n";
  }
  return head + "  $ 1 \"Robot Program\"\n" + body + "end\n";
}

std::string RapidModule(int n) {
  std::string decl =
      "MODULE M\n  PERS tooldata tool1:=[TRUE,[[0,15,140],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\n";
  std::string body = "  PROC main()\n";
  for (int k = 0; k < n; ++k) {
    const double a = 0.1 * (k % 1000);
    const std::string name = "p" + std::to_string(k);
    decl += "  CONST robtarget " + name + ":=[[" + Num(400 + a) + "," + Num(-200 + a) +
            ",500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n";
    body += "    MoveL " + name + ", v100, z10, tool1;\n";
  }
  return decl + body + "  ENDPROC\nENDMODULE\n";
}

void Parse(benchmark::State& state, ProgramLanguage language) {
  const int n = static_cast<int>(state.range(0));
  const std::string text =
      language == ProgramLanguage::kUrScript ? UrScriptProgram(n) : RapidModule(n);
  size_t targets = 0;
  for (auto _ : state) {
    ParsedProgram program;
    if (!ParseProgram(text, language, &program).ok()) state.SkipWithError("parse failed");
    targets = program.targets.size();
    benchmark::DoNotOptimize(program.targets.data());
  }
  if (targets != static_cast<size_t>(n)) state.SkipWithError("wrong number of targets");
  state.SetComplexityN(n);
  state.counters["targets"] = static_cast<double>(targets);
  state.counters["bytes"] = static_cast<double>(text.size());
  state.counters["per_target"] = benchmark::Counter(
      static_cast<double>(n), benchmark::Counter::kIsIterationInvariantRate |
                                  benchmark::Counter::kInvert);
}

void BM_ParseUrScript(benchmark::State& state) { Parse(state, ProgramLanguage::kUrScript); }
void BM_ParseRapid(benchmark::State& state) { Parse(state, ProgramLanguage::kRapid); }

BENCHMARK(BM_ParseUrScript)
    ->Arg(10000)
    ->Arg(40000)
    ->Arg(100000)
    ->Complexity(benchmark::oN)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ParseRapid)
    ->Arg(10000)
    ->Arg(40000)
    ->Arg(100000)
    ->Complexity(benchmark::oN)
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace lpoe

BENCHMARK_MAIN();
