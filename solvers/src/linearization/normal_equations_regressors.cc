// The joint-space terms' regressors in slot form and the projections of their blocks
// (normal_equations.h: BuildJointSpaceRegressors, SetSlotBasis, SameFrameDirections,
// ProjectJointBlocks). The accumulation of the normal equations is in normal_equations_assembly.cc.
#include "linearization/normal_equations.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <glog/logging.h>

#include "lpoe/terms/joint_term.h"

namespace lpoe {
namespace internal {

bool SameFrameDirections(const Parameterization& a, const Parameterization& b) {
  if (a.num_frame_parameters() != b.num_frame_parameters() || a.basis.size() != b.basis.size()) {
    return false;
  }
  for (size_t f = 0; f < a.basis.size(); ++f) {
    if (a.offset[f] != b.offset[f] || a.basis[f].cols() != b.basis[f].cols() ||
        a.basis[f] != b.basis[f]) {
      return false;
    }
  }
  return true;
}

JointSpaceRegressors BuildJointSpaceRegressors(const Parameterization& p,
                                               const MeasurementSet& data) {
  const int n = data.num_joints();
  const int N = data.size();
  JointSpaceRegressors regs;
  regs.num_joints = n;
  regs.column_offset.push_back(0);
  // Per joint: the unreduced columns that may move it (JointTerm::ParameterJoint).
  std::vector<std::vector<int>> columns(n);
  std::vector<int> joint_of;  // per unreduced column, -1: several joints
  for (const JointBlock& block : p.joint_blocks) {
    const JointTerm& term = *block.term;
    CHECK_EQ(term.num_joints(), n) << term.name();
    const int first = regs.column_offset.back();
    regs.one_joint_each.push_back(1);
    for (int k = 0; k < term.num_parameters(); ++k) {
      const int j = term.ParameterJoint(k);
      CHECK(j >= -1 && j < n) << term.name() << ": ParameterJoint(" << k << ") = " << j;
      if (j < 0) regs.one_joint_each.back() = 0;
      joint_of.push_back(j);
      for (int i = 0; i < n; ++i) {
        if (j < 0 || i == j) columns[i].push_back(first + k);
      }
    }
    regs.column_offset.push_back(first + term.num_parameters());
  }
  auto set_slots = [&]() {
    regs.slot_begin.assign(1, 0);
    regs.slot_column.clear();
    for (int j = 0; j < n; ++j) {
      regs.slot_column.insert(regs.slot_column.end(), columns[j].begin(), columns[j].end());
      regs.slot_begin.push_back(static_cast<int>(regs.slot_column.size()));
    }
  };
  set_slots();
  const int S = regs.num_slots();
  const double bytes = 8.0 * S * static_cast<double>(N);
  if (S > 0 && N > 0 && bytes <= kMaxJointRowsBytes) {
    // Every row's regressors, checked against the declared pattern; slots that stay zero in every
    // row are dropped. Slot t reads entry source[t] of its block's Y (column-major n x P_b).
    std::vector<int> source(S), block_of(S);
    for (int j = 0; j < n; ++j) {
      for (int t = regs.slot_begin[j]; t < regs.slot_begin[j + 1]; ++t) {
        const int c = regs.slot_column[t];
        int b = 0;
        while (c >= regs.column_offset[b + 1]) ++b;
        block_of[t] = b;
        source[t] = (c - regs.column_offset[b]) * n + j;
      }
    }
    // A block whose every parameter moves one joint may give those entries alone
    // (JointTerm::RegressorValues): slot t then reads entry slot_column[t] - column_offset[b].
    const size_t B = p.joint_blocks.size();
    std::vector<char> single_joint(B, 1), from_values(B, 0);
    std::vector<Eigen::VectorXd> y(B);
    for (size_t b = 0; b < B; ++b) {
      for (int c = regs.column_offset[b]; c < regs.column_offset[b + 1]; ++c) {
        if (joint_of[c] < 0) single_joint[b] = 0;
      }
      y[b].resize(p.joint_blocks[b].term->num_parameters());
    }
    std::vector<const double*> value_of(S);  // y's entry of each slot (y is not resized below)
    for (int t = 0; t < S; ++t) {
      const int b = block_of[t];
      value_of[t] = y[b].data() + (regs.slot_column[t] - regs.column_offset[b]);
    }
    Eigen::MatrixXd values(S, N);
    std::vector<Eigen::MatrixXd> Y(B);
    std::vector<char> used(S, 0);
    for (int r = 0; r < N; ++r) {
      const double* q = data.q(r);
      for (size_t b = 0; b < B; ++b) {
        const JointTerm& term = *p.joint_blocks[b].term;
        from_values[b] = single_joint[b] && term.RegressorValues(q, y[b].data());
        if (from_values[b]) continue;
        Y[b].resize(n, term.num_parameters());
        term.Regressor(q, Y[b].data());
        // A column that moves only its declared joint sums (exactly: the others add zeros) to that
        // joint's entry.
        const Eigen::RowVectorXd moved = Y[b].cwiseAbs().colwise().sum();
        for (int k = 0; k < Y[b].cols(); ++k) {
          const int j = joint_of[regs.column_offset[b] + k];
          if (j >= 0 && moved(k) != std::abs(Y[b](j, k))) {
            int i = 0;
            while (i + 1 < n && (i == j || Y[b](i, k) == 0)) ++i;
            LOG(FATAL) << "joint-space term " << term.name() << ": parameter "
                       << term.ParameterName(k) << " moves joint " << i + 1
                       << " but ParameterJoint() says joint " << j + 1;
          }
        }
      }
      double* v = values.col(r).data();
      bool all_values = true;
      for (size_t b = 0; b < B; ++b) all_values = all_values && from_values[b];
      if (all_values) {  // every block gave its entries: slot t reads value_of[t]
        for (int t = 0; t < S; ++t) {
          v[t] = *value_of[t];
          used[t] |= v[t] != 0;
        }
        continue;
      }
      for (int t = 0; t < S; ++t) {
        const int b = block_of[t];
        v[t] = from_values[b] ? y[b](regs.slot_column[t] - regs.column_offset[b])
                              : Y[b].data()[source[t]];
        used[t] |= v[t] != 0;
      }
    }
    std::vector<int> kept;
    for (int j = 0; j < n; ++j) {
      std::vector<int> live;
      for (int t = regs.slot_begin[j]; t < regs.slot_begin[j + 1]; ++t) {
        if (used[t]) {
          live.push_back(regs.slot_column[t]);
          kept.push_back(t);
        }
      }
      columns[j] = std::move(live);
    }
    set_slots();
    if (static_cast<int>(kept.size()) == S) {
      regs.values = std::move(values);
    } else {
      regs.values.resize(static_cast<Eigen::Index>(kept.size()), N);
      for (int r = 0; r < N; ++r) {
        for (size_t t = 0; t < kept.size(); ++t) regs.values(t, r) = values(kept[t], r);
      }
    }
  }
  SetSlotBasis(p, &regs);
  return regs;
}

void SetSlotBasis(const Parameterization& p, JointSpaceRegressors* r) {
  CHECK_EQ(r->column_offset.size(), p.joint_blocks.size() + 1);
  const int F = p.num_frame_parameters();
  r->slot_basis.setZero(r->num_slots(), p.num_joint_parameters());
  for (int t = 0; t < r->num_slots(); ++t) {
    const int c = r->slot_column[t];
    size_t b = 0;
    while (c >= r->column_offset[b + 1]) ++b;
    const JointBlock& block = p.joint_blocks[b];
    CHECK_EQ(block.basis.rows(), r->column_offset[b + 1] - r->column_offset[b])
        << "regressors of other joint-space terms";
    r->slot_basis.row(t).segment(block.offset - F, block.basis.cols()) =
        block.basis.row(c - r->column_offset[b]);
  }
}

NormalEquations ProjectJointBlocks(const NormalEquations& full, const Parameterization& reduced) {
  const int F = reduced.num_frame_parameters();
  const int K = reduced.num_joint_parameters();
  int unreduced = 0;
  for (const JointBlock& b : reduced.joint_blocks) unreduced += static_cast<int>(b.basis.rows());
  CHECK_EQ(full.H.rows(), F + unreduced);
  // T (unreduced x K) is block diagonal, one block per joint block (its basis): the products
  // below go block by block.
  struct Part {
    int row, col;
    const Eigen::MatrixXd* basis;
  };
  std::vector<Part> parts;
  int row = 0;
  for (const JointBlock& b : reduced.joint_blocks) {
    parts.push_back({row, b.offset - F, &b.basis});
    row += static_cast<int>(b.basis.rows());
  }
  NormalEquations out;
  out.cost = full.cost;
  out.max_error = full.max_error;
  out.mean_error = full.mean_error;
  out.joint_blocks = full.joint_blocks;
  out.H.resize(F + K, F + K);
  out.g.resize(F + K);
  out.H.topLeftCorner(F, F) = full.H.topLeftCorner(F, F);
  out.g.head(F) = full.g.head(F);
  Eigen::MatrixXd HT(unreduced, K);  // H_joint T
  for (const Part& b : parts) {
    const Eigen::MatrixXd& B = *b.basis;
    const Eigen::Index r = B.rows(), k = B.cols();
    out.H.block(0, F + b.col, F, k).noalias() = full.H.block(0, F + b.row, F, r) * B;
    HT.middleCols(b.col, k).noalias() = full.H.block(F, F + b.row, unreduced, r) * B;
    out.g.segment(F + b.col, k).noalias() = B.transpose() * full.g.segment(F + b.row, r);
  }
  out.H.bottomLeftCorner(K, F) = out.H.topRightCorner(F, K).transpose();
  Eigen::MatrixXd Hkk(K, K);
  for (const Part& a : parts) {
    const Eigen::MatrixXd& B = *a.basis;
    Hkk.middleRows(a.col, B.cols()).noalias() = B.transpose() * HT.middleRows(a.row, B.rows());
  }
  out.H.bottomRightCorner(K, K) = 0.5 * (Hkk + Hkk.transpose());
  out.finite = full.finite && out.H.allFinite() && out.g.allFinite();
  return out;
}

}  // namespace internal
}  // namespace lpoe
