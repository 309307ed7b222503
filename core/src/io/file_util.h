// Internal file access for the readers and writers: inputs opened with a bound and refused when
// they cannot be files (directories), read in chunks; outputs written atomically (lpoe/io/io.h).
#ifndef LPOE_CORE_SRC_FILE_UTIL_H_
#define LPOE_CORE_SRC_FILE_UTIL_H_

#include <cstddef>
#include <cstdint>
#include <string>

#include "lpoe/status.h"

namespace lpoe {
namespace internal {

// An input opened for sequential reading. Regular files, pipes/FIFOs and character devices are
// accepted (a FIFO without a writer reads as empty instead of blocking); directories, sockets and
// block devices are refused with a message naming the path.
class InputFile {
 public:
  InputFile() = default;
  ~InputFile();
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;

  Status Open(const std::string& path);
  // Reads up to `capacity` bytes into `buf`; `*got` is 0 at the end of the input.
  Status Read(char* buf, size_t capacity, size_t* got);
  // The size of a regular file, else -1 (a stream of unknown length).
  int64_t size() const { return size_; }
  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  int64_t size_ = -1;
  std::string path_;
};

// Reads all of `path` into `contents`, failing with "<path>: ... larger than <max_bytes> bytes"
// once more than `max_bytes` bytes arrive (so /dev/zero or a huge file cannot exhaust memory).
Status ReadFileBounded(const std::string& path, size_t max_bytes, std::string* contents);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_CORE_SRC_FILE_UTIL_H_
