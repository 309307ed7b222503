// Safe outputs for every tool: collisions checked by file identity, everything staged in private
// temporaries and renamed into place together once the run's final status is known.
//
//   tools::OutputSet out;
//   out.AddInput("--model", model_path);              // every file the run reads
//   out.AddOutput("--output", output_path);           // every file it will write
//   if (Status s = out.Check(); !s.ok()) ...          // exit 1: a collision
//   ... run; on failure just return (the destructor removes whatever was staged) ...
//   out.Stage(output_path, text);                     // or StageWith(path, writer) for a file
//                                                     // written by a library (plots)
//   if (Status s = out.Commit(&written); !s.ok()) ... // exit 6
//
// Identity: an existing file is its device and inode; a file not yet there is its resolved path
// (symlinks followed, "." and ".." and linked directories resolved). So "d/./x", "d/../d/x", a link
// to x, and x itself are one file; an output named like a plot in --plots_dir collides with it.
// Targets: a symlink is resolved and its target replaced (the link stays); a non-regular target
// (/dev/null, a FIFO) or a descriptor (/dev/stdout, /dev/fd/N, /proc/...) is written straight, never
// replaced (its contents staged under $TMPDIR); a directory is refused, and so is an output whose
// directory the process cannot write (checked by Check(), before any work).
// Temporaries: one private directory per target directory, created by mkdtemp (mode 0700) in it,
// files inside created with O_EXCL | O_NOFOLLOW; so nothing planted can be followed, and
// concurrent runs into one directory never share a temporary. SIGINT/SIGTERM remove them.
#ifndef LPOE_TOOLS_OUTPUT_FILES_H_
#define LPOE_TOOLS_OUTPUT_FILES_H_

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "lpoe/status.h"

namespace lpoe {
namespace tools {

// Creates `dir` and its missing parents (mode 0755). Existing non-directories are an error.
Status EnsureDirectories(const std::string& dir);

// A staged temporary written in pieces (a streamed output: StageWith's writer creates it on the
// temporary it is given, appends, and closes it). Created with O_EXCL | O_NOFOLLOW, mode 0600.
class StagedFile {
 public:
  StagedFile() = default;
  StagedFile(const StagedFile&) = delete;
  StagedFile& operator=(const StagedFile&) = delete;
  ~StagedFile();  // closes (the OutputSet removes the file when it is not committed)

  Status Create(const std::string& temporary);
  Status Append(const std::string& text);
  Status Close();

 private:
  int fd_ = -1;
  std::string path_;
};

class OutputSet {
 public:
  OutputSet() = default;
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;
  ~OutputSet();  // removes staged files not committed

  // `flag` names the path in messages ("--output"). Empty paths are ignored. With
  // `create_directory` the output's directory (and its parents) is created when it is staged;
  // nothing is created before (a failed run leaves no empty directory behind).
  void AddInput(const std::string& flag, const std::string& path);
  void AddOutput(const std::string& flag, const std::string& path, bool create_directory = false);

  // Every output against every input and every other output, by identity; outputs that are
  // directories, or whose directory does not exist (unless created), are refused.
  Status Check() const;

  // Writes `contents` to a private temporary for `path` (an output added before).
  Status Stage(const std::string& path, const std::string& contents);
  // Lets `writer` write the temporary (its argument) for `path`.
  Status StageWith(const std::string& path,
                   const std::function<Status(const std::string& temporary)>& writer);

  // Moves every staged file into place (in the order staged) and lists the paths in `written`.
  Status Commit(std::vector<std::string>* written);

 private:
  struct Entry {
    std::string flag, path;
    bool create_directory = false;
  };
  struct Staged {
    std::string path, resolved, temporary;
    bool direct = false;  // written straight to `path` (device, FIFO, descriptor)
  };
  Status StagingPath(const std::string& path, std::string* resolved, std::string* temporary,
                     bool* direct);
  void Discard();

  std::vector<Entry> inputs_, outputs_;
  std::map<std::string, std::string> staging_dirs_;  // resolved target directory -> private dir
  std::vector<Staged> staged_;
};

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_OUTPUT_FILES_H_
