// File utilities of lpoe/io/io.h: bounded, non-blocking-safe reading and atomic writing.
#include "io/file_util.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <exception>
#include <string>

#include "lpoe/io/io.h"

namespace lpoe {
namespace internal {

InputFile::~InputFile() {
  if (fd_ >= 0) ::close(fd_);
}

Status InputFile::Open(const std::string& path) {
  path_ = path;
  if (path.empty()) return Status::Error("cannot read a file with an empty path");
  // O_NONBLOCK: opening a FIFO without a writer must not hang; cleared below for blocking reads.
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd_ < 0) {
    const int err = errno;
    return Status::Error(path + ": cannot open: " + std::strerror(err));
  }
  struct stat st;
  if (::fstat(fd_, &st) != 0) {
    const int err = errno;
    return Status::Error(path + ": cannot stat: " + std::strerror(err));
  }
  if (S_ISDIR(st.st_mode)) return Status::Error(path + ": is a directory, not a file");
  if (!S_ISREG(st.st_mode) && !S_ISFIFO(st.st_mode) && !S_ISCHR(st.st_mode)) {
    return Status::Error(path + ": is not a regular file, a pipe or a character device");
  }
  if (S_ISREG(st.st_mode)) size_ = static_cast<int64_t>(st.st_size);
  const int flags = ::fcntl(fd_, F_GETFL);
  if (flags >= 0) ::fcntl(fd_, F_SETFL, flags & ~O_NONBLOCK);
  return Status::Ok();
}

Status InputFile::Read(char* buf, size_t capacity, size_t* got) {
  *got = 0;
  while (true) {
    const ssize_t r = ::read(fd_, buf, capacity);
    if (r >= 0) {
      *got = static_cast<size_t>(r);
      return Status::Ok();
    }
    if (errno == EINTR) continue;
    // A FIFO whose writer has not yet connected (opened non-blocking): nothing to read.
    if (errno == EAGAIN) return Status::Ok();
    const int err = errno;
    return Status::Error(path_ + ": cannot read: " + std::strerror(err));
  }
}

namespace {

Status ReadFileBoundedImpl(const std::string& path, size_t max_bytes, std::string* contents) {
  InputFile file;
  Status s = file.Open(path);
  if (!s.ok()) return s;
  if (file.size() > 0 && static_cast<uint64_t>(file.size()) > max_bytes) {
    return Status::Error(path + ": the file has " + std::to_string(file.size()) +
                         " bytes, more than the limit of " + std::to_string(max_bytes));
  }
  std::string text;
  if (file.size() > 0) text.reserve(static_cast<size_t>(file.size()));
  char buf[1 << 16];
  while (true) {
    size_t got = 0;
    s = file.Read(buf, sizeof(buf), &got);
    if (!s.ok()) return s;
    if (got == 0) break;
    if (text.size() + got > max_bytes) {
      return Status::Error(path + ": more than the limit of " + std::to_string(max_bytes) +
                           " bytes (not a regular file of that size: a device or a stream?)");
    }
    text.append(buf, got);
  }
  *contents = std::move(text);
  return Status::Ok();
}

}  // namespace

Status ReadFileBounded(const std::string& path, size_t max_bytes, std::string* contents) {
  try {
    return ReadFileBoundedImpl(path, max_bytes, contents);
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(path + ": cannot read: " + e.what());
  }
}

}  // namespace internal

Status ReadFile(const std::string& path, std::string* contents) {
  return internal::ReadFileBounded(path, kMaxReadFileBytes, contents);
}

Status ReadFile(const std::string& path, size_t max_bytes, std::string* contents) {
  return internal::ReadFileBounded(path, max_bytes, contents);
}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ >= 0) {
    ::close(fd_);
    ::unlink(tmp_.c_str());
  }
}

Status AtomicFileWriter::Fail(const char* what, int err) {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  ::unlink(tmp_.c_str());
  return Status::Error(path_ + ": " + what + " " + tmp_ + ": " + std::strerror(err));
}

Status AtomicFileWriter::Open(const std::string& path) {
  if (path.empty()) return Status::Error("cannot write a file with an empty path");
  if (fd_ >= 0) return Status::Error(path + ": the writer is already open for " + path_);
  path_ = path;
  tmp_ = path + ".tmp.XXXXXX";
  fd_ = ::mkstemp(&tmp_[0]);
  if (fd_ < 0) {
    const int err = errno;
    return Status::Error(path + ": cannot create a temporary file " + tmp_ + ": " +
                         std::strerror(err));
  }
  // mkstemp creates mode 0600; give the result the mode of the file it replaces, or 0644.
  struct stat st;
  const mode_t mode = ::stat(path.c_str(), &st) == 0 ? (st.st_mode & 07777) : 0644;
  if (::fchmod(fd_, mode) != 0) return Fail("cannot set the mode of", errno);
  return Status::Ok();
}

Status AtomicFileWriter::Append(const char* p, size_t left) {
  if (fd_ < 0) return Status::Error(path_ + ": the output is not open");
  while (left > 0) {
    const ssize_t w = ::write(fd_, p, left);
    if (w < 0) {
      if (errno == EINTR) continue;
      return Fail("cannot write", errno);
    }
    p += w;
    left -= static_cast<size_t>(w);
  }
  return Status::Ok();
}

Status AtomicFileWriter::Commit() {
  if (fd_ < 0) return Status::Error(path_ + ": the output is not open");
  if (::fsync(fd_) != 0) return Fail("cannot flush", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp_.c_str());
    return Status::Error(path_ + ": cannot close " + tmp_ + ": " + std::strerror(err));
  }
  if (::rename(tmp_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp_.c_str());
    return Status::Error(path_ + ": cannot rename " + tmp_ + " to it: " + std::strerror(err));
  }
  // Make the rename itself durable (best effort: some file systems refuse to open directories).
  const size_t slash = path_.rfind('/');
  const std::string dir = slash == std::string::npos ? "."
                          : slash == 0               ? "/"
                                                     : path_.substr(0, slash);
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return Status::Ok();
}

Status WriteFileAtomically(const std::string& path, const std::string& contents) {
  AtomicFileWriter out;
  if (Status s = out.Open(path); !s.ok()) return s;
  if (Status s = out.Append(contents); !s.ok()) return s;
  return out.Commit();
}

struct LineReader::File {
  internal::InputFile input;
};

LineReader::LineReader() : file_(new File) {}
LineReader::~LineReader() { delete file_; }

Status LineReader::Open(const std::string& path) {
  buffer_.clear();
  pos_ = 0;
  eof_ = false;
  status_ = file_->input.Open(path);
  return status_;
}

bool LineReader::Next(std::string* line) {
  constexpr size_t kBlock = size_t{1} << 20;
  constexpr size_t kMaxLine = size_t{1} << 24;
  while (true) {
    const size_t end = buffer_.find('\n', pos_);
    if (end != std::string::npos) {
      line->assign(buffer_, pos_, end - pos_);
      pos_ = end + 1;
      return true;
    }
    if (eof_ || !status_.ok()) {
      if (pos_ >= buffer_.size()) return false;
      line->assign(buffer_, pos_, std::string::npos);  // a last line without '\n'
      pos_ = buffer_.size();
      return status_.ok();
    }
    buffer_.erase(0, pos_);
    pos_ = 0;
    if (buffer_.size() > kMaxLine) {
      status_ = Status::Error(file_->input.path() + ": a line longer than " +
                              std::to_string(kMaxLine) + " bytes (not a text file?)");
      return false;
    }
    const size_t old = buffer_.size();
    buffer_.resize(old + kBlock);
    size_t got = 0;
    status_ = file_->input.Read(&buffer_[old], kBlock, &got);
    buffer_.resize(old + got);
    if (got == 0) eof_ = true;
  }
}

}  // namespace lpoe
