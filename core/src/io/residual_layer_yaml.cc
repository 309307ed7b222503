// The model-YAML block of the learned residual layer (docs/residual_layer.md, "Storage"):
//
//   residual_layer:
//     kernel: se_ard
//     frame: base
//     length_scales: [l1, ..., ln]        # rad (revolute) / mm (prismatic)
//     tool_correlation: rho               # [0, 1]
//     signal_std: s_f                     # mm
//     noise_std: s_n                      # mm
//     fitted_rows: N                      # information only
//     inducing_tools: [t1, ..., tm]       # 0-based tool indices
//     inducing:                           # m rows [q1, ..., qn]
//       - [...]
//     weights:                            # m rows [wx, wy, wz]
//       - [...]
//     variance:                           # W's lower triangle: row i has i + 1 numbers
//       - [...]
//
// Numbers are written as the shortest text that reads back exactly, so a written model predicts
// bit for bit what the model in memory did.
#include <cmath>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "io/joint_errors_yaml.h"
#include "terms/joint_term_kind.h"
#include "lpoe/model/model_limits.h"
#include "lpoe/model/residual_layer.h"
#include "io/parse_util.h"

namespace lpoe {
namespace internal {
namespace {

const std::vector<std::string> kLayerKeys = {
    "kernel",      "frame",       "length_scales", "tool_correlation", "signal_std", "noise_std",
    "fitted_rows", "inducing_tools", "inducing",   "weights",          "variance"};

// The reading of one residual_layer block: its keys, the line of the block, the model's sizes.
class LayerYamlReader {
 public:
  using R = JointErrorsYamlReader;
  LayerYamlReader(const JointErrorsYamlReader& reader, const YAML::Node& node, int line)
      : reader_(reader), node_(node), line_(line), at_(R::LineOf(node, line)) {}

  // The keys (every one but fitted_rows required), the kernel and the frame.
  Status Keys() {
    if (Status s = reader_.Map(node_, line_, "'residual_layer'", kLayerKeys, &keys_); !s.ok()) {
      return s;
    }
    for (const std::string& k : kLayerKeys) {
      if (k == "fitted_rows") continue;
      if (R::Find(keys_, k.c_str()) == nullptr) {
        return reader_.Error(node_, at_, "'residual_layer' has no '" + k + "'",
                             "the keys " + std::string("kernel, frame, length_scales, "
                                                       "tool_correlation, signal_std, noise_std, "
                                                       "inducing_tools, inducing, weights, "
                                                       "variance (docs/residual_layer.md)"));
      }
    }
    if (Status s = ScalarIs("kernel", ResidualLayer::kKernel); !s.ok()) return s;
    return ScalarIs("frame", ResidualLayer::kFrame);
  }

  // length_scales, tool_correlation, signal_std, noise_std and fitted_rows, each in its range.
  Status Hyperparameters(int n, ResidualLayer* layer) const {
    layer->length_scales.resize(n);
    const YAML::Node& scales = *R::Find(keys_, "length_scales");
    if (Status s = reader_.Numbers(scales, at_, "'length_scales'", n,
                                   "one positive length scale per joint",
                                   layer->length_scales.data());
        !s.ok()) {
      return s;
    }
    for (int j = 0; j < n; ++j) {
      if (!(layer->length_scales(j) >= kMinLayerLengthScale &&
            layer->length_scales(j) <= kMaxLayerLengthScale)) {
        return reader_.Error(scales, at_,
                             "'length_scales' entry " + std::to_string(j + 1) + " (" +
                                 ShortNumber(layer->length_scales(j)) + ") is out of range",
                             "length scales in [" + ShortNumber(kMinLayerLengthScale) + ", " +
                                 ShortNumber(kMaxLayerLengthScale) + "] (rad or mm)");
      }
    }
    struct Ranged {
      const char* key;
      double* value;
      double min, max;
      const char* unit;
    } scalars[] = {{"tool_correlation", &layer->tool_correlation, 0.0, 1.0, ""},
                   {"signal_std", &layer->signal_std, kMinLayerStd, kMaxLayerStd, " mm"},
                   {"noise_std", &layer->noise_std, kMinLayerStd, kMaxLayerStd, " mm"}};
    for (const Ranged& p : scalars) {
      const YAML::Node& v = *R::Find(keys_, p.key);
      if (Status s = reader_.Number(v, at_, std::string("'") + p.key + "'", p.value); !s.ok()) {
        return s;
      }
      if (!(*p.value >= p.min && *p.value <= p.max)) {
        return reader_.Error(v, at_,
                             std::string("'") + p.key + "' (" + ShortNumber(*p.value) +
                                 ") is out of range",
                             "a number in [" + ShortNumber(p.min) + ", " + ShortNumber(p.max) +
                                 "]" + p.unit);
      }
    }
    if (const YAML::Node* rows = R::Find(keys_, "fitted_rows"); rows != nullptr) {
      double v = 0;
      if (Status s = reader_.Number(*rows, at_, "'fitted_rows'", &v); !s.ok()) return s;
      if (!(v >= 0 && v <= 2e9 && v == std::floor(v))) {
        return reader_.Error(*rows, at_, "'fitted_rows' is not a count", "a whole number >= 0");
      }
      layer->fitted_rows = static_cast<int>(v);
    }
    return Status::Ok();
  }

  // inducing_tools: one tool index of the model per inducing input (at most kMaxLayerInducing).
  Status InducingTools(int num_tools, ResidualLayer* layer) const {
    const YAML::Node& tools = *R::Find(keys_, "inducing_tools");
    if (!tools.IsSequence() || tools.size() == 0) {
      return reader_.Error(tools, at_, "'inducing_tools' is not a non-empty list",
                           "one tool index per inducing input");
    }
    // The count first: the variance matrix is m^2 numbers, allocated below.
    if (tools.size() > static_cast<size_t>(kMaxLayerInducing)) {
      return reader_.Error(tools, at_,
                           "'inducing_tools' has " + std::to_string(tools.size()) + " entries",
                           "at most " + std::to_string(kMaxLayerInducing) + " inducing inputs");
    }
    const int m = static_cast<int>(tools.size());
    layer->inducing_tool.resize(m);
    for (int i = 0; i < m; ++i) {
      double v = 0;
      const std::string what = "'inducing_tools' entry " + std::to_string(i + 1);
      if (Status s = reader_.Number(tools[i], at_, what, &v); !s.ok()) return s;
      if (!(v >= 0 && v < num_tools && v == std::floor(v))) {
        return reader_.Error(tools[i], R::LineOf(tools, at_),
                             what + " is not a tool index of the model",
                             "a 0-based tool index below " + std::to_string(num_tools));
      }
      layer->inducing_tool[i] = static_cast<int>(v);
    }
    return Status::Ok();
  }

  // inducing, weights and variance: m rows each, their numbers within the ranges that keep a
  // prediction finite (the first such refusal after the rows' own).
  Status Rows(int n, ResidualLayer* layer) const {
    const int m = static_cast<int>(layer->inducing_tool.size());
    layer->inducing_q.resize(m, n);
    layer->weights.resize(m, 3);
    layer->variance.resize(m, m);
    Status range = Status::Ok();
    Status s = ReadRows(
        "inducing", m, "one joint value per joint", [&](int) { return n; },
        [&](int i, const std::vector<double>& r) {
          if (range.ok()) {
            range = Within("inducing", i, r, kMaxLayerJointValue,
                           "joint values within +-" + ShortNumber(kMaxLayerJointValue));
          }
          for (int j = 0; j < n; ++j) layer->inducing_q(i, j) = r[j];
        });
    // A weight moves the prediction by up to |w| s_f^2 (mm), a variance entry it by |W| s_f^4.
    const double sf2 = layer->signal_std * layer->signal_std;
    const double max_weight = kMaxLayerWeightMm / sf2;
    const double max_variance = kMaxLayerVarianceMm2 / (sf2 * sf2);
    if (s.ok()) {
      s = ReadRows(
          "weights", m, "[wx, wy, wz]", [](int) { return 3; },
          [&](int i, const std::vector<double>& r) {
            if (range.ok()) {
              range = Within("weights", i, r, max_weight,
                             "weights w with |w| signal_std^2 within " +
                                 ShortNumber(kMaxLayerWeightMm) + " mm");
            }
            for (int c = 0; c < 3; ++c) layer->weights(i, c) = r[c];
          });
    }
    if (s.ok()) {
      s = ReadRows(
          "variance", m, "row i of the lower triangle: i numbers", [](int i) { return i + 1; },
          [&](int i, const std::vector<double>& r) {
            if (range.ok()) {
              range = Within("variance", i, r, max_variance,
                             "entries W with |W| signal_std^4 within " +
                                 ShortNumber(kMaxLayerVarianceMm2) + " mm^2");
            }
            for (int j = 0; j <= i; ++j) layer->variance(i, j) = layer->variance(j, i) = r[j];
          });
    }
    if (!s.ok()) return s;
    return range;
  }

  Status Error(const std::string& what, const std::string& expected) const {
    return reader_.Error(node_, at_, what, expected);
  }

 private:
  Status ScalarIs(const char* key, const char* value) const {
    const YAML::Node& v = *R::Find(keys_, key);
    if (!v.IsScalar() || v.Scalar() != value) {
      return reader_.Error(v, at_, std::string("'residual_layer' ") + key + " is not " + value,
                           std::string(key) + ": " + value);
    }
    return Status::Ok();
  }

  // A list of m rows; row i has count(i) numbers, handed to store(i, row).
  template <typename Count, typename Store>
  Status ReadRows(const char* key, int m, const std::string& expected, Count count,
                  Store store) const {
    const YAML::Node& v = *R::Find(keys_, key);
    if (!v.IsSequence() || static_cast<int>(v.size()) != m) {
      return reader_.Error(v, at_,
                           std::string("'") + key + "' is " +
                               (v.IsSequence() ? "a list of " + std::to_string(v.size())
                                               : std::string("not a list")),
                           "a list of " + std::to_string(m) + " rows (one per inducing input)");
    }
    std::vector<double> row;
    for (int i = 0; i < m; ++i) {
      row.assign(count(i), 0.0);
      const YAML::Node item = v[i];
      if (Status s = reader_.Numbers(item, R::LineOf(item, R::LineOf(v, at_)),
                                     std::string("'") + key + "' row " + std::to_string(i + 1),
                                     count(i), expected, row.data());
          !s.ok()) {
        return s;
      }
      store(i, row);
    }
    return Status::Ok();
  }

  // Every number of a row within +-limit, else the row's line.
  Status Within(const char* key, int i, const std::vector<double>& r, double limit,
                const std::string& expected) const {
    for (size_t c = 0; c < r.size(); ++c) {
      if (!(std::abs(r[c]) <= limit)) {
        const YAML::Node& v = *R::Find(keys_, key);
        return reader_.Error(v[i], R::LineOf(v, at_),
                             std::string("'") + key + "' row " + std::to_string(i + 1) +
                                 " entry " + std::to_string(c + 1) + " (" + ShortNumber(r[c]) +
                                 ") is out of range",
                             expected);
      }
    }
    return Status::Ok();
  }

  const JointErrorsYamlReader& reader_;
  const YAML::Node& node_;
  const int line_, at_;
  std::vector<std::pair<std::string, YAML::Node>> keys_;
};

}  // namespace

Status ReadResidualLayerYaml(const JointErrorsYamlReader& reader, const YAML::Node& node,
                             int line, std::shared_ptr<const ResidualLayer>* out) {
  LayerYamlReader block(reader, node, line);
  if (Status s = block.Keys(); !s.ok()) return s;
  const RobotModel& model = reader.model();
  const int n = model.num_joints();
  auto layer = std::make_shared<ResidualLayer>();
  layer->num_joints = n;
  layer->num_tools = model.num_tools();
  if (Status s = block.Hyperparameters(n, layer.get()); !s.ok()) return s;
  if (Status s = block.InducingTools(model.num_tools(), layer.get()); !s.ok()) return s;
  if (Status s = block.Rows(n, layer.get()); !s.ok()) return s;
  if (Status v = layer->Validate(n, model.num_tools()); !v.ok()) {
    return block.Error(v.message(), "a residual layer as lpoe_calibrate writes it");
  }
  *out = std::move(layer);
  return Status::Ok();
}

std::string ResidualLayerToYaml(const RobotModel& model) {
  if (!model.residual_layer) return std::string();
  const ResidualLayer& l = *model.residual_layer;
  std::string out;
  out += "# The learned residual layer (docs/residual_layer.md): a sparse Gaussian process that adds a\n"
         "# correction (mm, this model's base frame) to every predicted tool position.\n";
  out += "residual_layer:\n";
  out += std::string("  kernel: ") + ResidualLayer::kKernel + "\n";
  out += std::string("  frame: ") + ResidualLayer::kFrame + "\n";
  out += "  length_scales: ";
  AppendYamlList(l.length_scales.data(), l.num_joints, &out);
  out += "  # rad (revolute) / mm (prismatic)\n  tool_correlation: ";
  AppendNumber(l.tool_correlation, &out);
  out += "\n  signal_std: ";
  AppendNumber(l.signal_std, &out);
  out += "  # mm\n  noise_std: ";
  AppendNumber(l.noise_std, &out);
  out += "  # mm\n  fitted_rows: " + std::to_string(l.fitted_rows) + "\n";
  out += "  inducing_tools: [";
  for (int i = 0; i < l.num_inducing(); ++i) {
    out += (i > 0 ? ", " : "") + std::to_string(l.inducing_tool[i]);
  }
  out += "]\n  inducing:  # joint values of the inducing inputs\n";
  std::vector<double> row;
  for (int i = 0; i < l.num_inducing(); ++i) {
    row.assign(l.num_joints, 0.0);
    for (int j = 0; j < l.num_joints; ++j) row[j] = l.inducing_q(i, j);
    out += "    - ";
    AppendYamlList(row.data(), l.num_joints, &out);
    out += '\n';
  }
  out += "  weights:\n";
  for (int i = 0; i < l.num_inducing(); ++i) {
    const double w[3] = {l.weights(i, 0), l.weights(i, 1), l.weights(i, 2)};
    out += "    - ";
    AppendYamlList(w, 3, &out);
    out += '\n';
  }
  out += "  variance:  # lower triangle, row i has i numbers\n";
  for (int i = 0; i < l.num_inducing(); ++i) {
    row.assign(i + 1, 0.0);
    for (int j = 0; j <= i; ++j) row[j] = l.variance(i, j);
    out += "    - ";
    AppendYamlList(row.data(), i + 1, &out);
    out += '\n';
  }
  return out;
}

}  // namespace internal
}  // namespace lpoe
