// URScript parser: motion targets of movej / movel / movep / movec / servoj.
//
// Understood: literal poses p[x, y, z, rx, ry, rz] (m, rotation vector) and joint lists [..] (rad),
// given inline or through a variable assigned a literal earlier (`global Waypoint_1_p=p[...]`);
// pose_trans(feature, target) with a literal or variable feature; get_inverse_kin(target,
// qnear=joints); set_tcp(pose) for the motions that follow. Anything else in a target position is
// computed at run time: reported, not compensated. The text is read in order, as the controller
// would run a straight-line program; a variable reassigned later is a new value from then on.
#include <algorithm>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/program.h"
#include "programs/program_lexer.h"

namespace lpoe {
namespace {

using program_internal::Token;
using program_internal::TokenView;

constexpr int kMetreDecimals = 10;  // 0.1 nm; radians alike

using Use = program_internal::TargetUse;

struct Var {
  int record = -1;      // the literal's record
  std::string runtime;  // non-empty: not a literal (why)
};

class UrParser {
 public:
  UrParser(std::string_view text, const std::vector<Token>& tokens, ParsedProgram* program)
      : v_(text, tokens), program_(program) {}

  Status Run() {
    const int n = v_.size();
    std::vector<int> depth(n, 0);
    int d = 0;
    for (int i = 0; i < n; ++i) {
      if (v_[i].kind == Token::kPunct && v_[i].match > i) {
        depth[i] = d++;
      } else if (v_[i].kind == Token::kPunct && v_[i].match >= 0 && v_[i].match < i) {
        depth[i] = --d;
      } else {
        depth[i] = d;
      }
    }
    for (int i = 0; i < n; ++i) {
      if (!v_.IsIdent(i)) continue;
      const std::string_view name = v_.Text(i);
      const bool member = i > 0 && v_.Is(i - 1, ".");
      if (member) continue;
      // Assignment at statement level: [global|local] NAME = value
      if (depth[i] == 0 && v_.Is(i + 1, "=") && !v_.Is(i + 2, "=") && i + 2 < n) {
        // The value ends at the end of its line (URScript statements are lines), or before a
        // separator at its depth. The line is found first, so that each assignment reads only its
        // own tokens (parsing stays linear in the text).
        int line_end = i + 2;
        while (line_end < n && v_[line_end].line == v_[i + 2].line) {
          line_end = v_[line_end].match > line_end ? v_[line_end].match + 1 : line_end + 1;
        }
        const int e = v_.ExpressionEnd(i + 2, std::min(line_end, n));
        int end = i + 2;
        while (end < e && v_[end].line == v_[i + 2].line) {
          end = v_[end].match > end ? v_[end].match + 1 : end + 1;
        }
        if (Status s = Assign(std::string(name), i + 2, end); !s.ok()) return s;
        i = i + 1;
        continue;
      }
      if (!v_.Is(i + 1, "(")) continue;
      const int open = i + 1;
      if (name == "set_tcp") {
        const auto items = v_.Items(open);
        if (items.empty()) return Error(v_[i].line, "set_tcp() needs a pose");
        SE3d pose;
        std::string why;
        if (FramePose(items[0].first, items[0].second, &pose, &why)) {
          tcp_ = pose;
          tcp_name_ = v_.Excerpt(items[0].first, items[0].second);
          tcp_runtime_.clear();
        } else {
          tcp_runtime_ = "the TCP (set_tcp on line " + std::to_string(v_[i].line) + ") " + why;
        }
        continue;
      }
      if (name == "movej" || name == "movel" || name == "movep" || name == "movec" ||
          name == "servoj") {
        const auto items = v_.Items(open);
        std::vector<std::pair<int, int>> positional;
        for (const auto& it : items) {
          if (v_.IsIdent(it.first) && v_.Is(it.first + 1, "=")) continue;  // a=..., v=...
          positional.push_back(it);
        }
        const int wanted = name == "movec" ? 2 : 1;
        if (static_cast<int>(positional.size()) < wanted) {
          return Error(v_[i].line, std::string(name) + "() needs " +
                                       (wanted == 2 ? "a via pose and a target" : "a target"));
        }
        for (int k = 0; k < wanted; ++k) {
          std::string inline_name = std::string(name) + ":" + std::to_string(v_[i].line);
          if (wanted == 2) inline_name += k == 0 ? ":via" : ":to";
          if (Status s = Target(positional[k].first, positional[k].second, inline_name, name);
              !s.ok()) {
            return s;
          }
        }
        i = v_[open].match;
      }
    }
    return Finish();
  }

 private:
  Status Error(int line, const std::string& what) const {
    return Status::Error("line " + std::to_string(line) + ": " + what);
  }

  // A literal p[...] at [a, e): its 6 numbers. Returns 1 literal, 0 not a literal, -1 malformed
  // (error set).
  int LiteralPose(int a, int e, std::vector<ProgramNumber>* numbers, Status* error) const {
    if (!(v_.Is(a, "p") && v_.Is(a + 1, "[") && v_[a + 1].match == e - 1)) return 0;
    return LiteralList(a + 1, numbers, error, 6);
  }
  // A literal list [...] whose bracket is at `open`: all numbers (count `want` when > 0).
  int LiteralList(int open, std::vector<ProgramNumber>* numbers, Status* error, int want) const {
    numbers->clear();
    for (const auto& it : v_.Items(open)) {
      ProgramNumber num;
      if (v_.Number(it.first, &num, kMetreDecimals) != it.second) return 0;
      numbers->push_back(num);
    }
    if (want > 0 && static_cast<int>(numbers->size()) != want) {
      *error = Error(v_[open].line,
                     "a pose p[...] needs 6 numbers (x, y, z in m, rx, ry, rz), "
                     "found " +
                         std::to_string(numbers->size()));
      return -1;
    }
    return numbers->empty() ? 0 : 1;
  }

  static SE3d PoseOf(const std::vector<ProgramNumber>& v) {
    SE3d T;
    T.t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value) * 1000.0;
    T.R = ExpSO3(Eigen::Vector3d(v[3].value, v[4].value, v[5].value));
    return T;
  }

  // A frame or TCP: a literal pose or a variable holding one. Marks the variable's record as not
  // a target.
  bool FramePose(int a, int e, SE3d* pose, std::string* why) {
    std::vector<ProgramNumber> numbers;
    Status error;
    const int lit = LiteralPose(a, e, &numbers, &error);
    if (lit == 1) {
      *pose = PoseOf(numbers);
      return true;
    }
    if (e == a + 1 && v_.IsIdent(a)) {
      const auto it = vars_.find(std::string(v_.Text(a)));
      if (it == vars_.end()) {
        *why = "is the variable '" + std::string(v_.Text(a)) + "', not assigned a literal before";
        return false;
      }
      if (!it->second.runtime.empty()) {
        *why = "is computed at run time (" + it->second.runtime + ")";
        return false;
      }
      const ProgramTarget& r = program_->targets[it->second.record];
      if (r.kind != ProgramTargetKind::kCartesian) {
        *why = "is a joint list, not a pose";
        return false;
      }
      frame_use_[it->second.record] = v_[a].line;
      *pose = PoseOf(r.numbers);
      return true;
    }
    *why = "is computed at run time: " + v_.Excerpt(a, e);
    return false;
  }

  Status Assign(const std::string& name, int a, int e) {
    std::vector<ProgramNumber> numbers;
    Status error;
    int lit = LiteralPose(a, e, &numbers, &error);
    if (lit < 0) return error;
    ProgramTargetKind kind = ProgramTargetKind::kCartesian;
    if (lit == 0 && v_.Is(a, "[") && v_[a].match == e - 1) {
      lit = LiteralList(a, &numbers, &error, 0);
      kind = ProgramTargetKind::kJoint;
    }
    Var var;
    if (lit == 1) {
      var.record = NewRecord(name, numbers, kind, v_[a].line);
    } else {
      var.runtime = "assigned at run time on line " + std::to_string(v_[a].line);
    }
    vars_[name] = var;
    return Status::Ok();
  }

  int NewRecord(const std::string& name, const std::vector<ProgramNumber>& numbers,
                ProgramTargetKind kind, int line) {
    ProgramTarget t;
    t.name = name;
    t.line = line;
    t.kind = kind;
    t.numbers = numbers;
    t.pose_encoding = PoseEncoding::kMetresRotationVector;
    t.joint_encoding = JointEncoding::kRadians;
    t.tcp_name = "flange";
    t.frame_name = "base";
    program_->targets.push_back(std::move(t));
    uses_.emplace_back();
    frame_use_.push_back(0);
    return static_cast<int>(program_->targets.size()) - 1;
  }

  int RuntimeRecord(const std::string& name, int line, const std::string& reason) {
    ProgramTarget t;
    t.name = name;
    t.line = line;
    t.compensable = false;
    t.reason = reason;
    program_->targets.push_back(std::move(t));
    uses_.emplace_back();
    frame_use_.push_back(0);
    return static_cast<int>(program_->targets.size()) - 1;
  }

  // A motion target at [a, e).
  Status Target(int a, int e, const std::string& inline_name, std::string_view instruction) {
    Use use;
    use.line = v_[a].line;
    use.order = ++order_;
    use.tcp = tcp_;
    use.tcp_name = tcp_name_;
    use.frame_name = "base";
    int x = a, xe = e;
    // get_inverse_kin(target, qnear=joints, ...)
    if (v_.Is(x, "get_inverse_kin") && v_.Is(x + 1, "(") && v_[x + 1].match == xe - 1) {
      const auto items = v_.Items(x + 1);
      if (items.empty()) return Error(use.line, "get_inverse_kin() needs a pose");
      for (size_t k = 1; k < items.size(); ++k) {
        int q = items[k].first;
        if (v_.Is(q, "qnear") && v_.Is(q + 1, "=")) {
          q += 2;
        } else if (k != 1) {
          continue;
        }
        std::vector<ProgramNumber> numbers;
        Status error;
        if (v_.Is(q, "[") && v_[q].match == items[k].second - 1 &&
            LiteralList(q, &numbers, &error, 0) == 1) {
          for (const auto& nm : numbers) use.qnear.push_back(nm.value);
        } else if (items[k].second == q + 1 && v_.IsIdent(q)) {
          const auto it = vars_.find(std::string(v_.Text(q)));
          if (it != vars_.end() && it->second.runtime.empty()) {
            frame_use_[it->second.record] = v_[q].line;
            for (const auto& nm : program_->targets[it->second.record].numbers) {
              use.qnear.push_back(nm.value);
            }
          }
        }
      }
      x = items[0].first;
      xe = items[0].second;
    }
    // pose_trans(feature, target)
    if (v_.Is(x, "pose_trans") && v_.Is(x + 1, "(") && v_[x + 1].match == xe - 1) {
      const auto items = v_.Items(x + 1);
      if (items.size() != 2) return Error(use.line, "pose_trans() needs two poses");
      std::string why;
      if (!FramePose(items[0].first, items[0].second, &use.frame, &why)) {
        return Runtime(inline_name, use.line, "its feature frame " + why);
      }
      use.frame_name = v_.Excerpt(items[0].first, items[0].second);
      x = items[1].first;
      xe = items[1].second;
    }
    std::vector<ProgramNumber> numbers;
    Status error;
    int record = -1;
    const int lit = LiteralPose(x, xe, &numbers, &error);
    if (lit < 0) return error;
    if (lit == 1) {
      record = NewRecord(inline_name, numbers, ProgramTargetKind::kCartesian, v_[x].line);
    } else if (v_.Is(x, "[") && v_[x].match == xe - 1 && LiteralList(x, &numbers, &error, 0) == 1) {
      record = NewRecord(inline_name, numbers, ProgramTargetKind::kJoint, v_[x].line);
    } else if (xe == x + 1 && v_.IsIdent(x)) {
      const auto it = vars_.find(std::string(v_.Text(x)));
      if (it == vars_.end()) {
        return Runtime(std::string(v_.Text(x)), use.line,
                       "the variable is not assigned a literal earlier in the program");
      }
      if (!it->second.runtime.empty()) {
        return Runtime(std::string(v_.Text(x)), use.line, "the variable is " + it->second.runtime);
      }
      record = it->second.record;
    } else {
      return Runtime(inline_name, use.line, "computed at run time: " + v_.Excerpt(x, xe));
    }
    if (program_->targets[record].kind == ProgramTargetKind::kCartesian && !tcp_runtime_.empty()) {
      program_->targets[record].compensable = false;
      program_->targets[record].reason = tcp_runtime_;
    }
    (void)instruction;
    uses_[record].push_back(use);
    return Status::Ok();
  }

  Status Runtime(const std::string& name, int line, const std::string& reason) {
    RuntimeRecord(name, line, reason);
    ++order_;
    return Status::Ok();
  }

  // Resolves each record's context from its uses; drops the literals no motion uses.
  Status Finish() {
    std::vector<ProgramTarget> kept;
    kept.reserve(program_->targets.size());
    for (size_t k = 0; k < program_->targets.size(); ++k) {
      ProgramTarget& t = program_->targets[k];
      const std::vector<Use>& uses = uses_[k];
      // A literal no motion uses is data, not a target: a feature, TCP or qnear, or one of
      // Polyscope's companion variables (Waypoint_1_q of a movel waypoint). Left out.
      if (uses.empty() && !t.numbers.empty()) continue;
      if (!uses.empty()) {
        // Another feature matters for any target, another TCP for a Cartesian one.
        program_internal::ApplyTargetUses(uses, {"TCPs", "features", true}, &t);
        if (t.compensable && frame_use_[k] > 0 && t.kind == ProgramTargetKind::kCartesian) {
          t.compensable = false;
          t.reason = "also used as a feature or TCP (line " + std::to_string(frame_use_[k]) + ")";
        }
      }
      kept.push_back(std::move(t));
    }
    program_->targets = std::move(kept);
    return Status::Ok();
  }

  TokenView v_;
  ParsedProgram* program_;
  std::map<std::string, Var> vars_;
  std::vector<std::vector<Use>> uses_;  // per record
  std::vector<int> frame_use_;          // per record: line of a use as frame / TCP / qnear
  SE3d tcp_;
  std::string tcp_name_ = "flange";
  std::string tcp_runtime_;
  int order_ = 0;
};

}  // namespace

Status ParseUrScriptProgram(std::string_view text, ParsedProgram* program) {
  std::vector<Token> tokens;
  program_internal::LexerOptions options;
  options.comment = '#';
  options.single_quotes = true;
  if (Status s = program_internal::Tokenize(text, options, &tokens); !s.ok()) return s;
  UrParser parser(text, tokens, program);
  return parser.Run();
}

}  // namespace lpoe
