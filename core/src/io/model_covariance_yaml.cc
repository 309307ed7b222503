// The `covariance:` block of a calibrated model (lpoe/model/model_covariance.h, docs/file_formats.md).
#include "lpoe/model/model_covariance.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <functional>

#include <Eigen/Eigenvalues>

#include "io/file_util.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "io/parse_util.h"

namespace lpoe {
namespace {

constexpr size_t kMaxCovarianceFileBytes = size_t{64} << 20;

int LineOfNode(const YAML::Node& node, int fallback) {
  const YAML::Mark m = node.Mark();
  return m.is_null() ? fallback : m.line + 1;
}

void AppendMatrix(const Eigen::MatrixXd& M, std::string* out) {
  *out += "[";
  for (int i = 0; i < M.rows(); ++i) {
    for (int j = 0; j < M.cols(); ++j) {
      if (i > 0 || j > 0) *out += ", ";
      internal::AppendNumber(M(i, j), out);
    }
  }
  *out += "]";
}

}  // namespace

std::string ModelCovarianceYaml(const RobotModel& model, const ModelCovariance& c) {
  std::string out;
  out += "# covariance of the estimate (docs/file_formats.md): per frame of xi = log(T_ref^-1 T) =\n";
  out += "# (omega rad, v mm) in the frame's coordinates, 6x6 row-major; per joint-space term of its\n";
  out += "# values; models: how many calibrations it was estimated from.\n";
  out += "covariance:\n  models: " + std::to_string(c.models) + "\n";
  if (c.data_sigma > 0) {
    out += "  data_sigma: ";
    internal::AppendNumber(c.data_sigma, &out);
    out += "  # mm per axis\n";
  }
  out += "  frames:\n";
  const int n = model.num_joints();
  for (int f = 0; f < model.num_frames() && f < static_cast<int>(c.frames.size()); ++f) {
    if (c.frames[f].rows() != 6 || c.frames[f].cols() != 6) continue;
    const std::string& name = f < n ? model.joints[f].name : model.tools[f - n].name;
    out += "    - {name: " + internal::YamlDoubleQuoted(name) + ", matrix: ";
    AppendMatrix(c.frames[f], &out);
    out += "}\n";
  }
  if (!c.terms.empty()) {
    out += "  joint_errors:\n";
    for (size_t b = 0; b < c.terms.size(); ++b) {
      out += "    - {name: " + internal::YamlDoubleQuoted(c.term_names[b]) + ", matrix: ";
      AppendMatrix(c.terms[b], &out);
      out += "}\n";
    }
  }
  return out;
}

Status ReadModelCovariance(const std::string& path, const RobotModel& model, ModelCovariance* out) {
  std::string text;
  if (Status s = internal::ReadFileBounded(path, kMaxCovarianceFileBytes, &text); !s.ok()) return s;
  auto error = [&](int line, const std::string& what, const std::string& expected) {
    return internal::LineError(path, line, what, expected);
  };
  const std::string kExpected =
      "covariance: {models: N, data_sigma: mm, frames: [{name: <frame>, matrix: [36 numbers]}, ...], "
      "joint_errors: [{name: <term>, matrix: [P*P numbers]}]} (docs/file_formats.md)";
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsMap() || !root["covariance"]) {
      return error(1, "no covariance block (write it with lpoe_calibrate --output, or lpoe_prior)",
                   kExpected);
    }
    const YAML::Node block = root["covariance"];
    const int block_line = LineOfNode(block, 1);
    if (!block.IsMap()) return error(block_line, "'covariance' is not a mapping", kExpected);
    ModelCovariance c;
    c.frames.assign(model.num_frames(), Eigen::MatrixXd());
    for (YAML::const_iterator it = block.begin(); it != block.end(); ++it) {
      const std::string key = it->first.IsScalar() ? it->first.Scalar() : std::string();
      if (key != "models" && key != "data_sigma" && key != "frames" && key != "joint_errors") {
        return error(LineOfNode(it->first, block_line),
                     "unknown key " + internal::Quote(key) + " in 'covariance'", kExpected);
      }
    }
    if (block["models"]) {
      const YAML::Node m = block["models"];
      int models = 0;
      if (!m.IsScalar() || !YAML::convert<int>::decode(m, models) || models < 1) {
        return error(LineOfNode(m, block_line), "'models' is not a positive integer", kExpected);
      }
      c.models = models;
    }
    if (block["data_sigma"]) {
      const YAML::Node m = block["data_sigma"];
      double v = 0;
      if (!m.IsScalar() || !YAML::convert<double>::decode(m, v) || !std::isfinite(v) || v < 0) {
        return error(LineOfNode(m, block_line), "'data_sigma' is not a non-negative number (mm)",
                     kExpected);
      }
      c.data_sigma = v;
    }
    // One entry: name and a row-major matrix of size x size finite numbers, symmetric, PSD.
    auto entry = [&](const YAML::Node& item, int size_hint, std::string* name,
                     Eigen::MatrixXd* M, const std::function<int(const std::string&)>& size_of) {
      const int line = LineOfNode(item, block_line);
      if (!item.IsMap() || !item["name"] || !item["matrix"] || item.size() != 2) {
        return error(line, "an entry is not {name, matrix}", kExpected);
      }
      *name = item["name"].IsScalar() ? item["name"].Scalar() : std::string();
      const int size = size_of(*name);
      if (size <= 0) return error(line, "unknown name " + internal::Quote(*name), kExpected);
      const YAML::Node m = item["matrix"];
      if (!m.IsSequence() || static_cast<int>(m.size()) != size * size) {
        return error(LineOfNode(m, line),
                     "matrix of " + internal::Quote(*name) + " does not have " +
                         std::to_string(size * size) + " numbers",
                     kExpected);
      }
      M->resize(size, size);
      for (int k = 0; k < size * size; ++k) {
        double v = 0;
        if (!m[k].IsScalar() || !YAML::convert<double>::decode(m[k], v) || !std::isfinite(v)) {
          return error(LineOfNode(m[k], line),
                       "matrix entry " + std::to_string(k + 1) + " of " + internal::Quote(*name) +
                           " is not a finite number",
                       kExpected);
        }
        (*M)(k / size, k % size) = v;
      }
      const double scale = std::max(1e-300, M->cwiseAbs().maxCoeff());
      if ((*M - M->transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) {
        return error(LineOfNode(m, line), "matrix of " + internal::Quote(*name) + " is not symmetric",
                     kExpected);
      }
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(*M);
      if (eig.eigenvalues().minCoeff() < -1e-9 * scale) {
        return error(LineOfNode(m, line),
                     "matrix of " + internal::Quote(*name) + " is not positive semi-definite",
                     kExpected);
      }
      (void)size_hint;
      return Status::Ok();
    };
    if (block["frames"]) {
      const YAML::Node frames = block["frames"];
      if (!frames.IsSequence()) {
        return error(LineOfNode(frames, block_line), "'frames' is not a list", kExpected);
      }
      const int n = model.num_joints();
      for (const YAML::Node& item : frames) {
        std::string name;
        Eigen::MatrixXd M;
        int frame = -1;
        Status s = entry(item, 6, &name, &M, [&](const std::string& nm) {
          for (int f = 0; f < model.num_frames(); ++f) {
            if ((f < n ? model.joints[f].name : model.tools[f - n].name) == nm) frame = f;
          }
          return frame >= 0 ? 6 : 0;
        });
        if (!s.ok()) return s;
        if (c.frames[frame].size() > 0) {
          return error(LineOfNode(item, block_line), "frame " + internal::Quote(name) + " listed twice",
                       kExpected);
        }
        c.frames[frame] = M;
      }
    }
    if (block["joint_errors"]) {
      const YAML::Node terms = block["joint_errors"];
      if (!terms.IsSequence()) {
        return error(LineOfNode(terms, block_line), "'joint_errors' is not a list", kExpected);
      }
      for (const YAML::Node& item : terms) {
        std::string name;
        Eigen::MatrixXd M;
        Status s = entry(item, 0, &name, &M, [&](const std::string& nm) {
          return static_cast<int>(model.joint_errors.Values(nm).size());
        });
        if (!s.ok()) return s;
        c.term_names.push_back(name);
        c.terms.push_back(M);
      }
    }
    *out = std::move(c);
    return Status::Ok();
  } catch (const YAML::Exception& e) {
    return error(e.mark.is_null() ? 1 : e.mark.line + 1, "YAML syntax error: " + e.msg, kExpected);
  }
}

}  // namespace lpoe
