// Helpers shared by the tests that run tools and check what they leave on disk: reading and writing
// files, a temporary directory, and running a tool with its output captured.
#ifndef LPOE_TESTS_FILE_UTIL_H_
#define LPOE_TESTS_FILE_UTIL_H_

#include <dirent.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace lpoe {
namespace testing {

inline std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Writes `text` to `path` (binary); false when that failed.
inline bool WriteAll(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  return out.good();
}

// True when `path` exists (a dangling symlink counts).
inline bool Exists(const std::string& path) {
  struct stat st;
  return lstat(path.c_str(), &st) == 0;
}

// The entries of `dir` other than "." and "..", unsorted.
inline std::vector<std::string> ListDir(const std::string& dir) {
  std::vector<std::string> names;
  if (DIR* d = opendir(dir.c_str())) {
    while (dirent* e = readdir(d)) {
      if (std::strcmp(e->d_name, ".") != 0 && std::strcmp(e->d_name, "..") != 0) {
        names.push_back(e->d_name);
      }
    }
    closedir(d);
  }
  return names;
}

// Removes `path`, and everything below it when it is a directory (links are not followed).
inline void RemoveTree(const std::string& path) {
  struct stat st;
  if (lstat(path.c_str(), &st) != 0) return;
  if (S_ISDIR(st.st_mode)) {
    for (const std::string& name : ListDir(path)) RemoveTree(path + "/" + name);
    rmdir(path.c_str());
  } else {
    unlink(path.c_str());
  }
}

// A fresh empty directory under the test temporary directory, named <prefix>_XXXXXX, removed with
// everything in it when this object goes. A failure to create it fails the test.
class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "lpoe_test") {
    std::string base = ::testing::TempDir();
    if (base.empty() || base.back() != '/') base += '/';
    std::string pattern = base + prefix + "_XXXXXX";
    if (mkdtemp(pattern.data()) != nullptr) {
      path_ = pattern;
    } else {
      ADD_FAILURE() << "cannot create a temporary directory " << pattern;
    }
  }
  ~TempDir() {
    if (!path_.empty()) RemoveTree(path_);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::string& path() const { return path_; }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// The program's exit code from a std::system or pclose status; -1 when it did not exit normally
// (a signal, a sanitizer abort).
inline int ExitCodeOf(int status) {
  return status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// `s` single-quoted for the shell.
inline std::string ShellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

struct ToolOutput {
  int exit_code = -1;  // -1: did not exit normally
  std::string out, err;
};

// The tools a test starts (through the shell: RunInDir, RunCapture, std::system) and their
// LeakSanitizer check. In the sanitizer build every process checks for leaks at exit, and for a
// tool that check (stopping the process, scanning its globals, stacks and heap) took about a third
// of the tool tests' time: 115 -> 78 CPU seconds for ten tool-heavy suites, of ~560 tool runs in
// the whole suite (docs/testing.md). A tool is a short-lived process whose memory goes back to the
// system when it exits; the leaks that matter are the library's, which the test program checks in
// its own process (its exit check covers every library call of every test). So the test program
// starts the tools with `detect_leaks=0` appended to ASAN_OPTIONS (tool_leak_check_test.cc, at
// start-up, in the sanitizer build only), except inside a ScopedToolLeakCheck: there they run with
// the test program's own options, leak check included. The tests that run every tool on its main
// paths (FiniteOutputs, PriorTool, ContactTool's tracker-and-ballbar job, CalibrateReport) do.
class ScopedToolLeakCheck {
 public:
  ScopedToolLeakCheck();
  ~ScopedToolLeakCheck();
  ScopedToolLeakCheck(const ScopedToolLeakCheck&) = delete;
  ScopedToolLeakCheck& operator=(const ScopedToolLeakCheck&) = delete;
};

// Runs the shell command line `command` in directory `dir`, stdout and stderr captured apart (through
// hidden files in `dir`, removed again, so that the directory holds only what the tool wrote).
inline ToolOutput RunInDir(const std::string& dir, const std::string& command) {
  const std::string out = dir + "/.lpoe_test_stdout", err = dir + "/.lpoe_test_stderr";
  const std::string line = "cd " + ShellQuote(dir) + " && " + command + " >" + ShellQuote(out) +
                           " 2>" + ShellQuote(err);
  ToolOutput o;
  o.exit_code = ExitCodeOf(std::system(line.c_str()));
  o.out = ReadAll(out);
  o.err = ReadAll(err);
  std::remove(out.c_str());
  std::remove(err.c_str());
  return o;
}

// Runs the shell command line `command`; appends its stdout and stderr, interleaved, to *out.
// Returns its exit code.
inline int RunCapture(const std::string& command, std::string* out) {
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return -1;
  std::array<char, 4096> buffer;
  size_t n;
  while ((n = fread(buffer.data(), 1, buffer.size(), pipe)) > 0) out->append(buffer.data(), n);
  return ExitCodeOf(pclose(pipe));
}

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_FILE_UTIL_H_
