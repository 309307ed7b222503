// tools::OutputSet (output_files.h) in-process: staging leaves the targets untouched until Commit,
// a discarded set leaves nothing behind, and SIGTERM removes the temporaries.
#include "common/output_files.h"

#include <dirent.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "file_util.h"
#include "report/json_text.h"
#include "common/tool_common.h"

namespace lpoe {
namespace tools {
namespace {
namespace output_files_test {

using ::lpoe::testing::Exists;
using ::lpoe::testing::ListDir;
using ::lpoe::testing::ReadAll;

class OutputFiles : public ::testing::Test {
 protected:
  ::lpoe::testing::TempDir temp_{"lpoe_outputs"};
  std::string dir_ = temp_.path();
};

TEST_F(OutputFiles, NothingMovesBeforeCommit) {
  const std::string a = dir_ + "/a.txt";
  {
    OutputSet out;
    out.AddOutput("--a", a);
    ASSERT_TRUE(out.Check().ok());
    ASSERT_TRUE(out.Stage(a, "one\n").ok());
    EXPECT_EQ(ListDir(dir_).size(), 1u);  // the private staging directory only
    EXPECT_NE(ListDir(dir_)[0], "a.txt");
  }  // discarded
  EXPECT_TRUE(ListDir(dir_).empty());
  OutputSet out;
  out.AddOutput("--a", a);
  ASSERT_TRUE(out.Stage(a, "two\n").ok());
  std::vector<std::string> written;
  ASSERT_TRUE(out.Commit(&written).ok());
  EXPECT_EQ(written, std::vector<std::string>{a});
  EXPECT_EQ(ReadAll(a), "two\n");
  EXPECT_EQ(ListDir(dir_), std::vector<std::string>{"a.txt"});
}

TEST_F(OutputFiles, MissingDirectoryIsRefusedUnlessCreated) {
  OutputSet out;
  out.AddOutput("--report", dir_ + "/no/such/r.json");
  const Status s = out.Check();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("--report"), std::string::npos) << s.message();
  OutputSet created;
  created.AddOutput("--plots_dir", dir_ + "/x/y/p.png", true);
  ASSERT_TRUE(created.Check().ok());
  ASSERT_TRUE(created.Stage(dir_ + "/x/y/p.png", "png").ok());
  ASSERT_TRUE(created.Commit(nullptr).ok());
  EXPECT_EQ(ReadAll(dir_ + "/x/y/p.png"), "png");
}

// A crash (a fault in a library such as PLplot, or abort) leaves no .lpoe-staging-* directory: the
// temporaries go, and the process still dies of its signal.
TEST_F(OutputFiles, CrashRemovesTheTemporaries) {
  for (int sig : {SIGSEGV, SIGABRT}) {
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      OutputSet out;
      out.AddOutput("--a", dir_ + "/a.txt");
      if (!out.Stage(dir_ + "/a.txt", "partial").ok()) _exit(3);
      if (ListDir(dir_).empty()) _exit(5);  // staged beside the target
      if (sig == SIGSEGV) {
        // A real fault, re-executed after the handler restores the previous action: a write to a
        // read-only page (no undefined behaviour a sanitizer would stop at first).
        void* page = mmap(nullptr, 4096, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (page == MAP_FAILED) _exit(6);
        *static_cast<volatile char*>(page) = 1;
      } else {
        std::abort();
      }
      _exit(4);  // not reached
    }
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    // Dies of the signal (or, under a sanitizer whose handler was chained to, of its abort or
    // exit after its report); never reaches the code after the crash.
    EXPECT_TRUE((WIFSIGNALED(status) && (WTERMSIG(status) == sig || WTERMSIG(status) == SIGABRT)) ||
                (WIFEXITED(status) && WEXITSTATUS(status) != 4 && WEXITSTATUS(status) != 0 &&
                 WEXITSTATUS(status) != 3 && WEXITSTATUS(status) != 5 && WEXITSTATUS(status) != 6))
        << "status " << status;
    EXPECT_TRUE(ListDir(dir_).empty()) << "signal " << sig;
  }
}

TEST_F(OutputFiles, SigtermRemovesTheTemporaries) {
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    OutputSet out;
    out.AddOutput("--a", dir_ + "/a.txt");
    if (!out.Stage(dir_ + "/a.txt", "partial").ok()) _exit(3);
    raise(SIGTERM);
    _exit(4);  // not reached
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM);
  EXPECT_TRUE(ListDir(dir_).empty());
}


// An output whose directory this process cannot write is refused by Check(), before any work
// (the temporary is created beside the target: a writable target in a read-only directory fails
// at commit otherwise).
TEST_F(OutputFiles, UnwritableDirectoryIsRefusedByCheck) {
  const std::string ro = dir_ + "/ro";
  ASSERT_EQ(::mkdir(ro.c_str(), 0555), 0);
  ASSERT_EQ(::chmod(dir_.c_str(), 0755), 0);  // searchable by the unprivileged child below
  // Root writes every directory: the check runs in a child that drops to an unprivileged user.
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    if (::geteuid() == 0 && (::setgid(65534) != 0 || ::setuid(65534) != 0)) _exit(10);
    OutputSet out;
    out.AddOutput("--output", ro + "/x.csv");
    const Status s = out.Check();
    if (s.ok()) _exit(1);
    if (s.message().find("not writable") == std::string::npos) _exit(2);
    // A writable directory beside it passes.
    OutputSet fine;
    fine.AddOutput("--output", "/tmp/lpoe_output_files_test_unused.csv");
    _exit(fine.Check().ok() ? 0 : 3);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  if (WEXITSTATUS(status) == 10) GTEST_SKIP() << "cannot drop privileges here";
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: accepted, 2: another message, 3: /tmp refused";
  ::chmod(ro.c_str(), 0755);
}

// A streamed output (StagedFile inside StageWith) commits like a staged string, and is discarded
// with the set when the run fails.
TEST_F(OutputFiles, StreamedOutputCommitsOrVanishes) {
  const std::string a = dir_ + "/a.csv", b = dir_ + "/b.json";
  {
    OutputSet out;
    out.AddOutput("--output", a);
    out.AddOutput("--report", b);
    ASSERT_TRUE(out.Check().ok());
    ASSERT_TRUE(out.StageWith(a, [](const std::string& tmp) {
                     StagedFile f;
                     Status s = f.Create(tmp);
                     for (int k = 0; k < 3 && s.ok(); ++k) s = f.Append("row\n");
                     return s.ok() ? f.Close() : s;
                   }).ok());
    // The report fails: neither file appears.
  }
  EXPECT_FALSE(Exists(a));
  EXPECT_FALSE(Exists(b));
  for (const std::string& name : ListDir(dir_)) EXPECT_EQ(name.find(".lpoe-staging"), std::string::npos) << name;
  OutputSet out;
  out.AddOutput("--output", a);
  ASSERT_TRUE(out.StageWith(a, [](const std::string& tmp) {
                   StagedFile f;
                   Status s = f.Create(tmp);
                   if (s.ok()) s = f.Append("x\n");
                   if (s.ok()) s = f.Append("y\n");
                   return s.ok() ? f.Close() : s;
                 }).ok());
  ASSERT_TRUE(out.Commit(nullptr).ok());
  EXPECT_EQ(ReadAll(a), "x\ny\n");
}

// ---- All outputs committed together.

// A device that refuses the write (/dev/full: ENOSPC) staged after two files: Commit fails and
// both files are as they were; nothing of the run is left in the directory.
TEST_F(OutputFiles, FailingDeviceLeavesEveryFileAsItWas) {
  if (!Exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const std::string a = dir_ + "/keep.script", b = dir_ + "/new.json";
  ASSERT_TRUE(::lpoe::testing::WriteAll(a, "old program\n"));
  {
    OutputSet out;
    out.AddOutput("--output", a);
    out.AddOutput("--html_report", b);
    out.AddOutput("--report", "/dev/full");
    ASSERT_TRUE(out.Check().ok());
    ASSERT_TRUE(out.Stage(a, "new program\n").ok());
    ASSERT_TRUE(out.Stage(b, "{}\n").ok());
    ASSERT_TRUE(out.Stage("/dev/full", "{\"report\": 1}\n").ok());
    std::vector<std::string> written;
    const Status s = out.Commit(&written);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("/dev/full"), std::string::npos) << s.message();
    EXPECT_TRUE(written.empty());
    EXPECT_EQ(ReadAll(a), "old program\n");
    EXPECT_FALSE(Exists(b));
  }  // the failed run ends: its temporaries go
  EXPECT_EQ(ListDir(dir_), std::vector<std::string>{"keep.script"});
}

// A staging directory of a process that no longer exists (killed by SIGKILL before it could
// clean up) is removed by the next run into that directory; one of a live process is not.
TEST_F(OutputFiles, StaleStagingOfDeadProcessesIsRemoved) {
  const pid_t child = ::fork();
  if (child == 0) _exit(0);
  ASSERT_GT(child, 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);  // reaped: the pid names no process now
  const std::string dead = dir_ + "/.lpoe-staging-" + std::to_string(child) + "-AbC123";
  const std::string live = dir_ + "/.lpoe-staging-" + std::to_string(::getppid()) + "-XyZ789";
  for (const std::string& d : {dead, live}) {
    ASSERT_EQ(::mkdir(d.c_str(), 0700), 0);
    ASSERT_TRUE(::lpoe::testing::WriteAll(d + "/out.yaml", "partial"));
    ASSERT_TRUE(::lpoe::testing::WriteAll(d + "/out.yaml.tmp", "partial"));
  }
  OutputSet out;
  out.AddOutput("--output", dir_ + "/out.yaml");
  ASSERT_TRUE(out.Stage(dir_ + "/out.yaml", "model\n").ok());
  ASSERT_TRUE(out.Commit(nullptr).ok());
  EXPECT_FALSE(Exists(dead));
  EXPECT_TRUE(Exists(live + "/out.yaml"));
  EXPECT_EQ(ReadAll(dir_ + "/out.yaml"), "model\n");
}

// ---- Names of any bytes.

TEST(ValidUtf8, KeepsValidTextAndReplacesEachInvalidSubpart) {
  const std::string valid = "joint \xc3\xa9\xe2\x82\xac\xf0\x9f\x98\x80 ok";
  EXPECT_EQ(ValidUtf8(valid), valid);
  const std::string r = "\xef\xbf\xbd";
  EXPECT_EQ(ValidUtf8("a\xff" "b"), "a" + r + "b");
  EXPECT_EQ(ValidUtf8("\x80\xbf"), r + r);                // stray continuation bytes
  EXPECT_EQ(ValidUtf8("\xc3"), r);                         // truncated at the end
  EXPECT_EQ(ValidUtf8("\xe2\x82x"), r + "x");              // truncated in the middle
  EXPECT_EQ(ValidUtf8("\xc0\xaf"), r + r);                // overlong
  EXPECT_EQ(ValidUtf8("\xed\xa0\x80"), r + r + r);        // a surrogate
  EXPECT_EQ(ValidUtf8("\xf4\x90\x80\x80"), r + r + r + r);  // above U+10FFFF
  // What nlohmann::json's replace handler gives, so the JSON and HTML agree.
  for (const std::string& s : {std::string("a\xff"), std::string("\xe2\x82x\xc3"),
                               std::string("\xed\xa0\x80z"), std::string("\xf0\x9f\x98")}) {
    const std::string dumped = nlohmann::json(s).dump(-1, ' ', false,
                                                      nlohmann::json::error_handler_t::replace);
    EXPECT_EQ(nlohmann::json::parse(dumped).get<std::string>(), ValidUtf8(s));
  }
}

TEST(JsonText, NeverThrowsOnInvalidUtf8) {
  nlohmann::json j = {{"model", "robot\xff\xfe"}, {"path", std::string("a\0b\x80", 4)}};
  std::string text;
  ASSERT_NO_THROW(text = JsonText(j));
  const nlohmann::json back = nlohmann::json::parse(text);
  EXPECT_EQ(back["model"].get<std::string>(), "robot\xef\xbf\xbd\xef\xbf\xbd");
  EXPECT_EQ(text.back(), '\n');
}

TEST(TruncateUtf8, CutsAtACharacterBoundary) {
  EXPECT_EQ(TruncateUtf8("short", 10), "short");
  EXPECT_EQ(TruncateUtf8("abcdef", 3), "abc...");
  // "\xc3\xa9" is one character: cut before it, never inside.
  EXPECT_EQ(TruncateUtf8("ab\xc3\xa9", 3), "ab...");
  EXPECT_EQ(ValidUtf8(TruncateUtf8(std::string(50, 'x') + "\xe2\x82\xac\xe2\x82\xac", 52)),
            TruncateUtf8(std::string(50, 'x') + "\xe2\x82\xac\xe2\x82\xac", 52));
}

}  // namespace output_files_test
}  // namespace
}  // namespace tools
}  // namespace lpoe
