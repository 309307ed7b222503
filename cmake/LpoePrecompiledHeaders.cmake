# Precompiled headers for the test program (LPOE_PRECOMPILED_HEADERS, off by default and in CI).
#
# Every test file parses the same large headers (GoogleTest, Eigen, Ceres, our kinematics and
# simulation): with the option on, the test program precompiles them once (tests/CMakeLists.txt).
# Measured under clang -O1 with the sanitizers (the CI's slowest build), test files compiled 13-22%
# faster one by one; with gcc -O3 about 5-7%. The library targets gain nothing measurable (their
# files share fewer headers and spend their time in instantiation and optimization), so they do not
# use it. The option changes no code, but a header missing from a test's own #include list would
# still compile with it: it is off by default (developers' builds, usually cached by ccache, keep
# every file honest). The CI's unity build compiles the test program as two files, each parsing the
# headers once anyway; there the precompiled headers made each file slower to compile (about 10
# CPU seconds each under the sanitizers, docs/testing.md), so CI leaves it off.
option(LPOE_PRECOMPILED_HEADERS "Precompile the headers the test files share (clean CI builds)" OFF)
