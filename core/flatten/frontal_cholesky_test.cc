#include "core/flatten/frontal_cholesky.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <random>

namespace vellum {
namespace {

// A grid graph with holes, its edges spanning up to `span` cells (8-neighbours, and bend edges
// two cells apart when span is 2), as a random positive definite matrix with `block` unknowns
// per node: each edge adds a positive semidefinite block coupling its ends, like a spring.
struct GridSystem {
  GridSystem(int cols, int rows, int span, int block, unsigned seed) : block(block) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> unit(-1, 1);
    auto active = [&](int k) { return k % 7 != 3; };  // Scattered holes.
    std::vector<int> order;
    fronts = DissectGrid(cols, rows, span, active, &order);
    const int n = static_cast<int>(order.size());
    std::vector<int> var(cols * rows, -1);
    for (int v = 0; v < n; ++v) var[order[v]] = v;
    dense = Eigen::MatrixXd::Zero(block * n, block * n);
    std::vector<Eigen::Triplet<double>> lt;
    auto couple = [&](int a, int b) {
      Eigen::VectorXd u(block);
      for (int d = 0; d < block; ++d) u[d] = unit(rng);
      const Eigen::MatrixXd uu = u * u.transpose();
      dense.block(block * a, block * a, block, block) += uu;
      dense.block(block * b, block * b, block, block) += uu;
      dense.block(block * a, block * b, block, block) -= uu;
      dense.block(block * b, block * a, block, block) -= uu;
      lt.emplace_back(std::max(a, b), std::min(a, b), 1.0);
    };
    for (int j = 0; j < rows; ++j) {
      for (int i = 0; i < cols; ++i) {
        for (int dj = 0; dj <= span; ++dj) {
          for (int di = -span; di <= span; ++di) {
            if ((dj == 0 && di <= 0) || i + di < 0 || i + di >= cols || j + dj >= rows) continue;
            const int a = var[j * cols + i], b = var[(j + dj) * cols + i + di];
            if (a >= 0 && b >= 0) couple(a, b);
          }
        }
      }
    }
    for (int v = 0; v < n; ++v) lt.emplace_back(v, v, 1.0);
    dense += 1e-3 * Eigen::MatrixXd::Identity(block * n, block * n);
    pattern.resize(n, n);
    pattern.setFromTriplets(lt.begin(), lt.end());
    pattern.makeCompressed();
    // The blocks in the pattern's storage order, read back from the dense matrix.
    for (int c = 0; c < n; ++c) {
      for (Eigen::SparseMatrix<double>::InnerIterator it(pattern, c); it; ++it) {
        const Eigen::MatrixXd b = dense.block(block * it.row(), block * c, block, block);
        for (int q = 0; q < block * block; ++q) values.push_back(b(q % block, q / block));
      }
    }
  }
  int block;
  std::vector<Front> fronts;
  Eigen::SparseMatrix<double> pattern;
  std::vector<double> values;
  Eigen::MatrixXd dense;
};

void ExpectSolvesLikeDense(int cols, int rows, int span, int block) {
  GridSystem sys(cols, rows, span, block, 7u * cols + rows);
  FrontalCholesky chol;
  ASSERT_TRUE(chol.Analyze(sys.pattern, sys.fronts, block).ok());
  ASSERT_TRUE(chol.Factorize(sys.values));
  const Eigen::MatrixXd rhs = Eigen::MatrixXd::Random(sys.dense.rows(), 3);
  Eigen::MatrixXd x = rhs;
  chol.Solve(&x);
  const Eigen::MatrixXd want = sys.dense.llt().solve(rhs);
  // Both are backward stable: relative agreement far below any use's need (the condition
  // number here is about 1e5).
  EXPECT_LT((x - want).norm() / want.norm(), 1e-9) << cols << "x" << rows << " span " << span;
  EXPECT_LT((sys.dense * x - rhs).norm() / rhs.norm(), 1e-11);
}

TEST(FrontalCholesky, SolvesLikeDenseCholesky) {
  ExpectSolvesLikeDense(13, 9, 1, 1);
  ExpectSolvesLikeDense(13, 9, 1, 2);
  ExpectSolvesLikeDense(31, 17, 2, 2);  // Bend springs: bands two cells wide.
  ExpectSolvesLikeDense(2, 2, 1, 2);
  ExpectSolvesLikeDense(1, 40, 1, 1);  // A strip.
}

TEST(FrontalCholesky, DissectionCoversEveryActiveCellOnce) {
  std::vector<int> order;
  const std::vector<Front> fronts = DissectGrid(
      45, 45, 1, [](int k) { return k % 5 != 0; }, &order);
  std::vector<int> seen(45 * 45, 0);
  for (int k : order) ++seen[k];
  for (int k = 0; k < 45 * 45; ++k) EXPECT_EQ(seen[k], k % 5 != 0 ? 1 : 0) << k;
  ASSERT_FALSE(fronts.empty());
  EXPECT_EQ(fronts.back().parent, -1);
  EXPECT_EQ(fronts.back().end, static_cast<int>(order.size()));
  // The last front is the top separator: one column of the 45 x 45 grid.
  EXPECT_LE(fronts.back().end - fronts.back().first, 45);
}

TEST(FrontalCholesky, RefusesIndefiniteMatrices) {
  GridSystem sys(9, 9, 1, 2, 1);
  for (double& v : sys.values) v = -v;
  FrontalCholesky chol;
  ASSERT_TRUE(chol.Analyze(sys.pattern, sys.fronts, 2).ok());
  EXPECT_FALSE(chol.Factorize(sys.values));
  EXPECT_FALSE(chol.Factorize(std::vector<double>(3, 1.0)));  // Wrong size.
}

TEST(FrontalCholesky, RefusesATreeThatDoesNotSeparate) {
  GridSystem sys(9, 9, 1, 1, 1);
  // Every node its own root: coupled nodes in different trees.
  std::vector<Front> flat;
  for (int v = 0; v < sys.pattern.cols(); ++v) flat.push_back({v, v + 1, -1});
  FrontalCholesky chol;
  const Status s = chol.Analyze(sys.pattern, flat, 1);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not a separator tree"), std::string::npos) << s.message();
  // A front listed after its parent.
  std::vector<Front> backwards = sys.fronts;
  backwards[0].parent = 0;
  EXPECT_FALSE(chol.Analyze(sys.pattern, backwards, 1).ok());
}

}  // namespace
}  // namespace vellum
