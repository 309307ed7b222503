// ABB RAPID parser: robtarget / jointtarget declarations and inline targets of the
// motion instructions, with the tooldata and wobjdata they are used with.
//
// robtarget [[x, y, z], [q1, q2, q3, q4], [cf1, cf4, cf6, cfx], [eax_a .. eax_f]]: mm, quaternion
// w first; the quadrants cf1, cf4, cf6 seed the inverse kinematics and are rewritten from the
// compensated joints; cfx and the external axes are never touched. jointtarget [[j1 .. j6], [eax]]
// (degrees) with MoveAbsJ. tooldata [robhold, [[x, y, z], [q]], load] and wobjdata [robhold,
// ufprog, ufmec, uframe, oframe] resolved by name (tool0, wobj0 built in). A robtarget assigned
// anywhere
// (`p := ...`), an array element, Offs(...), RelTool(...), CRobT() ... are run-time values:
// reported, not compensated. Declarations are read first (RAPID data may follow the routines).
#include <algorithm>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/program.h"
#include "programs/program_lexer.h"

namespace lpoe {
namespace {

using program_internal::Lower;
using program_internal::Token;
using program_internal::TokenView;

constexpr int kMmDecimals = 4;
constexpr int kQuaternionDecimals = 9;
constexpr int kDegreeDecimals = 6;

using Use = program_internal::TargetUse;

struct Frame {
  SE3d pose;
  std::string runtime;  // non-empty: cannot be used (why)
  // RAPID's robhold (Technical reference manual - RAPID Instructions, Functions and Data types):
  // tooldata TRUE = the robot holds the tool, FALSE = a stationary tool; wobjdata TRUE = the robot
  // holds the work object (used with a stationary tool), FALSE = the work object is fixed.
  // `stationary` is true for a stationary tool (tooldata robhold FALSE) and for a work object held
  // by the robot (wobjdata robhold TRUE): such a tool and work object go together.
  bool stationary = false;
};

struct Motion {
  std::vector<int> targets;  // positional arguments that are targets
  int tool = -1;             // positional index of the tool; -1: the last one
  bool joint = false;
};

bool FindMotion(const std::string& lower, Motion* m) {
  static const char* kLinear[] = {"movel",     "movej",   "moveldo", "movejdo", "movelsync",
                                  "movejsync", "movelao", "movejao", "movelgo", "movejgo"};
  static const char* kCircular[] = {"movec", "movecdo", "movecsync", "movecao", "movecgo"};
  for (const char* s : kLinear) {
    if (lower == s) {
      *m = Motion{{0}, 3, false};
      return true;
    }
  }
  for (const char* s : kCircular) {
    if (lower == s) {
      *m = Motion{{0, 1}, 4, false};
      return true;
    }
  }
  if (lower == "moveabsj") {
    *m = Motion{{0}, 3, true};
    return true;
  }
  if (lower == "triggl" || lower == "triggj") {
    *m = Motion{{0}, -1, false};
    return true;
  }
  if (lower == "triggc") {
    *m = Motion{{0, 1}, -1, false};
    return true;
  }
  return false;
}

class RapidParser {
 public:
  RapidParser(std::string_view text, const std::vector<Token>& tokens, ParsedProgram* program)
      : v_(text, tokens), program_(program) {
    tools_["tool0"] = Frame();
    wobjs_["wobj0"] = Frame();
  }

  Status Run() {
    // Statements: the tokens between semicolons.
    std::vector<std::pair<int, int>> statements;
    int a = 0;
    for (int i = 0; i < v_.size(); ++i) {
      if (v_.Is(i, ";")) {
        statements.emplace_back(a, i);
        a = i + 1;
      }
    }
    // Pass 1: declarations and assignments.
    for (const auto& st : statements) {
      if (Status s = Declaration(st.first, st.second); !s.ok()) return s;
    }
    // Pass 2: motions, in order.
    for (const auto& st : statements) {
      if (Status s = MotionStatement(st.first, st.second); !s.ok()) return s;
    }
    return Finish();
  }

 private:
  Status Error(int line, const std::string& what) const {
    return Status::Error("line " + std::to_string(line) + ": " + what);
  }

  // The token at depth 0 in [a, e) where the statement proper starts (after PROC headers, IF
  // conditions...): a declaration keyword, a motion instruction, or an assignment's target.
  int Start(int a, int e, bool* declaration, bool* assignment) const {
    *declaration = *assignment = false;
    for (int i = a; i < e; ++i) {
      if (v_[i].kind == Token::kPunct && v_[i].match > i) {
        i = v_[i].match;
        continue;
      }
      if (!v_.IsIdent(i)) continue;
      if (v_.IsNoCase(i, "CONST") || v_.IsNoCase(i, "PERS") || v_.IsNoCase(i, "VAR")) {
        *declaration = true;
        return i;
      }
      Motion m;
      if (FindMotion(Lower(v_.Text(i)), &m)) return i;
      // NAME [.field]* [{...}] :=
      int k = i + 1;
      while (k + 1 < e && v_.Is(k, ".") && v_.IsIdent(k + 1)) k += 2;
      if (k < e && v_.Is(k, "{") && v_[k].match > k) k = v_[k].match + 1;
      if (k + 1 < e && v_.Is(k, ":") && v_.Is(k + 1, "=")) {
        *assignment = true;
        return i;
      }
    }
    return -1;
  }

  // A bracketed list of numbers [n, ...] exactly at [a, e); the count, or -1.
  int Numbers(int a, int e, int decimals, std::vector<ProgramNumber>* out) const {
    out->clear();
    if (!(v_.Is(a, "[") && v_[a].match == e - 1)) return -1;
    for (const auto& it : v_.Items(a)) {
      ProgramNumber n;
      if (v_.Number(it.first, &n, decimals) != it.second) return -1;
      out->push_back(n);
    }
    return static_cast<int>(out->size());
  }

  // [[x, y, z], [q1, q2, q3, q4]] at [a, e): a frame (tooldata tframe, wobjdata uframe/oframe).
  Status PoseLiteral(int a, int e, const std::string& what, SE3d* pose, bool* literal) const {
    *literal = false;
    if (!(v_.Is(a, "[") && v_[a].match == e - 1)) return Status::Ok();
    const auto items = v_.Items(a);
    if (items.size() != 2) {
      return Error(v_[a].line, what + ": a frame is [[x, y, z], [q1, q2, q3, q4]]");
    }
    std::vector<ProgramNumber> t, q;
    if (Numbers(items[0].first, items[0].second, kMmDecimals, &t) < 0 ||
        Numbers(items[1].first, items[1].second, kQuaternionDecimals, &q) < 0) {
      return Status::Ok();
    }
    if (t.size() != 3) {
      return Error(v_[a].line,
                   what + ": the position needs 3 numbers, found " + std::to_string(t.size()));
    }
    if (q.size() != 4) {
      return Error(v_[a].line, what +
                                   ": the orientation needs 4 quaternion numbers [q1, q2, q3, "
                                   "q4], found " +
                                   std::to_string(q.size()));
    }
    const Eigen::Vector4d qv(q[1].value, q[2].value, q[3].value, q[0].value);
    if (!(std::abs(qv.norm() - 1) < 1e-3)) {
      return Error(v_[a].line, what + ": the quaternion is not normalized");
    }
    pose->t = Eigen::Vector3d(t[0].value, t[1].value, t[2].value);
    pose->R = QuaternionToRotation<double>(qv / qv.norm());
    *literal = true;
    return Status::Ok();
  }

  // robtarget literal at [a, e): a record (index in *record), or -1 when not a literal.
  Status Robtarget(int a, int e, const std::string& name, int* record) {
    *record = -1;
    if (!(v_.Is(a, "[") && v_[a].match == e - 1)) return Status::Ok();
    const auto items = v_.Items(a);
    if (items.size() != 4) {
      return Error(v_[a].line, "robtarget " + name +
                                   ": expected [[x, y, z], [q1, q2, q3, q4], "
                                   "[cf1, cf4, cf6, cfx], [eax_a, ..., eax_f]], "
                                   "found " +
                                   std::to_string(items.size()) + " parts");
    }
    std::vector<ProgramNumber> t, q, conf, ext;
    const int nt = Numbers(items[0].first, items[0].second, kMmDecimals, &t);
    const int nq = Numbers(items[1].first, items[1].second, kQuaternionDecimals, &q);
    const int nc = Numbers(items[2].first, items[2].second, 0, &conf);
    const int ne = Numbers(items[3].first, items[3].second, 0, &ext);
    if (nt < 0 || nq < 0 || nc < 0 || ne < 0) return Status::Ok();  // not a literal
    if (nt != 3) {
      return Error(v_[a].line, "robtarget " + name + ": the position needs 3 numbers (mm), found " +
                                   std::to_string(nt));
    }
    if (nq != 4) {
      return Error(v_[a].line, "robtarget " + name +
                                   ": the orientation needs 4 quaternion "
                                   "numbers [q1, q2, q3, q4], found " +
                                   std::to_string(nq));
    }
    if (nc != 4) {
      return Error(v_[a].line, "robtarget " + name +
                                   ": confdata needs 4 numbers [cf1, cf4, cf6, "
                                   "cfx], found " +
                                   std::to_string(nc));
    }
    if (ne != 6) {
      return Error(v_[a].line,
                   "robtarget " + name + ": extjoint needs 6 numbers, found " + std::to_string(ne));
    }
    ProgramTarget r;
    r.name = name;
    r.line = v_[a].line;
    r.kind = ProgramTargetKind::kCartesian;
    r.pose_encoding = PoseEncoding::kMillimetresQuaternionWxyz;
    r.numbers = t;
    r.numbers.insert(r.numbers.end(), q.begin(), q.end());
    const int joints[3] = {0, 3, 5};
    for (int k = 0; k < 3; ++k) {
      ProgramTarget::Quadrant qd;
      qd.joint = joints[k];
      qd.number = conf[k];
      r.quadrants.push_back(qd);
    }
    *record = Add(std::move(r));
    return Status::Ok();
  }

  // jointtarget literal [[j1..j6], [eax]].
  Status Jointtarget(int a, int e, const std::string& name, int* record) {
    *record = -1;
    if (!(v_.Is(a, "[") && v_[a].match == e - 1)) return Status::Ok();
    const auto items = v_.Items(a);
    if (items.size() != 2) {
      return Error(v_[a].line, "jointtarget " + name +
                                   ": expected [[j1, ..., j6], [eax_a, ..., "
                                   "eax_f]]");
    }
    std::vector<ProgramNumber> j, ext;
    if (Numbers(items[0].first, items[0].second, kDegreeDecimals, &j) < 0 ||
        Numbers(items[1].first, items[1].second, 0, &ext) < 0) {
      return Status::Ok();
    }
    if (j.size() != 6 || ext.size() != 6) {
      return Error(v_[a].line, "jointtarget " + name + ": robax and extax need 6 numbers each");
    }
    ProgramTarget r;
    r.name = name;
    r.line = v_[a].line;
    r.kind = ProgramTargetKind::kJoint;
    r.joint_encoding = JointEncoding::kDegrees;
    r.numbers = j;
    *record = Add(std::move(r));
    return Status::Ok();
  }

  int Add(ProgramTarget r) {
    program_->targets.push_back(std::move(r));
    uses_.emplace_back();
    return static_cast<int>(program_->targets.size()) - 1;
  }

  Status Declaration(int a, int e) {
    bool declaration, assignment;
    const int s = Start(a, e, &declaration, &assignment);
    if (s < 0) return Status::Ok();
    if (assignment) {
      const std::string name = Lower(v_.Text(s));
      const std::string why = "assigned at run time on line " + std::to_string(v_[s].line);
      assigned_[name] = why;
      return Status::Ok();
    }
    if (!declaration) return Status::Ok();
    // CONST|PERS|VAR type name [{dims}] [:= value]
    const int type = s + 1, name_at = s + 2;
    if (!v_.IsIdent(type) || !v_.IsIdent(name_at) || name_at >= e) return Status::Ok();
    const std::string t = Lower(v_.Text(type));
    const std::string name(v_.Text(name_at));
    const std::string key = Lower(name);
    int k = name_at + 1;
    const bool array = k < e && v_.Is(k, "{");
    if (array && v_[k].match > k) k = v_[k].match + 1;
    const bool init = k + 1 < e && v_.Is(k, ":") && v_.Is(k + 1, "=");
    const int va = k + 2, ve = e;
    const bool is_var = v_.IsNoCase(s, "VAR");
    if (t == "robtarget" || t == "jointtarget") {
      // A name declared twice: which value a motion uses is not known (routine scopes are not
      // distinguished), so it is an error naming both lines.
      if (const auto first = named_.find(key); first != named_.end()) {
        return Error(v_[name_at].line, t + " " + name + " is declared twice (first on line " +
                                           std::to_string(first->second.line) +
                                           "); give each target its own name");
      }
      Named n;
      n.line = v_[name_at].line;
      if (array) {
        n.runtime = "an array element";
      } else if (!init) {
        n.runtime = "declared without a value";
      } else {
        int record = -1;
        if (Status st = t == "robtarget" ? Robtarget(va, ve, name, &record)
                                         : Jointtarget(va, ve, name, &record);
            !st.ok()) {
          return st;
        }
        if (record < 0) {
          n.runtime = "its value is computed at run time: " + v_.Excerpt(va, ve);
        }
        n.record = record;
      }
      n.joint = t == "jointtarget";
      (void)is_var;
      named_[key] = n;
      return Status::Ok();
    }
    if (t == "tooldata" || t == "wobjdata") {
      Frame f;
      if (array || !init || !(v_.Is(va, "[") && v_[va].match == ve - 1)) {
        f.runtime = array ? "an array element" : "its value is not a literal";
      } else {
        const auto items = v_.Items(va);
        const std::string what = t + " " + name;
        // robhold: a literal TRUE or FALSE (a bool variable is a run-time value).
        const bool robhold_literal =
            !items.empty() && items[0].second == items[0].first + 1 &&
            (v_.IsNoCase(items[0].first, "TRUE") || v_.IsNoCase(items[0].first, "FALSE"));
        const bool robhold = robhold_literal && v_.IsNoCase(items[0].first, "TRUE");
        if (t == "tooldata") {
          if (items.size() != 3) {
            return Error(v_[va].line, what +
                                          ": expected [robhold, [[x, y, z], [q1, q2, q3, q4]], "
                                          "load]");
          }
          bool literal;
          if (Status st = PoseLiteral(items[1].first, items[1].second, what, &f.pose, &literal);
              !st.ok()) {
            return st;
          }
          if (!literal) f.runtime = "its tframe is not a literal";
          // tooldata robhold TRUE: the robot holds the tool (tframe on the flange); FALSE: a
          // stationary tool (tframe in the world frame, used with a work object the robot holds).
          f.stationary = !robhold;
          if (!robhold_literal) f.runtime = "its robhold is not TRUE or FALSE";
        } else {
          if (items.size() != 5) {
            return Error(v_[va].line, what +
                                          ": expected [robhold, ufprog, ufmec, uframe, "
                                          "oframe]");
          }
          SE3d user, object;
          bool l1, l2;
          if (Status st = PoseLiteral(items[3].first, items[3].second, what, &user, &l1);
              !st.ok()) {
            return st;
          }
          if (Status st = PoseLiteral(items[4].first, items[4].second, what, &object, &l2);
              !st.ok()) {
            return st;
          }
          f.pose = user * object;
          if (!l1 || !l2) f.runtime = "its frames are not literals";
          if (v_.IsNoCase(items[1].first, "FALSE")) {
            f.runtime = "a moving user frame (ufprog FALSE, coordinated motion) is not supported";
          }
          // wobjdata robhold TRUE: the robot holds the work object (uframe on the flange), for
          // a stationary tool; FALSE: the work object is fixed (uframe in the world frame).
          f.stationary = robhold;
          if (!robhold_literal) f.runtime = "its robhold is not TRUE or FALSE";
        }
      }
      (t == "tooldata" ? tools_ : wobjs_)[key] = f;
    }
    return Status::Ok();
  }

  // Positional arguments of the motion at `s` (statement end e): the part of each comma-separated
  // argument before its optional arguments (\Name...).
  std::vector<std::pair<int, int>> Arguments(int s, int e) const {
    std::vector<std::pair<int, int>> out;
    int a = s + 1;
    while (a < e) {
      const int end = v_.ExpressionEnd(a, e);
      int main_end = a;
      while (main_end < end && !v_.Is(main_end, "\\")) {
        main_end = v_[main_end].match > main_end ? v_[main_end].match + 1 : main_end + 1;
      }
      if (main_end > a) out.emplace_back(a, main_end);
      if (end >= e || !v_.Is(end, ",")) break;
      a = end + 1;
    }
    return out;
  }

  Status MotionStatement(int a, int e) {
    bool declaration, assignment;
    const int s = Start(a, e, &declaration, &assignment);
    if (s < 0 || declaration || assignment) return Status::Ok();
    Motion m;
    const std::string instruction(v_.Text(s));
    if (!FindMotion(Lower(instruction), &m)) return Status::Ok();
    const int line = v_[s].line;
    const auto args = Arguments(s, e);
    const int tool_index = m.tool >= 0 ? m.tool : static_cast<int>(args.size()) - 1;
    const int needed = std::max(tool_index, m.targets.back()) + 1;
    if (static_cast<int>(args.size()) < needed || tool_index < 0) {
      return Error(line, instruction + " needs at least " + std::to_string(needed) +
                             " arguments (targets, speed, zone, tool)");
    }
    Use use;
    use.line = line;
    use.order = ++order_;
    std::string context_runtime;
    // Tool.
    const auto& ta = args[tool_index];
    if (ta.second == ta.first + 1 && v_.IsIdent(ta.first)) {
      const std::string tool = Lower(v_.Text(ta.first));
      const auto it = tools_.find(tool);
      if (it == tools_.end()) {
        return Error(line, "unknown tool '" + std::string(v_.Text(ta.first)) +
                               "' (no tooldata declaration of that name in the program)");
      }
      use.tcp = it->second.pose;
      use.tcp_name = std::string(v_.Text(ta.first));
      const std::string label = "tool " + use.tcp_name + ": ";
      if (!it->second.runtime.empty()) context_runtime = label + it->second.runtime;
      if (assigned_.count(tool)) context_runtime = label + assigned_[tool];
    } else {
      context_runtime =
          "its tool is computed at run time: " + v_.Excerpt(ta.first, ta.second);
    }
    const auto tool_it = tools_.find(use.tcp_name.empty() ? std::string() : Lower(use.tcp_name));
    const bool stationary_tool = tool_it != tools_.end() && tool_it->second.stationary;
    bool held_wobj = false;
    // Work object: \WObj:=name anywhere in the statement.
    use.frame_name = "wobj0";
    for (int i = s; i + 4 < e; ++i) {
      if (v_.Is(i, "\\") && v_.IsNoCase(i + 1, "WObj") && v_.Is(i + 2, ":") && v_.Is(i + 3, "=")) {
        if (!v_.IsIdent(i + 4) || v_.Is(i + 5, "{")) {
          context_runtime = "its work object is computed at run time";
          break;
        }
        const std::string w = Lower(v_.Text(i + 4));
        const auto it = wobjs_.find(w);
        if (it == wobjs_.end()) {
          return Error(line, "unknown work object '" + std::string(v_.Text(i + 4)) +
                                 "' (no wobjdata declaration of that name in the program)");
        }
        use.frame = it->second.pose;
        use.frame_name = std::string(v_.Text(i + 4));
        held_wobj = it->second.stationary;
        const std::string label = "work object " + use.frame_name + ": ";
        if (!it->second.runtime.empty()) context_runtime = label + it->second.runtime;
        if (assigned_.count(w)) context_runtime = label + assigned_[w];
      }
    }
    // A stationary tool is used with a work object the robot holds, and only then (RAPID's
    // definition of robhold in tooldata and wobjdata).
    use.stationary = stationary_tool && held_wobj;
    if (context_runtime.empty() && stationary_tool != held_wobj) {
      context_runtime =
          stationary_tool
              ? "tool " + use.tcp_name + " is a stationary tool (robhold FALSE) but work object " +
                    use.frame_name +
                    " is not held by the robot (robhold FALSE): a stationary tool needs a work "
                    "object the robot holds"
              : "work object " + use.frame_name +
                    " is held by the robot (robhold TRUE, for a stationary tool) but tool " +
                    use.tcp_name + " is held by the robot too (robhold TRUE)";
    }
    for (size_t k = 0; k < m.targets.size(); ++k) {
      const auto& arg = args[m.targets[k]];
      std::string inline_name = instruction + ":" + std::to_string(line);
      if (m.targets.size() == 2) inline_name += k == 0 ? ":cir" : ":to";
      int record = -1;
      if (v_.Is(arg.first, "[")) {
        if (Status st = m.joint ? Jointtarget(arg.first, arg.second, inline_name, &record)
                                : Robtarget(arg.first, arg.second, inline_name, &record);
            !st.ok()) {
          return st;
        }
        if (record < 0) {
          Runtime(inline_name, line,
                  "computed at run time: " + v_.Excerpt(arg.first, arg.second));
          continue;
        }
      } else if (arg.second == arg.first + 1 && v_.IsIdent(arg.first)) {
        const std::string name(v_.Text(arg.first));
        const std::string key = Lower(name);
        const auto it = named_.find(key);
        if (it == named_.end()) {
          Runtime(name, line, "not declared in this module (a run-time or external value)");
          continue;
        }
        if (it->second.record < 0) {
          Runtime(name, line, it->second.runtime);
          continue;
        }
        if (it->second.joint != m.joint) {
          return Error(line, instruction + ": '" + name + "' is a " +
                                 (it->second.joint ? "jointtarget" : "robtarget"));
        }
        record = it->second.record;
      } else {
        Runtime(inline_name, line,
                "computed at run time: " + v_.Excerpt(arg.first, arg.second));
        continue;
      }
      ProgramTarget& r = program_->targets[record];
      const auto as = assigned_.find(Lower(r.name));
      if (r.compensable && as != assigned_.end() && r.name.find(':') == std::string::npos) {
        r.compensable = false;
        r.reason = as->second;
      }
      if (r.compensable && !context_runtime.empty() && r.kind == ProgramTargetKind::kCartesian) {
        r.compensable = false;
        r.reason = context_runtime;
      }
      uses_[record].push_back(use);
    }
    return Status::Ok();
  }

  void Runtime(const std::string& name, int line, const std::string& reason) {
    ProgramTarget t;
    t.name = name;
    t.line = line;
    t.compensable = false;
    t.reason = reason;
    Add(std::move(t));
  }

  Status Finish() {
    for (size_t k = 0; k < program_->targets.size(); ++k) {
      ProgramTarget& t = program_->targets[k];
      const std::vector<Use>& uses = uses_[k];
      if (uses.empty()) continue;
      // Another work object or tool matters for a Cartesian target only.
      program_internal::ApplyTargetUses(uses, {"tools", "work objects", false}, &t);
    }
    std::stable_sort(program_->targets.begin(), program_->targets.end(),
                     [](const ProgramTarget& x, const ProgramTarget& y) {
                       if (x.line != y.line) return x.line < y.line;
                       const size_t bx = x.numbers.empty() ? 0 : x.numbers[0].begin;
                       const size_t by = y.numbers.empty() ? 0 : y.numbers[0].begin;
                       return bx < by;
                     });
    return Status::Ok();
  }

  struct Named {
    int line = 0;  // of its declaration
    int record = -1;
    bool joint = false;
    std::string runtime;
  };

  TokenView v_;
  ParsedProgram* program_;
  std::map<std::string, Named> named_;
  std::map<std::string, Frame> tools_, wobjs_;
  std::map<std::string, std::string> assigned_;  // lower-case name -> why it is a run-time value
  std::vector<std::vector<Use>> uses_;
  int order_ = 0;
};

}  // namespace

Status ParseRapidProgram(std::string_view text, ParsedProgram* program) {
  std::vector<Token> tokens;
  program_internal::LexerOptions options;
  options.comment = '!';
  if (Status s = program_internal::Tokenize(text, options, &tokens); !s.ok()) return s;
  RapidParser parser(text, tokens, program);
  return parser.Run();
}

}  // namespace lpoe
