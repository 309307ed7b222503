// The dense decompositions of dynamic-size matrices used across the library, instantiated once.
//
// Eigen's BDCSVD, JacobiSVD, SelfAdjointEigenSolver and ColPivHouseholderQR of Eigen::MatrixXd are
// heavy templates: every translation unit that uses one spends 10-40 s compiling it (several times
// that under the sanitizers). Including this header instead of <Eigen/SVD>, <Eigen/Eigenvalues> or
// <Eigen/QR> declares them `extern template`, so they are compiled once, in
// core/src/kinematics/eigen_decompositions.cc, and linked from lpoe_core. Fixed-size decompositions
// (Matrix3d, 6x6) are cheap and stay implicit.
#pragma once

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

extern template class Eigen::BDCSVD<Eigen::MatrixXd>;
extern template class Eigen::JacobiSVD<Eigen::MatrixXd>;
extern template class Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>;
extern template class Eigen::ColPivHouseholderQR<Eigen::MatrixXd>;
extern template class Eigen::HouseholderQR<Eigen::MatrixXd>;
// `extern template class` does not reach member templates: SelfAdjointEigenSolver's compute() is
// one (templated on the input's type), and it holds the expensive part (the tridiagonalization and
// the Householder back-transformation). Declared here for the input type every caller uses, a
// plain MatrixXd (including the constructor's call of it).
extern template Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>&
Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>::compute<Eigen::MatrixXd>(
    const Eigen::EigenBase<Eigen::MatrixXd>&, int);
