// tools::OutputSet (output_files.h) in-process: staging leaves the targets untouched until Commit,
// a discarded set leaves nothing behind, and SIGTERM removes the temporaries.
#include "output_files.h"

#include <dirent.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "file_util.h"

namespace lpoe {
namespace tools {
namespace {

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

}  // namespace
}  // namespace tools
}  // namespace lpoe
