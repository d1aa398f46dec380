// Multifrontal sparse Cholesky over a nested-dissection tree, for the sheet's matrices.
//
// The flattening solvers factor matrices whose pattern is the sheet's spring graph: the graph
// Laplacian (one unknown per node) and the Gauss-Newton normal equations (a 2 x 2 block per
// node pair). Ordered by nested dissection (the caller's tree, see Front), each front
// eliminates one separator as a dense block: the work runs in vectorised dense kernels rather
// than a scalar column-by-column loop, which on a 200 x 150 sheet is several times faster
// than a simplicial factorisation of the same ordering.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <functional>
#include <vector>

#include "core/common/status.h"

namespace vellum {

// One front of the elimination tree: eliminates nodes [first, end) of the ordering. Fronts are
// listed children before parents (postorder); a subtree's nodes precede its separator's.
struct Front {
  int first = 0, end = 0;
  int parent = -1;  // -1: a root.
};

// Nested-dissection order of the cells of a cols x rows grid (cell (i, j) is j * cols + i)
// for which `active` holds: both halves of the grid first, then the band of `band` rows or
// columns that separates them (no edge of the graph may span more than `band` cells),
// recursively, down to leaves of a few cells. Eliminated in this order a grid graph's
// Cholesky factor fills in O(n log n). Writes the cells in order to `order` and returns the
// fronts: one per band and per leaf.
std::vector<Front> DissectGrid(int cols, int rows, int band, const std::function<bool(int)>& active,
                               std::vector<int>* order);

class FrontalCholesky {
 public:
  // pattern: the nodes' graph as a lower-triangular column-compressed matrix (diagonal
  // included; values ignored), in the ordering of `fronts`. block: unknowns per node.
  Status Analyze(const Eigen::SparseMatrix<double>& pattern, const std::vector<Front>& fronts,
                 int block);

  // values: block x block entries (column-major) per nonzero of the pattern, in the pattern's
  // storage order. Only the lower triangle of diagonal blocks is read. Returns false if the
  // matrix is not positive definite.
  bool Factorize(const std::vector<double>& values);

  // Solves A X = B in place; B has block * nodes rows (unknown d of node v on row
  // block * v + d) and any number of columns.
  void Solve(Eigen::MatrixXd* b) const;

  int block() const { return block_; }
  int unknowns() const { return unknowns_; }

 private:
  struct Frontal {
    int first = 0, size = 0;    // Eliminated unknowns [first, first + size).
    std::vector<int> boundary;  // Later unknowns coupled to them, ascending.
    std::vector<int> children;
    Eigen::MatrixXd l_ss;  // Cholesky factor of the separator block (lower).
    Eigen::MatrixXd l_bs;  // boundary x separator block of the factor.
  };

  int block_ = 1, unknowns_ = 0;
  std::vector<Frontal> fronts_;
  std::vector<int> col_begin_;  // Pattern column starts (node level), and their rows:
  std::vector<int> row_;
  std::vector<int> local_;               // Scratch: unknown -> row in the current front (-1: none).
  std::vector<Eigen::MatrixXd> update_;  // Per front, its update for the parent.
};

}  // namespace vellum
