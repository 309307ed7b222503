// The program the tests' precompiled header is built for (LPOE_PRECOMPILED_HEADERS; see
// tests/CMakeLists.txt). It tests nothing: GTest::gtest_main provides main(), which finds no test.
