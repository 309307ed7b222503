// Selected columns of the orthogonal factor of a Householder QR, without forming the whole of it.
#pragma once

#include <Eigen/Core>
#include <Eigen/QR>

namespace lpoe {

// Columns [first, first + count) of the Householder Q of `qr`'s matrix (P x P), as P x count: the
// identity's columns with the reflectors H_{r-1} .. H_0 applied, each only to the rows it acts on
// and the columns it changes (column c of the identity is untouched by H_j for j > c), which are the
// operations HouseholderSequence::evalTo does on those columns, so the numbers are those of
// `Eigen::MatrixXd(qr.householderQ()).middleCols(first, count)`. When Eigen would form Q by blocks
// of reflectors (more than 48 of them), or for a single column (its product would be a dot
// product, another summation order), the whole Q is formed and the columns taken from it.
// The joint blocks' kept combinations (first = 0) and their complement (first = k) use it.
Eigen::MatrixXd HouseholderQColumns(const Eigen::HouseholderQR<Eigen::MatrixXd>& qr,
                                    Eigen::Index first, Eigen::Index count);

}  // namespace lpoe
