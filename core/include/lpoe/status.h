// A small status type for user-facing errors: bad files, bad flags, data that cannot identify a
// model. Programmer errors use CHECK instead (Ceres/glog style).
#ifndef LPOE_STATUS_H_
#define LPOE_STATUS_H_

#include <string>
#include <utility>

namespace lpoe {

class Status {
 public:
  Status() = default;
  static Status Ok() { return Status(); }
  static Status Error(std::string message) { return Status(std::move(message)); }

  bool ok() const { return !error_; }
  const std::string& message() const { return message_; }
  explicit operator bool() const { return ok(); }

 private:
  explicit Status(std::string message) : error_(true), message_(std::move(message)) {}
  bool error_ = false;
  std::string message_;
};

}  // namespace lpoe

#endif  // LPOE_STATUS_H_
