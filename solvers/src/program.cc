// Robot programs: the language-neutral parts (tokens, compensation, rewriting, report). The
// parsers are program_urscript.cc and program_rapid.cc; see lpoe/program.h.
#include "lpoe/program.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <regex>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/kinematics.h"
#include "program_lexer.h"

namespace lpoe {
namespace program_internal {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string LineError(int line, const std::string& what) {
  return "line " + std::to_string(line) + ": " + what;
}

// Length of the valid UTF-8 sequence at s[i], 0 when invalid.
int Utf8Length(std::string_view s, size_t i) {
  const unsigned char c = static_cast<unsigned char>(s[i]);
  if (c < 0x80) return 1;
  int n;
  unsigned int cp;
  if ((c & 0xE0) == 0xC0) { n = 2; cp = c & 0x1F; }
  else if ((c & 0xF0) == 0xE0) { n = 3; cp = c & 0x0F; }
  else if ((c & 0xF8) == 0xF0) { n = 4; cp = c & 0x07; }
  else return 0;
  if (i + n > s.size()) return 0;
  for (int k = 1; k < n; ++k) {
    const unsigned char d = static_cast<unsigned char>(s[i + k]);
    if ((d & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (d & 0x3F);
  }
  if ((n == 2 && cp < 0x80) || (n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000) ||
      cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) {
    return 0;
  }
  return n;
}

bool IdentStart(unsigned char c) { return std::isalpha(c) || c == '_' || c >= 0x80; }
bool IdentChar(unsigned char c) { return std::isalnum(c) || c == '_' || c >= 0x80; }

}  // namespace

std::string Lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

Status Tokenize(std::string_view text, const LexerOptions& options, std::vector<Token>* tokens) {
  tokens->clear();
  int line = 1;
  if (text.size() > kMaxProgramBytes) {
    size_t i = 0;
    for (; i < kMaxProgramBytes; ++i) line += text[i] == '\n';
    return Status::Error(LineError(line, "the program is larger than " +
                                             std::to_string(kMaxProgramBytes >> 20) +
                                             " MB (its size here exceeds the limit)"));
  }
  std::vector<int> open;  // token indices of open brackets
  size_t i = 0;
  const size_t n = text.size();
  if (n >= 3 && text.compare(0, 3, "\xEF\xBB\xBF") == 0) i = 3;  // UTF-8 byte order mark
  auto push = [&](Token::Kind kind, size_t b, size_t e) {
    Token t;
    t.kind = kind;
    t.begin = b;
    t.end = e;
    t.line = line;
    tokens->push_back(t);
  };
  while (i < n) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\n') {
      ++line;
      ++i;
      continue;
    }
    if (c >= 0x80) {
      if (Utf8Length(text, i) == 0) {
        return Status::Error(LineError(line, "the text is not valid UTF-8 (byte " +
                                                 std::to_string(i) + ")"));
      }
    } else if (c < 0x20 && c != '\t' && c != '\r' && c != '\f' && c != '\v') {
      return Status::Error(LineError(line, "control character " + std::to_string(c) +
                                               " in the program text"));
    }
    if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
      ++i;
      continue;
    }
    if (c == static_cast<unsigned char>(options.comment)) {
      while (i < n && text[i] != '\n') {
        const int len = Utf8Length(text, i);
        if (len == 0) {
          return Status::Error(LineError(line, "the text is not valid UTF-8 (byte " +
                                                   std::to_string(i) + ")"));
        }
        i += len;
      }
      continue;
    }
    if (c == '"' || (options.single_quotes && c == '\'')) {
      const size_t b = i++;
      bool closed = false;
      while (i < n && text[i] != '\n') {
        if (text[i] == '\\' && i + 1 < n && text[i + 1] != '\n') {
          i += 2;
          continue;
        }
        if (text[i] == static_cast<char>(c)) {
          if (i + 1 < n && text[i + 1] == static_cast<char>(c)) {  // "" inside a string
            i += 2;
            continue;
          }
          closed = true;
          ++i;
          break;
        }
        const int len = Utf8Length(text, i);
        if (len == 0) {
          return Status::Error(LineError(line, "the text is not valid UTF-8 (byte " +
                                                   std::to_string(i) + ")"));
        }
        i += len;
      }
      if (!closed) return Status::Error(LineError(line, "unterminated string"));
      push(Token::kString, b, i);
      continue;
    }
    if (std::isdigit(c) || (c == '.' && i + 1 < n && std::isdigit(static_cast<unsigned char>(text[i + 1])))) {
      const size_t b = i;
      while (i < n && std::isdigit(static_cast<unsigned char>(text[i]))) ++i;
      if (i < n && text[i] == '.') {
        ++i;
        while (i < n && std::isdigit(static_cast<unsigned char>(text[i]))) ++i;
      }
      if (i < n && (text[i] == 'e' || text[i] == 'E')) {
        size_t k = i + 1;
        if (k < n && (text[k] == '+' || text[k] == '-')) ++k;
        if (k < n && std::isdigit(static_cast<unsigned char>(text[k]))) {
          i = k;
          while (i < n && std::isdigit(static_cast<unsigned char>(text[i]))) ++i;
        }
      }
      if (i < n && IdentChar(static_cast<unsigned char>(text[i]))) {
        return Status::Error(LineError(line, "malformed number '" +
                                                 std::string(text.substr(b, i + 1 - b)) + "'"));
      }
      push(Token::kNumber, b, i);
      double v = 0;
      const auto r = std::from_chars(text.data() + b, text.data() + i, v);
      if (r.ec != std::errc() || !std::isfinite(v)) {
        return Status::Error(LineError(line, "number out of range '" +
                                                 std::string(text.substr(b, i - b)) + "'"));
      }
      tokens->back().value = v;
      continue;
    }
    if (IdentStart(c)) {
      const size_t b = i;
      while (i < n && IdentChar(static_cast<unsigned char>(text[i]))) {
        const int len = Utf8Length(text, i);
        if (len == 0) {
          return Status::Error(LineError(line, "the text is not valid UTF-8 (byte " +
                                                   std::to_string(i) + ")"));
        }
        i += len;
      }
      push(Token::kIdent, b, i);
      continue;
    }
    push(Token::kPunct, i, i + 1);
    ++i;
    if (c == '(' || c == '[' || c == '{') {
      open.push_back(static_cast<int>(tokens->size()) - 1);
    } else if (c == ')' || c == ']' || c == '}') {
      if (open.empty()) {
        return Status::Error(LineError(line, std::string("'") + static_cast<char>(c) +
                                                 "' without an opening bracket"));
      }
      Token& o = (*tokens)[open.back()];
      const char oc = text[o.begin];
      const char want = oc == '(' ? ')' : oc == '[' ? ']' : '}';
      if (want != static_cast<char>(c)) {
        return Status::Error(LineError(
            line, std::string("'") + static_cast<char>(c) + "' does not close '" + oc +
                      "' opened on line " + std::to_string(o.line)));
      }
      o.match = static_cast<int>(tokens->size()) - 1;
      tokens->back().match = open.back();
      open.pop_back();
    }
  }
  if (!open.empty()) {
    const Token& o = (*tokens)[open.back()];
    return Status::Error(LineError(o.line, std::string("'") + text[o.begin] + "' is never closed"));
  }
  return Status::Ok();
}

bool TokenView::IsNoCase(int i, std::string_view s) const {
  if (i >= size()) return false;
  const std::string_view t = Text(i);
  if (t.size() != s.size()) return false;
  for (size_t k = 0; k < t.size(); ++k) {
    if (std::tolower(static_cast<unsigned char>(t[k])) !=
        std::tolower(static_cast<unsigned char>(s[k]))) {
      return false;
    }
  }
  return true;
}

int TokenView::Number(int i, ProgramNumber* n, int decimals) const {
  if (i >= size()) return -1;
  double sign = 1;
  const int first = i;
  if (Is(i, "-") || Is(i, "+")) {
    sign = Is(i, "-") ? -1 : 1;
    ++i;
  }
  if (i >= size() || t_[i].kind != Token::kNumber) return -1;
  n->begin = t_[first].begin;
  n->end = t_[i].end;
  n->value = sign * t_[i].value;
  n->decimals = decimals;
  return i + 1;
}

int TokenView::ExpressionEnd(int i, int limit) const {
  while (i < limit) {
    const Token& t = t_[i];
    if (t.kind == Token::kPunct) {
      const char c = text_[t.begin];
      if (c == ',' || c == ';' || c == ')' || c == ']' || c == '}') return i;
      if (t.match > i) {
        i = t.match + 1;
        continue;
      }
    }
    ++i;
  }
  return limit;
}

std::vector<std::pair<int, int>> TokenView::Items(int open) const {
  std::vector<std::pair<int, int>> items;
  const int close = t_[open].match;
  if (close == open + 1) return items;
  int a = open + 1;
  while (a <= close) {
    const int e = ExpressionEnd(a, close);
    items.emplace_back(a, e);
    if (e >= close) break;
    a = e + 1;
  }
  return items;
}

}  // namespace program_internal

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = 180.0 / kPi;

std::string FormatNumber(double x, int decimals) {
  if (std::abs(x) < 0.5 * std::pow(10.0, -decimals)) x = 0;
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", decimals, x);
  std::string s(buf);
  if (s.find('.') != std::string::npos) {
    while (s.back() == '0') s.pop_back();
    if (s.back() == '.') s.push_back('0');
  }
  if (s == "-0.0") s = "0.0";
  return s;
}

int Quadrant(double q) { return static_cast<int>(std::floor(q / (kPi / 2))); }

double Angle(const Eigen::Matrix3d& R) {
  return std::acos(std::clamp((R.trace() - 1) / 2, -1.0, 1.0));
}

// The pose (mm) of a Cartesian record from its numbers; false when they do not make one.
bool DecodePose(const ProgramTarget& t, SE3d* pose, std::string* why) {
  const auto& v = t.numbers;
  if (t.pose_encoding == PoseEncoding::kMetresRotationVector) {
    if (v.size() != 6) {
      *why = "a pose needs 6 numbers";
      return false;
    }
    pose->t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value) * 1000.0;
    pose->R = ExpSO3(Eigen::Vector3d(v[3].value, v[4].value, v[5].value));
    return true;
  }
  if (v.size() != 7) {
    *why = "a pose needs 7 numbers";
    return false;
  }
  pose->t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value);
  Eigen::Vector4d q(v[4].value, v[5].value, v[6].value, v[3].value);  // x y z w
  if (std::abs(q.norm() - 1) > 1e-3) {
    *why = "the orientation quaternion is not normalized (norm " + std::to_string(q.norm()) + ")";
    return false;
  }
  pose->R = QuaternionToRotation<double>(q / q.norm());
  return true;
}

// New numbers for `pose`, the representation nearest the original's (rotation vector branch,
// quaternion sign).
std::vector<double> EncodePose(const ProgramTarget& t, const SE3d& pose) {
  const auto& v = t.numbers;
  if (t.pose_encoding == PoseEncoding::kMetresRotationVector) {
    Eigen::Vector3d rv = LogSO3(pose.R);
    const Eigen::Vector3d old(v[3].value, v[4].value, v[5].value);
    const double a = rv.norm();
    if (a > 1e-9) {
      const Eigen::Vector3d alt = rv * (1 - 2 * kPi / a);
      if ((alt - old).norm() < (rv - old).norm()) rv = alt;
    }
    return {pose.t.x() / 1000, pose.t.y() / 1000, pose.t.z() / 1000, rv.x(), rv.y(), rv.z()};
  }
  Eigen::Vector4d q = RotationToQuaternion<double>(pose.R);  // x y z w
  const Eigen::Vector4d old(v[4].value, v[5].value, v[6].value, v[3].value);
  if (q.dot(old) < 0) q = -q;
  return {pose.t.x(), pose.t.y(), pose.t.z(), q(3), q(0), q(1), q(2)};
}

const char* IkReason(IkStatus s) {
  switch (s) {
    case IkStatus::kOk: return "reached";
    case IkStatus::kUnreachable: return "out of reach";
    case IkStatus::kLimit: return "outside the joint limits";
    case IkStatus::kSingular: return "at a singularity";
    case IkStatus::kBranch: return "only on another configuration branch (across a singular surface)";
  }
  return "?";
}

void JsonString(std::string_view s, std::string* out) {
  out->push_back('"');
  for (const char c : s) {
    switch (c) {
      case '"': *out += "\\\""; break;
      case '\\': *out += "\\\\"; break;
      case '\n': *out += "\\n"; break;
      case '\r': *out += "\\r"; break;
      case '\t': *out += "\\t"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char b[8];
          std::snprintf(b, sizeof(b), "\\u%04x", c);
          *out += b;
        } else {
          out->push_back(c);
        }
    }
  }
  out->push_back('"');
}

}  // namespace

const char* ProgramLanguageName(ProgramLanguage language) {
  return language == ProgramLanguage::kRapid ? "rapid" : "urscript";
}

bool ProgramLanguageFromName(std::string_view name, ProgramLanguage* language) {
  const std::string l = program_internal::Lower(name);
  if (l == "urscript") *language = ProgramLanguage::kUrScript;
  else if (l == "rapid") *language = ProgramLanguage::kRapid;
  else return false;
  return true;
}

bool ProgramLanguageFromPath(std::string_view path, ProgramLanguage* language) {
  const size_t dot = path.rfind('.');
  const size_t slash = path.find_last_of("/\\");
  if (dot == std::string_view::npos || (slash != std::string_view::npos && dot < slash)) {
    return false;
  }
  const std::string ext = program_internal::Lower(path.substr(dot + 1));
  if (ext == "script" || ext == "urscript") *language = ProgramLanguage::kUrScript;
  else if (ext == "mod" || ext == "modx" || ext == "prg") *language = ProgramLanguage::kRapid;
  else return false;
  return true;
}

const char* ProgramTargetStatusName(ProgramTargetStatus status) {
  switch (status) {
    case ProgramTargetStatus::kCompensated: return "compensated";
    case ProgramTargetStatus::kNotCompensated: return "not_compensated";
    case ProgramTargetStatus::kNotSelected: return "not_selected";
  }
  return "?";
}

Status ParseProgram(std::string_view text, ProgramLanguage language, ParsedProgram* program) {
  program->language = language;
  program->targets.clear();
  const Status s = language == ProgramLanguage::kRapid ? ParseRapidProgram(text, program)
                                                       : ParseUrScriptProgram(text, program);
  if (!s.ok()) program->targets.clear();
  return s;
}

int ResolveFlangeTool(const RobotModel& model, const std::string& flange, std::string* message) {
  if (!flange.empty()) {
    const int t = model.FindTool(flange);
    if (t < 0) *message = "the model " + model.name + " has no tool '" + flange + "'";
    return t;
  }
  const int t = model.FindTool("flange");
  if (t >= 0) return t;
  if (model.num_tools() == 1) return 0;
  *message = "the model " + model.name +
             " has no tool named 'flange' and several tools; say which one is the controller's "
             "flange (tool0) with --flange";
  return -1;
}

Status CompensateProgram(const RobotModel& calibrated, const RobotModel& nominal,
                         const ProgramOptions& options, ParsedProgram* program) {
  if (calibrated.num_joints() != nominal.num_joints()) {
    return Status::Error("the calibrated model has " + std::to_string(calibrated.num_joints()) +
                         " joints, the nominal " + std::to_string(nominal.num_joints()));
  }
  for (const RobotModel* m : {&calibrated, &nominal}) {
    if (Status s = InverseKinematics::CheckModel(*m); !s.ok()) return s;
  }
  std::string message;
  const int flange_cal = ResolveFlangeTool(calibrated, options.flange, &message);
  if (flange_cal < 0) return Status::Error(message);
  const int flange_nom = ResolveFlangeTool(nominal, calibrated.tools[flange_cal].name, &message);
  if (flange_nom < 0) return Status::Error(message);
  std::regex selected;
  if (!options.targets_only.empty()) {
    try {
      selected = std::regex(options.targets_only, std::regex::ECMAScript);
    } catch (const std::regex_error& e) {
      return Status::Error("targets_only '" + options.targets_only +
                           "' is not a regular expression: " + e.what());
    }
  }
  const int n = calibrated.num_joints();
  std::vector<double> prev(n, 0.0);
  if (!options.home.empty()) {
    if (static_cast<int>(options.home.size()) != n) {
      return Status::Error("home has " + std::to_string(options.home.size()) + " joints, the model " +
                           std::to_string(n));
    }
    prev = options.home;
  } else {
    for (int j = 0; j < n; ++j) {
      const Joint& J = nominal.joints[j];
      if (std::isfinite(J.lower) && std::isfinite(J.upper)) prev[j] = 0.5 * (J.lower + J.upper);
    }
  }
  IkOptions nominal_options = options.ik;
  nominal_options.check_branch = false;
  const InverseKinematics ik_cal(calibrated, options.ik);
  const InverseKinematics ik_nom(nominal, nominal_options);
  const KinematicChain nom_chain(nominal);

  std::vector<int> order;
  for (int k = 0; k < static_cast<int>(program->targets.size()); ++k) {
    ProgramTarget& t = program->targets[k];
    t.status = ProgramTargetStatus::kNotCompensated;
    t.new_values.clear();
    t.new_quadrants.clear();
    if (!t.compensable) continue;
    if (!t.used) {
      t.compensable = false;
      t.reason = "not used by a motion instruction (its tool and frame are unknown)";
      continue;
    }
    order.push_back(k);
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return program->targets[a].order < program->targets[b].order;
  });
  std::vector<double> seed(n), q_nom(n), q_cal(n);
  for (const int k : order) {
    ProgramTarget& t = program->targets[k];
    const bool wanted = options.targets_only.empty() || std::regex_match(t.name, selected);
    if (t.kind == ProgramTargetKind::kJoint) {
      if (static_cast<int>(t.numbers.size()) != n) {
        t.compensable = false;
        t.reason = std::to_string(t.numbers.size()) + " joint values for a robot with " +
                   std::to_string(n) + " joints";
        continue;
      }
      for (int j = 0; j < n; ++j) {
        const bool deg = t.joint_encoding == JointEncoding::kDegrees &&
                         nominal.joints[j].type == JointType::kRevolute;
        q_nom[j] = deg ? t.numbers[j].value / kDeg : t.numbers[j].value;
      }
      prev = q_nom;
      if (!wanted) {
        t.status = ProgramTargetStatus::kNotSelected;
        t.reason = "name does not match targets_only (taught point)";
        continue;
      }
      const SE3d X = calibrated.T_measurement_base * nom_chain.Pose(q_nom.data(), flange_nom);
      IkTarget target;
      target.tool = flange_cal;
      target.position = X.t;
      target.rotation = X.R;
      target.has_orientation = true;
      const IkResult r = ik_cal.Solve(target, q_nom.data(), q_cal.data());
      if (r.status != IkStatus::kOk) {
        t.reason = std::string("the calibrated robot reaches this pose ") + IkReason(r.status);
        continue;
      }
      double max_dq = 0;
      for (int j = 0; j < n; ++j) {
        const bool deg = t.joint_encoding == JointEncoding::kDegrees &&
                         nominal.joints[j].type == JointType::kRevolute;
        t.new_values.push_back(deg ? q_cal[j] * kDeg : q_cal[j]);
        if (nominal.joints[j].type == JointType::kRevolute) {
          max_dq = std::max(max_dq, std::abs(q_cal[j] - q_nom[j]) * kDeg);
        }
      }
      const SE3d a = nom_chain.Pose(q_nom.data(), flange_nom) * t.tcp;
      const SE3d b = nom_chain.Pose(q_cal.data(), flange_nom) * t.tcp;
      t.correction_mm = (b.t - a.t).norm();
      t.correction_deg = max_dq;
      t.status = ProgramTargetStatus::kCompensated;
      t.reason.clear();
      continue;
    }
    SE3d pose;
    std::string why;
    if (!DecodePose(t, &pose, &why)) {
      t.compensable = false;
      t.reason = why;
      continue;
    }
    // The controller's seed: qnear, else the previous target's joints moved into the quadrants.
    if (static_cast<int>(t.qnear.size()) == n) {
      seed = t.qnear;
    } else {
      seed = prev;
    }
    for (const ProgramTarget::Quadrant& qd : t.quadrants) {
      if (qd.joint < n && Quadrant(seed[qd.joint]) != static_cast<int>(qd.number.value)) {
        seed[qd.joint] = (qd.number.value + 0.5) * kPi / 2;
      }
    }
    const SE3d flange_base = t.frame * pose * t.tcp.Inverse();
    IkTarget target;
    target.tool = flange_nom;
    target.position = flange_base.t;
    target.rotation = flange_base.R;
    target.has_orientation = true;
    const IkResult rn = ik_nom.Solve(target, seed.data(), q_nom.data());
    if (rn.status != IkStatus::kOk && rn.status != IkStatus::kBranch) {
      t.reason = std::string("the nominal model reaches this target ") + IkReason(rn.status) +
                 " (the controller would not run it)";
      continue;
    }
    prev = q_nom;
    if (!wanted) {
      t.status = ProgramTargetStatus::kNotSelected;
      t.reason = "name does not match targets_only (taught point)";
      continue;
    }
    const SE3d measured = calibrated.T_measurement_base * flange_base;
    target.tool = flange_cal;
    target.position = measured.t;
    target.rotation = measured.R;
    const IkResult rc = ik_cal.Solve(target, q_nom.data(), q_cal.data());
    if (rc.status != IkStatus::kOk) {
      t.reason = std::string("the calibrated robot reaches this target ") + IkReason(rc.status);
      continue;
    }
    const SE3d corrected = t.frame.Inverse() * nom_chain.Pose(q_cal.data(), flange_nom) * t.tcp;
    t.new_values = EncodePose(t, corrected);
    for (const ProgramTarget::Quadrant& qd : t.quadrants) {
      t.new_quadrants.push_back(qd.joint < n ? Quadrant(q_cal[qd.joint]) : qd.number.value);
    }
    t.correction_mm = (corrected.t - pose.t).norm();
    t.correction_deg = Angle(pose.R.transpose() * corrected.R) * kDeg;
    t.status = ProgramTargetStatus::kCompensated;
    t.reason.clear();
  }
  return Status::Ok();
}

std::string RewriteProgram(std::string_view text, const ParsedProgram& program) {
  struct Edit {
    size_t begin, end;
    std::string text;
  };
  std::vector<Edit> edits;
  for (const ProgramTarget& t : program.targets) {
    if (t.status != ProgramTargetStatus::kCompensated) continue;
    for (size_t k = 0; k < t.numbers.size() && k < t.new_values.size(); ++k) {
      edits.push_back({t.numbers[k].begin, t.numbers[k].end,
                       FormatNumber(t.new_values[k], t.numbers[k].decimals)});
    }
    for (size_t k = 0; k < t.quadrants.size() && k < t.new_quadrants.size(); ++k) {
      if (t.new_quadrants[k] == t.quadrants[k].number.value) continue;  // unchanged: keep bytes
      edits.push_back({t.quadrants[k].number.begin, t.quadrants[k].number.end,
                       std::to_string(static_cast<long long>(t.new_quadrants[k]))});
    }
  }
  std::sort(edits.begin(), edits.end(),
            [](const Edit& a, const Edit& b) { return a.begin < b.begin; });
  std::string out;
  out.reserve(text.size() + 16 * edits.size());
  size_t at = 0;
  for (const Edit& e : edits) {
    if (e.begin < at) continue;  // overlapping (never made by the parsers)
    out.append(text.substr(at, e.begin - at));
    out += e.text;
    at = e.end;
  }
  out.append(text.substr(at));
  return out;
}

std::string ProgramReportJson(const ParsedProgram& program) {
  int counts[3] = {};
  for (const ProgramTarget& t : program.targets) ++counts[static_cast<int>(t.status)];
  std::string out = "{\n  \"language\": \"";
  out += ProgramLanguageName(program.language);
  out += "\",\n  \"targets\": " + std::to_string(program.targets.size()) + ",\n  \"status_counts\": {";
  for (int s = 0; s < 3; ++s) {
    out += s ? ", \"" : "\"";
    out += ProgramTargetStatusName(static_cast<ProgramTargetStatus>(s));
    out += "\": " + std::to_string(counts[s]);
  }
  out += "},\n  \"rows\": [";
  for (size_t k = 0; k < program.targets.size(); ++k) {
    const ProgramTarget& t = program.targets[k];
    out += k ? ",\n    {" : "\n    {";
    out += "\"name\": ";
    JsonString(t.name, &out);
    out += ", \"line\": " + std::to_string(t.line) + ", \"kind\": \"";
    out += t.kind == ProgramTargetKind::kJoint ? "joint" : "cartesian";
    out += "\", \"status\": \"";
    out += ProgramTargetStatusName(t.status);
    out += "\", \"frame\": ";
    JsonString(t.frame_name, &out);
    out += ", \"tcp\": ";
    JsonString(t.tcp_name, &out);
    out += ", \"reason\": ";
    JsonString(t.reason, &out);
    char buf[96];
    std::snprintf(buf, sizeof(buf), ", \"correction_mm\": %.6g, \"correction_deg\": %.6g}",
                  t.correction_mm, t.correction_deg);
    out += buf;
  }
  out += program.targets.empty() ? "]\n}\n" : "\n  ]\n}\n";
  return out;
}

Status CompensateProgramText(std::string_view text, ProgramLanguage language,
                             const RobotModel& calibrated, const RobotModel& nominal,
                             const ProgramOptions& options, std::string* output,
                             ParsedProgram* program) {
  if (Status s = ParseProgram(text, language, program); !s.ok()) return s;
  if (Status s = CompensateProgram(calibrated, nominal, options, program); !s.ok()) return s;
  *output = RewriteProgram(text, *program);
  return Status::Ok();
}

}  // namespace lpoe
