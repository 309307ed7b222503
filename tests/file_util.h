// File helpers shared by the tests that run tools and check what they leave on disk.
#ifndef LPOE_TESTS_FILE_UTIL_H_
#define LPOE_TESTS_FILE_UTIL_H_

#include <dirent.h>
#include <sys/stat.h>

#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace lpoe {
namespace testing {

inline std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
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

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_FILE_UTIL_H_
