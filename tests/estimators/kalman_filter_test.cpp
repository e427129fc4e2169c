// Discrete Kalman filter (Saheba 2010 eqs. 18-34): closed-form gain, Joseph vs textbook update.
#include "estimators/kalman_filter.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <utility>

namespace pe = pumptherm::estimators;

// Local level model x(k+1) = x(k) + w, y = x + v, var(w) = q, var(v) = r. Its steady-state prior
// variance solves P = P r / (P + r) + q, i.e. P = (q + sqrt(q^2 + 4 q r)) / 2, and the gain is
// K = P / (P + r): J. Durbin and S. J. Koopman, "Time Series Analysis by State Space Methods",
// 2nd ed., Oxford 2012, section 2.11 (steady state of the local level model).
TEST(KalmanFilter, LocalLevelGainConvergesToClosedForm) {
  const double q = 0.0894 * 0.0894, r = 0.0557 * 0.0557;
  pe::KalmanFilter kf(1);
  kf.Reset(Eigen::VectorXd::Zero(1), Eigen::MatrixXd::Constant(1, 1, 100.0));
  const Eigen::MatrixXd a = Eigen::MatrixXd::Identity(1, 1);
  const Eigen::MatrixXd qm = Eigen::MatrixXd::Constant(1, 1, q);
  const Eigen::MatrixXd rm = Eigen::MatrixXd::Constant(1, 1, r);
  const Eigen::MatrixXd c = Eigen::MatrixXd::Identity(1, 1);
  for (int k = 0; k < 200; ++k) {
    kf.Predict(a, Eigen::VectorXd::Zero(1), qm);
    kf.Update(c, Eigen::VectorXd::Zero(1), rm);
  }
  const double p = (q + std::sqrt(q * q + 4 * q * r)) / 2.0;
  EXPECT_NEAR(kf.Gain()(0, 0), p / (p + r), 1e-12);
  EXPECT_NEAR(kf.Covariance()(0, 0), p * r / (p + r), 1e-14);
}

TEST(KalmanFilter, OneStepGainMatchesFormula) {
  // K = S C^T (C S C^T + Sm)^-1 (eq. 34) written out for a 2-state, 1-measurement case.
  pe::KalmanFilter kf(2);
  Eigen::Matrix2d s;
  s << 4.0, 1.0, 1.0, 2.0;
  kf.Reset(Eigen::Vector2d(1.0, 2.0), s);
  Eigen::MatrixXd c(1, 2);
  c << 1.0, 0.0;
  const auto& rep =
      kf.Update(c, Eigen::VectorXd::Constant(1, 3.0), Eigen::MatrixXd::Constant(1, 1, 1.0));
  EXPECT_NEAR(kf.Gain()(0, 0), 4.0 / 5.0, 1e-15);
  EXPECT_NEAR(kf.Gain()(1, 0), 1.0 / 5.0, 1e-15);
  EXPECT_NEAR(rep.innovation(0), 2.0, 1e-15);
  EXPECT_NEAR(rep.nis, 4.0 / 5.0, 1e-15);
  EXPECT_NEAR(kf.State()(0), 1.0 + 1.6, 1e-15);
  EXPECT_NEAR(kf.State()(1), 2.0 + 0.4, 1e-15);
}

TEST(KalmanFilter, AddVarianceWidensOneStateAndIgnoresBadInput) {
  pe::KalmanFilter kf(2);
  Eigen::Matrix2d s;
  s << 4.0, 1.0, 1.0, 2.0;
  kf.Reset(Eigen::Vector2d(1.0, 2.0), s);
  kf.AddVariance(1, 3.0);
  EXPECT_DOUBLE_EQ(kf.Covariance()(1, 1), 5.0);
  EXPECT_DOUBLE_EQ(kf.Covariance()(0, 1), 1.0);  // a jump of that state alone
  kf.AddVariance(2, 1.0);
  kf.AddVariance(-1, 1.0);
  kf.AddVariance(0, -1.0);
  kf.AddVariance(0, std::nan(""));
  EXPECT_DOUBLE_EQ(kf.Covariance()(0, 0), 4.0);
  EXPECT_DOUBLE_EQ(kf.Covariance()(1, 1), 5.0);
}

TEST(KalmanFilter, JosephAndTextbookUpdatesAgree) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> nd;
  const int n = 7, m = 2;
  Eigen::MatrixXd l(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) l(i, j) = nd(rng);
  const Eigen::MatrixXd s0 = l * l.transpose() + Eigen::MatrixXd::Identity(n, n);
  Eigen::MatrixXd a(n, n), c(m, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) a(i, j) = 0.1 * nd(rng) + (i == j ? 0.9 : 0.0);
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < n; ++j) c(i, j) = nd(rng);
  const Eigen::MatrixXd q = 0.01 * Eigen::MatrixXd::Identity(n, n);
  const Eigen::MatrixXd r = 0.3 * Eigen::MatrixXd::Identity(m, m);
  pe::KalmanFilter joseph(n), textbook(n);
  joseph.Reset(Eigen::VectorXd::Zero(n), s0);
  textbook.Reset(Eigen::VectorXd::Zero(n), s0);
  for (int k = 0; k < 50; ++k) {
    Eigen::VectorXd y(m), u(n);
    for (int i = 0; i < m; ++i) y(i) = nd(rng);
    for (int i = 0; i < n; ++i) u(i) = nd(rng);
    joseph.Predict(a, u, q);
    textbook.Predict(a, u, q);
    const auto rj = joseph.Update(c, y, r, pe::CovarianceUpdate::kJoseph);
    const auto rt = textbook.Update(c, y, r, pe::CovarianceUpdate::kTextbook);
    EXPECT_NEAR(rj.nis, rt.nis, 1e-9 * (1 + rt.nis));
  }
  EXPECT_LT((joseph.Covariance() - textbook.Covariance()).cwiseAbs().maxCoeff(), 1e-10);
  EXPECT_LT((joseph.State() - textbook.State()).cwiseAbs().maxCoeff(), 1e-10);
  // The Joseph form stays exactly symmetric.
  EXPECT_EQ((joseph.Covariance() - joseph.Covariance().transpose()).cwiseAbs().maxCoeff(), 0.0);
}

TEST(KalmanFilter, NoMeasurementLeavesTheStateAndReportsZero) {
  pe::KalmanFilter kf(2);
  kf.Reset(Eigen::Vector2d(1, 2), Eigen::Matrix2d::Identity());
  const auto& rep = kf.Update(Eigen::MatrixXd(0, 2), Eigen::VectorXd(0), Eigen::MatrixXd(0, 0));
  EXPECT_EQ(rep.measurements, 0);
  EXPECT_EQ(kf.State(), Eigen::Vector2d(1, 2));
}

TEST(KalmanFilter, IndefiniteInnovationCovarianceIsReportedNotThrown) {
  pe::KalmanFilter kf(1);
  kf.Reset(Eigen::VectorXd::Zero(1), Eigen::MatrixXd::Constant(1, 1, 1.0));
  const auto& rep = kf.Update(Eigen::MatrixXd::Identity(1, 1), Eigen::VectorXd::Ones(1),
                              Eigen::MatrixXd::Constant(1, 1, -2.0));
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(kf.State()(0), 0.0);
}

// The fixed-size paths (4 to 11 states, 1 to 3 measurements) against eqs. 30-34 with the Joseph
// form written out here in dynamic-size Eigen (an oracle cross-check), and against counts that
// take the dynamic path (12 states, 4 measurements) for the same equations.
TEST(KalmanFilter, FixedSizePathsMatchTheEquationsWrittenOut) {
  for (const int n : {4, 5, 6, 7, 9, 10, 11, 12}) {
    for (const int m : {1, 2, 3, 4}) {
      std::mt19937_64 rng(11 + static_cast<unsigned>(n) * 7 + static_cast<unsigned>(m));
      std::normal_distribution<double> nd;
      Eigen::MatrixXd l(n, n), a(n, n), c(m, n);
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < m; ++j) c(j, i) = nd(rng);
        for (int j = 0; j < n; ++j) {
          l(i, j) = nd(rng);
          a(i, j) = 0.1 * nd(rng) + (i == j ? 0.9 : 0.0);
        }
      }
      Eigen::MatrixXd s = l * l.transpose() + Eigen::MatrixXd::Identity(n, n);
      const Eigen::MatrixXd q = 0.02 * Eigen::MatrixXd::Identity(n, n);
      const Eigen::MatrixXd r = 0.4 * Eigen::MatrixXd::Identity(m, m);
      Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
      pe::KalmanFilter kf(n);
      kf.Reset(x, s);
      const std::string what = "n=" + std::to_string(n) + " m=" + std::to_string(m);
      for (int k = 0; k < 20; ++k) {
        Eigen::VectorXd u(n), y(m);
        for (int i = 0; i < n; ++i) u(i) = nd(rng);
        for (int i = 0; i < m; ++i) y(i) = nd(rng);
        // Oracle.
        x = a * x + u;
        s = a * s * a.transpose() + q;
        const Eigen::MatrixXd sy = c * s * c.transpose() + r;
        const Eigen::MatrixXd gain = s * c.transpose() * sy.inverse();
        const Eigen::VectorXd nu = y - c * x;
        const double nis = nu.dot(sy.inverse() * nu);
        x += gain * nu;
        const Eigen::MatrixXd ikc = Eigen::MatrixXd::Identity(n, n) - gain * c;
        s = ikc * s * ikc.transpose() + gain * r * gain.transpose();
        // Filter.
        kf.Predict(a, u, q);
        const pe::KalmanUpdateReport& rep = kf.Update(c, y, r);
        ASSERT_TRUE(rep.ok) << what;
        EXPECT_LT((rep.innovation - nu).cwiseAbs().maxCoeff(),
                  1e-9 * (1 + nu.cwiseAbs().maxCoeff()))
            << what;
        EXPECT_LT((rep.innovation_var - sy.diagonal()).cwiseAbs().maxCoeff(),
                  1e-9 * sy.diagonal().maxCoeff())
            << what;
        EXPECT_NEAR(rep.nis, nis, 1e-9 * (1 + nis)) << what;
        EXPECT_LT((kf.Gain() - gain).cwiseAbs().maxCoeff(), 1e-10) << what;
      }
      EXPECT_LT((kf.State() - x).cwiseAbs().maxCoeff(), 1e-9) << what;
      EXPECT_LT((kf.Covariance() - s).cwiseAbs().maxCoeff(), 1e-9 * s.cwiseAbs().maxCoeff())
          << what;
      EXPECT_EQ((kf.Covariance() - kf.Covariance().transpose()).cwiseAbs().maxCoeff(), 0.0) << what;
    }
  }
}

// A non-positive innovation covariance on a fixed-size path (scalar, and Cholesky) is reported,
// not used.
TEST(KalmanFilter, FixedSizePathReportsANonPositiveInnovationCovariance) {
  for (const auto& [n, m] : {std::pair{6, 1}, std::pair{6, 2}, std::pair{7, 1}, std::pair{10, 2}}) {
    pe::KalmanFilter kf(n);
    kf.Reset(Eigen::VectorXd::Ones(n), Eigen::MatrixXd::Zero(n, n));
    Eigen::MatrixXd c = Eigen::MatrixXd::Zero(m, n);
    for (int i = 0; i < m; ++i) c(i, i) = 1.0;
    const auto& rep =
        kf.Update(c, Eigen::VectorXd::Constant(m, 3.0), -1.0 * Eigen::MatrixXd::Identity(m, m));
    EXPECT_FALSE(rep.ok) << n;
    EXPECT_EQ(kf.State(), Eigen::VectorXd::Ones(n)) << n;
  }
}

// The dynamic-size path skips the zero coefficients of A_D and C. With the disturbance-state
// filter's structure (a dense block of node temperatures, states that are constants or
// first-order processes, heat states driving the nodes, measurement rows that read a few states)
// both covariance forms must equal the equations written out in dense Eigen.
TEST(KalmanFilter, DynamicPathWithSparseMatricesMatchesTheEquationsWrittenOut) {
  // 10 has a fixed-size path (the diagonal-Sp overload forms a dense Sp for it); 12 to 16 take
  // the block paths with their column length known at compile time, 18 at run time.
  for (const int n : {10, 12, 14, 16, 18}) {
    for (const auto form : {pe::CovarianceUpdate::kJoseph, pe::CovarianceUpdate::kTextbook}) {
      const int nodes = 5, m = 3;
      std::mt19937_64 rng(29 + static_cast<unsigned>(n));
      std::normal_distribution<double> nd;
      Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n, n), c = Eigen::MatrixXd::Zero(m, n);
      for (int i = 0; i < nodes; ++i) {
        for (int j = 0; j < nodes; ++j) a(i, j) = 0.05 * nd(rng) + (i == j ? 0.9 : 0.0);
        for (int j = nodes; j < nodes + 4; ++j) a(i, j) = 0.01 * nd(rng);  // heat states
      }
      for (int i = nodes; i < n; ++i) a(i, i) = i % 2 == 0 ? 1.0 : 0.99;
      c(0, 0) = 1.0;
      c(0, n - 1) = 1.0;  // a sensor and its offset
      for (const int j : {1, 2, nodes + 1, n - 3, n - 2}) c(1, j) = nd(rng);  // a voltage row
      c(2, 3) = 1.0;
      Eigen::MatrixXd l(n, n);
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) l(i, j) = nd(rng);
      Eigen::MatrixXd s = l * l.transpose() + Eigen::MatrixXd::Identity(n, n);
      const Eigen::MatrixXd q = 0.02 * Eigen::MatrixXd::Identity(n, n);
      Eigen::MatrixXd r = 0.4 * Eigen::MatrixXd::Identity(m, m);
      r(0, 1) = r(1, 0) = 0.1;
      Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
      pe::KalmanFilter kf(n), kf_diagonal(n);
      kf.Reset(x, s);
      kf_diagonal.Reset(x, s);
      const std::string what = "n=" + std::to_string(n) +
                               (form == pe::CovarianceUpdate::kJoseph ? " Joseph" : " textbook");
      for (int k = 0; k < 30; ++k) {
        Eigen::VectorXd u(n), y(m);
        for (int i = 0; i < n; ++i) u(i) = 0.1 * nd(rng);
        for (int i = 0; i < m; ++i) y(i) = nd(rng);
        x = a * x + u;
        s = a * s * a.transpose() + q;
        const Eigen::MatrixXd sy = c * s * c.transpose() + r;
        const Eigen::MatrixXd gain = s * c.transpose() * sy.inverse();
        const Eigen::VectorXd nu = y - c * x;
        x += gain * nu;
        const Eigen::MatrixXd ikc = Eigen::MatrixXd::Identity(n, n) - gain * c;
        s = form == pe::CovarianceUpdate::kJoseph
                ? Eigen::MatrixXd(ikc * s * ikc.transpose() + gain * r * gain.transpose())
                : Eigen::MatrixXd(ikc * s);
        s = 0.5 * (s + s.transpose()).eval();
        kf.Predict(a, u, q);
        // The same with Sp as its diagonal and the coupled rows (the nodes') declared.
        kf_diagonal.Predict(a, u, Eigen::VectorXd(q.diagonal()), nodes);
        ASSERT_TRUE(kf_diagonal.Update(c, y, r, form).ok) << what;
        const pe::KalmanUpdateReport& rep = kf.Update(c, y, r, form);
        ASSERT_TRUE(rep.ok) << what;
        EXPECT_NEAR(rep.nis, nu.dot(sy.inverse() * nu), 1e-9 * (1 + rep.nis)) << what;
        EXPECT_LT((kf.Gain() - gain).cwiseAbs().maxCoeff(), 1e-10) << what;
      }
      EXPECT_LT((kf.State() - x).cwiseAbs().maxCoeff(), 1e-9) << what;
      EXPECT_LT((kf_diagonal.State() - kf.State()).cwiseAbs().maxCoeff(), 1e-12) << what;
      EXPECT_LT((kf_diagonal.Covariance() - kf.Covariance()).cwiseAbs().maxCoeff(),
                1e-12 * s.cwiseAbs().maxCoeff())
          << what;
      EXPECT_LT((kf.Covariance() - s).cwiseAbs().maxCoeff(), 1e-9 * s.cwiseAbs().maxCoeff())
          << what;
      if (form == pe::CovarianceUpdate::kJoseph) {
        EXPECT_EQ((kf.Covariance() - kf.Covariance().transpose()).cwiseAbs().maxCoeff(), 0.0)
            << what;
      }
    }
  }
}
