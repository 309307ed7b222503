#include "common/output_files.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <csignal>
#include <ctime>
#include <cstdlib>
#include <cstring>
#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <vector>

namespace lpoe {
namespace tools {
namespace {

// ---- Cleanup on SIGINT / SIGTERM: a fixed table of paths (async-signal-safe: unlink, rmdir).
constexpr int kMaxCleanup = 256;
char g_cleanup[kMaxCleanup][PATH_MAX + 8];
std::atomic<int> g_cleanup_count{0};
std::atomic<bool> g_handlers{false};

extern "C" void CleanupAndReraise(int sig) {
  // Files first (registered after their directory), then directories.
  const int n = g_cleanup_count.load();
  for (int k = n - 1; k >= 0; --k) {
    if (g_cleanup[k][0] != 0) {
      ::unlink(g_cleanup[k]);
      ::rmdir(g_cleanup[k]);
    }
  }
  ::signal(sig, SIG_DFL);
  ::raise(sig);
}

// Faults (a crash in a library: PLplot, a solver) and abort(): the temporaries are removed, the
// previous action (the default, or a sanitizer's handler) is restored, and the handler returns: a
// fault re-executes the faulting instruction and abort() raises again, so the process dies as it
// would have (with the sanitizer's report), leaving no .lpoe-staging-* directory behind.
constexpr int kFaultSignals[] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT};
struct sigaction g_previous[sizeof(kFaultSignals) / sizeof(kFaultSignals[0])];

extern "C" void CleanupAndChain(int sig) {
  const int n = g_cleanup_count.load();
  for (int k = n - 1; k >= 0; --k) {
    if (g_cleanup[k][0] != 0) {
      ::unlink(g_cleanup[k]);
      ::rmdir(g_cleanup[k]);
    }
  }
  for (size_t k = 0; k < sizeof(kFaultSignals) / sizeof(kFaultSignals[0]); ++k) {
    if (kFaultSignals[k] == sig) ::sigaction(sig, &g_previous[k], nullptr);
  }
}

void RegisterCleanup(const std::string& path) {
  if (!g_handlers.exchange(true)) {
    struct sigaction sa;
    std::memset(&sa, 0, sizeof(sa));
    sa.sa_handler = CleanupAndReraise;
    sigemptyset(&sa.sa_mask);
    ::sigaction(SIGINT, &sa, nullptr);
    ::sigaction(SIGTERM, &sa, nullptr);
    ::sigaction(SIGHUP, &sa, nullptr);
    struct sigaction fault;
    std::memset(&fault, 0, sizeof(fault));
    fault.sa_handler = CleanupAndChain;
    sigemptyset(&fault.sa_mask);
    fault.sa_flags = SA_ONSTACK;  // a stack overflow still reaches it when an altstack exists
    for (size_t k = 0; k < sizeof(kFaultSignals) / sizeof(kFaultSignals[0]); ++k) {
      ::sigaction(kFaultSignals[k], &fault, &g_previous[k]);
    }
  }
  const int k = g_cleanup_count.load();
  if (k >= kMaxCleanup || path.size() > PATH_MAX) return;
  std::memcpy(g_cleanup[k], path.c_str(), path.size() + 1);
  g_cleanup_count.store(k + 1);
}

void UnregisterCleanup(const std::string& path) {
  const int n = g_cleanup_count.load();
  for (int k = 0; k < n; ++k) {
    if (path == g_cleanup[k]) g_cleanup[k][0] = 0;
  }
}

std::string DirName(const std::string& path) {
  const size_t slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

std::string BaseName(const std::string& path) {
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

// The file `path` names: symlinks of the last component followed (up to 40), the directory
// resolved with realpath. Fails when the directory does not exist.
Status Resolve(const std::string& path, std::string* resolved) {
  std::string p = path;
  for (int hops = 0; hops < 40; ++hops) {
    char dir[PATH_MAX];
    if (::realpath(DirName(p).c_str(), dir) == nullptr) {
      return Status::Error(path + ": the directory " + DirName(p) + " does not exist (" +
                           std::strerror(errno) + ")");
    }
    const std::string base = BaseName(p);
    if (base.empty() || base == "." || base == "..") {
      return Status::Error(path + ": names a directory, not a file");
    }
    const std::string full = std::string(dir) == "/" ? "/" + base : std::string(dir) + "/" + base;
    struct stat st;
    if (::lstat(full.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) {
      *resolved = full;
      return Status::Ok();
    }
    char target[PATH_MAX];
    const ssize_t len = ::readlink(full.c_str(), target, sizeof(target) - 1);
    if (len < 0) return Status::Error(path + ": cannot read the link " + full);
    target[len] = 0;
    p = target[0] == '/' ? std::string(target) : std::string(dir) + "/" + target;
  }
  return Status::Error(path + ": too many levels of symbolic links");
}

// `path` with its deepest existing ancestor resolved by realpath and the rest normalized
// lexically ("." dropped, ".." taking one component off).
std::string ResolveLexically(const std::string& path) {
  std::vector<std::string> rest;
  std::string head = path;
  char buf[PATH_MAX];
  while (::realpath(head.c_str(), buf) == nullptr) {
    const std::string base = BaseName(head);
    const std::string dir = DirName(head);
    rest.push_back(base);
    if (dir == head) break;
    head = dir;
  }
  std::vector<std::string> parts;
  std::string resolved = ::realpath(head.c_str(), buf) ? std::string(buf) : head;
  for (auto it = rest.rbegin(); it != rest.rend(); ++it) {
    if (*it == "." || it->empty()) continue;
    if (*it == "..") {
      resolved = DirName(resolved);
      continue;
    }
    resolved += (resolved == "/" ? "" : "/") + *it;
  }
  return resolved;
}

// Identity of a file: "dev:ino" when it exists, else its resolved path.
std::string Identity(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) == 0) {
    return "#" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
  }
  std::string resolved;
  if (Resolve(path, &resolved).ok()) {
    if (::stat(resolved.c_str(), &st) == 0) {
      return "#" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
    }
    return resolved;
  }
  return ResolveLexically(path);
}

Status WriteAll(int fd, const char* p, size_t left, const std::string& what) {
  while (left > 0) {
    const ssize_t w = ::write(fd, p, left);
    if (w < 0) {
      if (errno == EINTR) continue;
      return Status::Error(what + ": cannot write: " + std::strerror(errno));
    }
    p += w;
    left -= static_cast<size_t>(w);
  }
  return Status::Ok();
}

Status ReadAll(const std::string& path, std::string* out) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) return Status::Error(path + ": cannot read: " + std::strerror(errno));
  char buf[65536];
  for (;;) {
    const ssize_t r = ::read(fd, buf, sizeof(buf));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) {
      ::close(fd);
      return Status::Error(path + ": cannot read: " + std::strerror(errno));
    }
    if (r == 0) break;
    out->append(buf, static_cast<size_t>(r));
  }
  ::close(fd);
  return Status::Ok();
}

// The descriptor number `path` names in this process (/dev/stdout, /dev/stderr, /dev/fd/N,
// /proc/self/fd/N), else -1.
int DescriptorOf(const std::string& path) {
  if (path == "/dev/stdout") return 1;
  if (path == "/dev/stderr") return 2;
  for (const std::string prefix : {"/dev/fd/", "/proc/self/fd/"}) {
    if (path.rfind(prefix, 0) != 0) continue;
    const std::string number = path.substr(prefix.size());
    if (number.empty() || number.size() > 6 ||
        number.find_first_not_of("0123456789") != std::string::npos) {
      return -1;
    }
    return std::stoi(number);
  }
  return -1;
}

// Staging directories (".lpoe-staging-<pid>-XXXXXX") that a process killed by SIGKILL (or a
// power loss) left in `dir`: removed when that process is gone (kill(pid, 0) says ESRCH) and the
// directory is ours. Only what is not a directory directly inside is removed (a staging
// directory holds nothing else). Directories of the old form without a pid
// (".lpoe-staging-XXXXXX") are removed when older than a day.
void RemoveStaleStaging(const std::string& dir) {
  DIR* d = ::opendir(dir.c_str());
  if (d == nullptr) return;
  const std::string prefix = ".lpoe-staging-";
  std::vector<std::string> stale;
  while (const struct dirent* e = ::readdir(d)) {
    const std::string name = e->d_name;
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string rest = name.substr(prefix.size());
    const std::string path = dir + "/" + name;
    struct stat st;
    if (::lstat(path.c_str(), &st) != 0 || !S_ISDIR(st.st_mode) || st.st_uid != ::geteuid()) {
      continue;
    }
    const size_t dash = rest.find('-');
    bool dead = false;
    if (dash != std::string::npos && dash > 0 && rest.find_first_not_of("0123456789") == dash) {
      const long pid = std::strtol(rest.substr(0, dash).c_str(), nullptr, 10);
      dead = pid > 0 && pid != ::getpid() && ::kill(static_cast<pid_t>(pid), 0) != 0 &&
             errno == ESRCH;
    } else if (dash == std::string::npos) {
      dead = ::time(nullptr) - st.st_mtime > 24 * 3600;
    }
    if (dead) stale.push_back(path);
  }
  ::closedir(d);
  for (const std::string& path : stale) {
    DIR* inner = ::opendir(path.c_str());
    if (inner == nullptr) continue;
    const int fd = ::dirfd(inner);
    while (const struct dirent* e = ::readdir(inner)) {
      const std::string name = e->d_name;
      if (name == "." || name == "..") continue;
      struct stat st;
      if (::fstatat(fd, name.c_str(), &st, AT_SYMLINK_NOFOLLOW) == 0 && !S_ISDIR(st.st_mode)) {
        ::unlinkat(fd, name.c_str(), 0);
      }
    }
    ::closedir(inner);
    ::rmdir(path.c_str());
  }
}

}  // namespace

Status EnsureDirectories(const std::string& dir) {
  if (dir.empty()) return Status::Error("empty directory name");
  struct stat st;
  if (::stat(dir.c_str(), &st) == 0) {
    return S_ISDIR(st.st_mode) ? Status::Ok() : Status::Error(dir + ": exists and is not a directory");
  }
  const std::string parent = DirName(dir);
  if (parent != dir && parent != "." && parent != "/") {
    if (Status s = EnsureDirectories(parent); !s.ok()) return s;
  }
  if (::mkdir(dir.c_str(), 0755) != 0 && errno != EEXIST) {
    return Status::Error(dir + ": cannot create the directory: " + std::strerror(errno));
  }
  return Status::Ok();
}

OutputSet::~OutputSet() { Discard(); }

void OutputSet::AddInput(const std::string& flag, const std::string& path) {
  if (!path.empty()) inputs_.push_back({flag, path});
}

void OutputSet::AddOutput(const std::string& flag, const std::string& path,
                          bool create_directory) {
  if (!path.empty()) outputs_.push_back({flag, path, create_directory});
}

Status OutputSet::Check() const {
  for (size_t a = 0; a < outputs_.size(); ++a) {
    const Entry& o = outputs_[a];
    struct stat st;
    if (::stat(o.path.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) {
      return Status::Error(o.flag + "=" + o.path + " is a directory");
    }

    const std::string id = Identity(o.path);
    for (const Entry& in : inputs_) {
      if (id == Identity(in.path)) {
        return Status::Error(o.flag + "=" + o.path + " would overwrite the input " + in.flag + "=" +
                             in.path);
      }
    }
    // Devices and FIFOs are written straight: two outputs may share one (/dev/null, a terminal).
    const bool special = ::stat(o.path.c_str(), &st) == 0 && !S_ISREG(st.st_mode);
    for (size_t b = 0; b < a && !special; ++b) {
      if (id == Identity(outputs_[b].path)) {
        return Status::Error(o.flag + "=" + o.path + " and " + outputs_[b].flag + "=" +
                             outputs_[b].path + " name the same file");
      }
    }
  }
  for (const Entry& o : outputs_) {
    // A device, FIFO or descriptor is written straight (its directory is not written).
    struct stat st;
    if (::stat(o.path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) continue;
    std::string dir;
    if (o.create_directory) {
      // The deepest existing ancestor is where the missing directories will be created.
      dir = ResolveLexically(DirName(o.path));
      while (::stat(dir.c_str(), &st) != 0 && dir != "/") dir = DirName(dir);
      if (!S_ISDIR(st.st_mode)) {
        return Status::Error(o.flag + "=" + o.path + ": " + dir + " is not a directory");
      }
    } else {
      std::string resolved;
      if (Status r = Resolve(o.path, &resolved); !r.ok()) {
        return Status::Error(o.flag + "=" + r.message());
      }
      dir = DirName(resolved);
    }
    // The temporary is created beside the target and renamed onto it: the directory itself must
    // be writable, even when the target file exists and is.
    if (::access(dir.c_str(), W_OK | X_OK) != 0) {
      return Status::Error(o.flag + "=" + o.path + ": the directory " + dir +
                           " is not writable (" + std::strerror(errno) + ")");
    }
  }
  return Status::Ok();
}

Status OutputSet::StagingPath(const std::string& path, std::string* resolved,
                              std::string* temporary, bool* direct_out) {
  for (const Entry& o : outputs_) {
    if (o.path == path && o.create_directory) {
      if (Status s = EnsureDirectories(DirName(path)); !s.ok()) return s;
    }
  }
  // A device, FIFO or socket (/dev/null, /dev/stdout through /proc) is written straight at commit:
  // its contents are staged in a private directory under $TMPDIR, never beside it.
  // The same for a file descriptor named through /dev/stdout, /dev/fd/N or /proc: the shell's
  // redirection target must receive the text, not be replaced by a new file.
  struct stat target;
  const bool exists = ::stat(path.c_str(), &target) == 0;
  const bool descriptor = path.rfind("/dev/std", 0) == 0 || path.rfind("/dev/fd/", 0) == 0 ||
                          path.rfind("/proc/", 0) == 0;
  const bool direct = exists && !S_ISDIR(target.st_mode) && (descriptor || !S_ISREG(target.st_mode));
  *direct_out = direct;
  if (direct) {
    *resolved = path;
  } else if (Status s = Resolve(path, resolved); !s.ok()) {
    return s;
  }
  std::string dir = DirName(*resolved);
  if (direct) {
    const char* tmp = std::getenv("TMPDIR");
    dir = tmp && *tmp ? tmp : "/tmp";
  }
  auto it = staging_dirs_.find(dir);
  if (it == staging_dirs_.end()) {
    RemoveStaleStaging(dir);
    std::string tmpl = dir + "/.lpoe-staging-" + std::to_string(::getpid()) + "-XXXXXX";
    if (::mkdtemp(&tmpl[0]) == nullptr) {
      return Status::Error(path + ": cannot create a temporary directory in " + dir + ": " +
                           std::strerror(errno));
    }
    RegisterCleanup(tmpl);
    it = staging_dirs_.emplace(dir, tmpl).first;
  }
  *temporary = it->second + "/" + BaseName(*resolved);
  // Two direct targets with one base name (/dev/stdout, /dev/fd/stdout) need distinct names.
  for (int k = 1; direct && std::any_of(staged_.begin(), staged_.end(), [&](const Staged& s) {
         return s.temporary == *temporary;
       }); ++k) {
    *temporary = it->second + "/" + std::to_string(k) + "." + BaseName(*resolved);
  }
  RegisterCleanup(*temporary);
  RegisterCleanup(*temporary + ".tmp");  // a writer's own temporary (plots)
  return Status::Ok();
}

StagedFile::~StagedFile() {
  if (fd_ >= 0) ::close(fd_);
}

Status StagedFile::Create(const std::string& temporary) {
  if (fd_ >= 0) return Status::Error(path_ + ": already open");
  path_ = temporary;
  fd_ = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
  if (fd_ < 0) return Status::Error(temporary + ": cannot create: " + std::strerror(errno));
  return Status::Ok();
}

Status StagedFile::Append(const std::string& text) {
  if (fd_ < 0) return Status::Error(path_ + ": not open");
  return WriteAll(fd_, text.data(), text.size(), path_);
}

Status StagedFile::Close() {
  if (fd_ < 0) return Status::Error(path_ + ": not open");
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) return Status::Error(path_ + ": cannot close: " + std::strerror(errno));
  return Status::Ok();
}

Status OutputSet::Stage(const std::string& path, const std::string& contents) {
  return StageWith(path, [&contents](const std::string& tmp) {
    StagedFile file;
    Status s = file.Create(tmp);
    if (s.ok()) s = file.Append(contents);
    if (s.ok()) s = file.Close();
    return s;
  });
}

Status OutputSet::StageWith(const std::string& path,
                            const std::function<Status(const std::string&)>& writer) {
  Staged st;
  st.path = path;
  if (Status s = StagingPath(path, &st.resolved, &st.temporary, &st.direct); !s.ok()) return s;
  staged_.push_back(st);  // before writing: Discard() removes a partial file
  if (Status s = writer(st.temporary); !s.ok()) return s;
  struct stat info;
  if (::lstat(st.temporary.c_str(), &info) != 0 || !S_ISREG(info.st_mode)) {
    return Status::Error(path + ": the writer left no file");
  }
  return Status::Ok();
}

Status OutputSet::Commit(std::vector<std::string>* written) {
  const mode_t mask = ::umask(0);
  ::umask(mask);
  // Phase 1: every regular temporary complete, with its mode, and flushed; every target checked.
  for (const Staged& s : staged_) {
    struct stat target;
    const bool exists = ::stat(s.resolved.c_str(), &target) == 0;
    if (exists && S_ISDIR(target.st_mode)) {
      return Status::Error(s.path + ": is a directory; nothing written there");
    }
    if (s.direct) continue;
    const mode_t mode = exists ? (target.st_mode & 07777) : (0666 & ~mask);
    const int fd = ::open(s.temporary.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) return Status::Error(s.temporary + ": cannot open: " + std::strerror(errno));
    const bool ok = ::fchmod(fd, mode) == 0 && ::fsync(fd) == 0;
    ::close(fd);
    if (!ok) return Status::Error(s.temporary + ": cannot flush: " + std::strerror(errno));
  }
  // Phase 2: devices, FIFOs, sockets and descriptors (staged under $TMPDIR) written straight,
  // before any file is replaced: a write that fails (/dev/full) leaves every file as it was.
  for (const Staged& s : staged_) {
    if (!s.direct) continue;
    std::string contents;
    if (Status r = ReadAll(s.temporary, &contents); !r.ok()) return r;
    // A descriptor of this process is written through itself, at its own offset (opening
    // /proc/self/fd/1 anew would start at 0 over what the tool printed before).
    int fd = DescriptorOf(s.path);
    const bool own = fd < 0;
    if (own) fd = ::open(s.path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
    if (fd < 0) return Status::Error(s.path + ": cannot open: " + std::strerror(errno));
    Status w = WriteAll(fd, contents.data(), contents.size(), s.path);
    if (own && ::close(fd) != 0 && w.ok()) {
      w = Status::Error(s.path + ": cannot close: " + std::strerror(errno));
    }
    if (!w.ok()) return w;
  }
  // Phase 3: the files renamed into place together. An existing target is first linked into the
  // staging directory (same directory, same file system), so that a rename that fails puts back
  // every file renamed before it.
  struct Done {
    const Staged* staged;
    std::string backup;  // empty: the target did not exist (removed on rollback)
  };
  std::vector<Done> done;
  auto rollback = [&]() {
    for (auto it = done.rbegin(); it != done.rend(); ++it) {
      if (!it->backup.empty()) {
        ::rename(it->backup.c_str(), it->staged->resolved.c_str());
      } else {
        ::unlink(it->staged->resolved.c_str());
      }
    }
  };
  int backups = 0;
  for (const Staged& s : staged_) {
    if (s.direct) continue;
    Done d{&s, ""};
    struct stat target;
    if (::lstat(s.resolved.c_str(), &target) == 0 && S_ISREG(target.st_mode)) {
      const std::string backup =
          DirName(s.temporary) + "/.backup-" + std::to_string(backups++);
      RegisterCleanup(backup);
      if (::link(s.resolved.c_str(), backup.c_str()) == 0) d.backup = backup;
    }
    if (::rename(s.temporary.c_str(), s.resolved.c_str()) != 0) {
      const std::string why = std::strerror(errno);
      if (!d.backup.empty()) ::unlink(d.backup.c_str());
      rollback();
      return Status::Error(s.path + ": cannot rename the temporary onto it: " + why +
                           " (no output replaced)");
    }
    done.push_back(d);
  }
  for (const Done& d : done) {
    if (!d.backup.empty()) {
      ::unlink(d.backup.c_str());
      UnregisterCleanup(d.backup);
    }
  }
  for (const Staged& s : staged_) {
    if (written) written->push_back(s.path);
  }
  for (const auto& [dir, staging] : staging_dirs_) {
    const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0) {
      ::fsync(dfd);
      ::close(dfd);
    }
  }
  Discard();
  return Status::Ok();
}

void OutputSet::Discard() {
  for (const Staged& s : staged_) {
    ::unlink(s.temporary.c_str());
    ::unlink((s.temporary + ".tmp").c_str());
    UnregisterCleanup(s.temporary);
    UnregisterCleanup(s.temporary + ".tmp");
  }
  for (const auto& [dir, staging] : staging_dirs_) {
    ::rmdir(staging.c_str());
    UnregisterCleanup(staging);
  }
  staged_.clear();
  staging_dirs_.clear();
}

}  // namespace tools
}  // namespace lpoe
