// The calibration run for ballbar distances and probe contacts (lpoe/contact_pipeline.h).
#include "lpoe/joint_error_list.h"
#include "lpoe/contact_pipeline.h"

#include "identifiability/cross_validation.h"

#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>

namespace lpoe {

ContactKindFigures ContactFigures(const ContactMeasurementSet& data,
                                  const std::vector<double>& errors, MeasurementKindId kind,
                                  int feature) {
  ContactKindFigures f;
  std::vector<double> sigmas;
  double sum = 0;
  for (int r = 0; r < data.size(); ++r) {
    if (data.rows[r].kind != kind) continue;
    if (feature >= 0 && data.rows[r].feature != feature) continue;
    ++f.rows;
    // |e| over the kind's residuals (three axes for position rows); the RMS per residual.
    const double e = errors[r];
    sum += e * e / MeasurementKind(kind).residuals;
    f.max_abs = std::max(f.max_abs, std::abs(e));
    sigmas.push_back(data.rows[r].sigma);
  }
  f.rms = f.rows > 0 ? std::sqrt(sum / f.rows) : 0;
  if (!sigmas.empty()) {
    std::sort(sigmas.begin(), sigmas.end());
    f.sigma = sigmas[sigmas.size() / 2];
  }
  return f;
}

const char* ContactKindVerdict(const ContactKindFigures& f) {
  if (f.rows == 0) return "none";
  const double ratio = f.sigma > 0 ? f.rms / f.sigma : 0;
  return ratio <= 2 ? "pass" : ratio <= 5 ? "check" : "fail";
}

Status ContactVerificationSet(const ContactMeasurementSet& data,
                              const std::vector<ContactMeasurementSet>& parts,
                              ContactMeasurementSet* verification) {
  ContactMeasurementSet combined = data;
  for (const ContactMeasurementSet& part : parts) combined.Append(part);
  if (combined.pivots.size() != data.pivots.size() ||
      combined.planes.size() != data.planes.size()) {
    return Status::Error(combined.pivots.size() != data.pivots.size()
                             ? combined.pivots[data.pivots.size()]
                             : combined.planes[data.planes.size()]);
  }
  std::vector<int> rows;
  for (int r = data.size(); r < combined.size(); ++r) rows.push_back(r);
  *verification = combined.Subset(rows);
  return Status::Ok();
}

namespace {

ContactCalibrationResult CalibrateContactsWith(const std::string& solver, const RobotModel& start,
                                               const ContactMeasurementSet& data,
                                               const ContactCalibrationOptions& options) {
  return solver == "ceres" ? CalibrateContactsCeres(start, data, options)
                           : CalibrateContactsLinear(start, data, options);
}

RobotModel WithoutLayer(const RobotModel& model) {
  RobotModel m = model;
  m.residual_layer = nullptr;
  return m;
}

// The layer of the run on its identification rows, stored in out->calibration.model.
void FitContactLayer(const ContactPipelineOptions& options, ContactPipelineResult* out) {
  out->residual_layer.requested = true;
  auto fitted = std::make_shared<ResidualLayer>();
  const Status s = FitContactResidualLayer(out->calibration, out->identification,
                                           options.residual_layer, fitted.get(),
                                           &out->residual_layer.fit);
  if (!s.ok()) {
    out->residual_layer.message = "residual layer not fitted: " + s.message();
    return;
  }
  out->residual_layer.fitted = true;
  out->residual_layer.inducing = fitted->num_inducing();
  out->calibration.model.residual_layer = std::move(fitted);
  out->errors_with_layer =
      ContactErrors(out->calibration.model, out->calibration.features, out->identification);
}

// --residual_model=auto: none against gp on folds of the identification rows (each fold's
// calibration and layer fitted on its training rows), the held-out errors in mm.
ResidualModelSelection SelectContactResidualModel(const RobotModel& start,
                                                  const ContactPipelineOptions& options,
                                                  const ContactCalibrationOptions& calibration,
                                                  const ContactPipelineResult& run) {
  const ContactMeasurementSet& identification = run.identification;
  ResidualModelSelection sel;
  sel.ran = true;
  sel.folds = std::min(options.kfold > 0 ? options.kfold : 5, identification.size());
  sel.seed = options.split_seed + 2;
  std::mt19937_64 rng(sel.seed);
  std::vector<int> order(identification.size());
  for (int i = 0; i < identification.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  std::vector<internal::FoldErrors> outcomes[2];
  for (int fold = 0; fold < sel.folds; ++fold) {
    internal::FoldErrors none, gp;
    std::vector<int> train, test;
    for (int i = 0; i < identification.size(); ++i) {
      (i % sel.folds == fold ? test : train).push_back(order[i]);
    }
    std::sort(train.begin(), train.end());
    std::sort(test.begin(), test.end());
    const ContactMeasurementSet training = identification.Subset(train);
    const ContactMeasurementSet tested = identification.Subset(test);
    ContactCalibrationResult f =
        CalibrateContactsWith(options.solver, start, training, calibration);
    auto layer = std::make_shared<ResidualLayer>();
    Status s = f.ok ? FitContactResidualLayer(f, training, options.residual_layer, layer.get(),
                                              nullptr)
                    : Status::Error(f.message);
    if (!s.ok()) {
      none.failure = gp.failure = "fold " + std::to_string(fold + 1) + ": " + s.message();
    } else {
      for (double e : ContactErrors(f.model, f.features, tested)) none.squared.push_back(e * e);
      f.model.residual_layer = std::move(layer);
      for (double e : ContactErrors(f.model, f.features, tested)) gp.squared.push_back(e * e);
      none.ok = gp.ok = true;
    }
    outcomes[0].push_back(std::move(none));
    outcomes[1].push_back(std::move(gp));
  }
  internal::ChooseResidualModel(outcomes, &sel);
  return sel;
}

// ---- Hold-out rows: the verification rows given, else options.holdout of the rows drawn with
// options.split_seed.
void SplitContactHoldout(const ContactMeasurementSet& data,
                         const ContactMeasurementSet& verification,
                         const ContactPipelineOptions& options, ContactPipelineResult* out) {
  out->identification = data;
  out->held = verification;
  out->held_from_verification = verification.size() > 0;
  if (options.holdout > 0 && !out->held_from_verification) {
    std::mt19937_64 rng(options.split_seed);
    std::vector<int> order(data.size());
    for (int i = 0; i < data.size(); ++i) order[i] = i;
    std::shuffle(order.begin(), order.end(), rng);
    const int count = static_cast<int>(std::floor(options.holdout * data.size()));
    std::vector<int> train(order.begin() + count, order.end()),
        test(order.begin(), order.begin() + count);
    std::sort(train.begin(), train.end());
    std::sort(test.begin(), test.end());
    out->identification = data.Subset(train);
    out->held = data.Subset(test);
  }
}

// ---- --joint_errors=auto: the terms chosen on the identification rows, into
// calibration->joint_terms. False (out->message says why) when they cannot be made.
bool ChooseContactJointTerms(const RobotModel& parametric_start,
                             const ContactPipelineOptions& options,
                             ContactCalibrationOptions* calibration, ContactPipelineResult* out) {
  out->joint_error_selection =
      SelectContactJointErrors(parametric_start, out->identification, options);
  const JointErrorSelection& sel = out->joint_error_selection;
  std::string chosen;
  for (const std::string& t : sel.candidates[sel.chosen].terms) {
    chosen += (chosen.empty() ? "" : ",") + t;
  }
  if (Status s = ContactJointTerms(chosen.empty() ? "none" : chosen, parametric_start,
                                   &calibration->joint_terms);
      !s.ok()) {
    out->message = s.message();
    return false;
  }
  return true;
}

// ---- The residual model: --residual_model=auto's choice, then the layer when it is "gp"; the
// held rows' errors with (and without) it.
void FitContactResidualModel(const RobotModel& parametric_start,
                             const ContactPipelineOptions& options,
                             const ContactCalibrationOptions& calibration,
                             ContactPipelineResult* out) {
  ResidualModelKind residual = options.residual_model;
  if (residual == ResidualModelKind::kAuto) {
    out->residual_model_selection =
        SelectContactResidualModel(parametric_start, options, calibration, *out);
    const ResidualModelSelection& sel = out->residual_model_selection;
    residual = sel.chosen >= 0 && sel.candidates[sel.chosen].label == "gp"
                   ? ResidualModelKind::kGp
                   : ResidualModelKind::kNone;
    if (residual == ResidualModelKind::kNone) {
      out->residual_layer.requested = true;
      out->residual_layer.message = "auto chose none (" + sel.reason + ")";
    }
  }
  if (residual == ResidualModelKind::kGp) FitContactLayer(options, out);
  if (out->held.size() > 0) {
    out->held_errors = ContactErrors(out->calibration.model, out->calibration.features, out->held);
    if (out->residual_layer.fitted) {
      out->held_errors_parametric =
          ContactErrors(WithoutLayer(out->calibration.model), out->calibration.features, out->held);
    }
  }
}

// ---- k-fold: each fold's rows predicted by the calibration of the others, same options. False
// (out says why) when a fold fails or there are fewer rows than folds.
bool RunContactKFold(const RobotModel& parametric_start, const ContactPipelineOptions& options,
                     const ContactCalibrationOptions& calibration, ContactPipelineResult* out) {
  const ContactMeasurementSet& identification = out->identification;
  if (options.kfold > identification.size()) {
    out->kfold_too_large = true;
    out->message = "is larger than the " + std::to_string(identification.size()) +
                   " identification rows";
    return false;
  }
  std::mt19937_64 rng(options.split_seed + 1);
  std::vector<int> order(identification.size());
  for (int i = 0; i < identification.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  out->fold_errors.assign(identification.size(), 0.0);
  for (int fold = 0; fold < options.kfold; ++fold) {
    std::vector<int> train, test;
    for (int i = 0; i < identification.size(); ++i) {
      (i % options.kfold == fold ? test : train).push_back(order[i]);
    }
    std::sort(train.begin(), train.end());
    std::sort(test.begin(), test.end());
    const ContactMeasurementSet training = identification.Subset(train);
    ContactCalibrationResult f =
        CalibrateContactsWith(options.solver, parametric_start, training, calibration);
    if (!f.ok) {
      out->failed_fold = fold;
      out->message = f.message;
      out->fold_failure = std::move(f);
      return false;
    }
    const ContactMeasurementSet tested = identification.Subset(test);
    const std::vector<double> e = ContactErrors(f.model, f.features, tested);
    for (size_t i = 0; i < test.size(); ++i) out->fold_errors[test[i]] = e[i];
    // With a layer: the fold's own, fitted on its training rows (none when its fit fails: the
    // fold's figure is then the parametric model's).
    if (out->residual_layer.fitted) {
      if (out->fold_errors_parametric.empty()) {
        out->fold_errors_parametric.assign(identification.size(), 0.0);
      }
      for (size_t i = 0; i < test.size(); ++i) out->fold_errors_parametric[test[i]] = e[i];
      auto fold_layer = std::make_shared<ResidualLayer>();
      if (FitContactResidualLayer(f, training, options.residual_layer, fold_layer.get(), nullptr)
              .ok()) {
        f.model.residual_layer = std::move(fold_layer);
        const std::vector<double> el = ContactErrors(f.model, f.features, tested);
        for (size_t i = 0; i < test.size(); ++i) out->fold_errors[test[i]] = el[i];
      }
    }
  }
  return true;
}

// The names of a kind's features in a set (pivots, planes), null for a kind without features.
const std::vector<std::string>* ContactFeatureNames(const ContactMeasurementSet& set,
                                                    const MeasurementKindInfo& kind) {
  if (kind.feature_size == 0) return nullptr;
  return kind.id == MeasurementKindId::kDistance ? &set.pivots : &set.planes;
}

// ---- Figures per kind (of the kind table) and per feature, and the run's verdict.
void SummarizeContactKinds(const ContactPipelineOptions& options, ContactPipelineResult* out) {
  const ContactMeasurementSet& identification = out->identification;
  out->verdict = "pass";
  for (const MeasurementKindInfo& kind : MeasurementKinds()) {
    if (kind.id == MeasurementKindId::kPose) continue;  // tracker rows are position rows here
    ContactKindSummary k;
    k.kind = &kind;
    k.fit = ContactFigures(identification, out->calibration.errors, kind.id);
    if (k.fit.rows == 0) continue;
    if (out->held.size() > 0) k.held = ContactFigures(out->held, out->held_errors, kind.id);
    if (options.kfold > 0) k.kfold = ContactFigures(identification, out->fold_errors, kind.id);
    if (out->residual_layer.fitted) {
      k.fit_with_layer = ContactFigures(identification, out->errors_with_layer, kind.id);
      if (out->held.size() > 0) {
        k.held_parametric = ContactFigures(out->held, out->held_errors_parametric, kind.id);
      }
      if (options.kfold > 0) {
        k.kfold_parametric = ContactFigures(identification, out->fold_errors_parametric, kind.id);
      }
    }
    const std::vector<std::string>* names = ContactFeatureNames(identification, kind);
    for (int i = 0; names != nullptr && i < static_cast<int>(names->size()); ++i) {
      ContactFeatureSummary s;
      s.name = (*names)[i];
      s.fit = ContactFigures(identification, out->calibration.errors, kind.id, i);
      if (s.fit.rows == 0) continue;
      if (out->held.size() > 0) s.held = ContactFigures(out->held, out->held_errors, kind.id, i);
      if (options.kfold > 0) s.kfold = ContactFigures(identification, out->fold_errors, kind.id, i);
      k.features.push_back(s);
    }
    const std::string v = ContactKindVerdict(k.fit);
    if (v == "fail" || (v == "check" && out->verdict == "pass")) out->verdict = v;
    out->kinds.push_back(std::move(k));
  }
}

}  // namespace

ContactPipelineResult RunContactPipeline(const RobotModel& start, const ContactMeasurementSet& data,
                                         const ContactMeasurementSet& verification,
                                         const ContactPipelineOptions& options) {
  ContactPipelineResult out;
  SplitContactHoldout(data, verification, options, &out);
  // The start model without a layer: the solvers' model is parametric.
  RobotModel parametric_start = start;
  parametric_start.residual_layer = nullptr;
  ContactCalibrationOptions calibration = options.calibration;
  if (options.joint_errors_auto &&
      !ChooseContactJointTerms(parametric_start, options, &calibration, &out)) {
    return out;
  }
  out.calibration =
      CalibrateContactsWith(options.solver, parametric_start, out.identification, calibration);
  if (!out.calibration.ok) {
    out.message = out.calibration.message;
    return out;
  }
  FitContactResidualModel(parametric_start, options, calibration, &out);
  if (options.kfold > 0 && !RunContactKFold(parametric_start, options, calibration, &out)) {
    return out;
  }
  SummarizeContactKinds(options, &out);
  out.ok = true;
  return out;
}

std::string ContactRefusalReason(const std::string& option) {
  if (option == "joint_errors_auto") {
    return "the automatic choice is made by lpoe_calibrate and lpoe.calibrate (it prints the "
           "chosen terms); comparing the two solvers takes the terms by name, e.g. "
           "--joint_errors=harmonics";
  }
  if (option == "joint_errors_tilt") {
    return "the gravity tilt is bilinear with the compliance term's parameters and is identified "
           "by the tracker solvers only; the contact solvers take the registry's linear terms "
           "(compliance, harmonics, ...) with gravity as the model gives it";
  }
  if (option == "loss") {
    return "both contact solvers minimise the plain whitened least-squares cost (the cost "
           "lpoe_compare checks they agree on); no robust loss is built for these rows";
  }
  if (option == "fixed_tools") {
    return "the contact parameterization decides every frame's directions from the data (the "
           "base's and the gauge's left out); holding a tool at given values is not part of it";
  }
  if (option == "parameterization") {
    return "distances and planes do not see the base relative to the pivots and planes: the full "
           "parameterization would carry those null directions, so the identifiable one, decided "
           "from the data, is always used";
  }
  if (option == "urdf_with_tracker") {
    return "with a tracker file the model is registered into the tracker's frame first, and that "
           "registration is not recorded to be taken back out: the URDF's first joint would "
           "carry the tracker's pose";
  }
  return "";
}

Status ContactJointTerms(const std::string& text, const RobotModel& reference,
                         std::vector<std::shared_ptr<const JointTerm>>* terms) {
  terms->clear();
  if (text == "none" || text.empty()) return Status::Ok();
  if (text == "auto") {
    return Status::Error("'auto' is not available with distance or plane data: " +
                         ContactRefusalReason("joint_errors_auto"));
  }
  std::vector<std::string> names, effects;
  std::string error;
  if (!ParseJointErrorList(text, &names, &effects, &error)) {
    return Status::Error("'" + text + "': " + error + " (expected none or a comma-separated list "
                         "of " + JointTermNameList() + ")");
  }
  if (!effects.empty()) {
    return Status::Error("'" + text + "': the " +
                         FindBilinearEffectName(effects.front())->description +
                         " is not available with distance or plane data: " +
                         ContactRefusalReason("joint_errors_tilt"));
  }
  for (const std::string& name : InRegistryOrder(names)) {
    std::shared_ptr<const JointTerm> term;
    if (Status s = MakeJointTerm(name, reference, &term); !s.ok()) return s;
    terms->push_back(std::move(term));
  }
  return Status::Ok();
}

Status ReadContactInputs(const std::vector<std::string>& files, const RobotModel& nominal,
                         const ContactInputOptions& options, ContactInputs* out,
                         bool* usage_error) {
  bool usage_dummy = false;
  bool* usage = usage_error != nullptr ? usage_error : &usage_dummy;
  *usage = false;
  out->data = ContactMeasurementSet();
  out->data.num_joints = nominal.num_joints();
  out->tracker = MeasurementSet(nominal.num_joints());
  out->kinds.clear();
  for (size_t i = 0; i < files.size(); ++i) {
    const double sigma = i < options.sigmas.size() ? options.sigmas[i] : 0.0;
    const MeasurementKindInfo* kind = nullptr;
    if (Status s = DetectMeasurementFileKind(files[i], &kind); !s.ok()) return s;
    if (options.forced_kind != nullptr && options.forced_kind != kind) {
      return Status::Error(files[i] + ": --data_kind=" + options.forced_kind->name +
                           " but its columns are a " + kind->name + " file's (" + kind->columns +
                           ")");
    }
    out->kinds.push_back(kind->name);
    ContactMeasurementSet part;
    if (!IsTrackerKind(kind->id)) {  // a kind with a feature: the contact reader
      ContactCsvOptions o;
      o.units = options.units;
      o.kind = kind;
      o.sigma = sigma;
      if (Status s = ReadContactMeasurements(files[i], nominal, o, &part); !s.ok()) return s;
    } else {
      if (!options.tracker_refusal.empty()) {
        *usage = true;
        return Status::Error(files[i] + ": " + options.tracker_refusal);
      }
      if (!(sigma > 0)) {
        *usage = true;
        return Status::Error(files[i] +
                             ": a tracker file has no sigma column; give its noise with --sigmas "
                             "(one value per file) or --sigma");
      }
      MeasurementSet positions;
      if (Status s = ReadMeasurements(files[i], nominal, options.units, &positions, nullptr);
          !s.ok()) {
        return s;
      }
      out->tracker.Append(positions);
      part = ContactSetFromPositions(positions, sigma, files[i]);
    }
    out->data.Append(part);
  }
  return Status::Ok();
}

}  // namespace lpoe
