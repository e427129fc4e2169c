#include "estimators/resistance_rls.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace pumptherm::estimators {
namespace {

constexpr double kRs_ohm = 0.28;  // Han 2019 Table 1
constexpr double kPsi_Wb = 0.0182;

struct Sample {
  Eigen::Vector2d phi;
  double y;
};

// Excited, noise-free q-axis data: iq and w_r vary independently.
std::vector<Sample> NoiseFree(int n) {
  std::vector<Sample> out;
  for (int k = 0; k < n; ++k) {
    const double iq = 2.0 + 1.5 * std::sin(0.05 * k);
    const double w = 1000.0 + 800.0 * std::cos(0.013 * k);
    out.push_back({Eigen::Vector2d(iq, w), kRs_ohm * iq + kPsi_Wb * w});
  }
  return out;
}

TEST(Han2019Weight, FourLevelsOfEq23) {
  EXPECT_EQ(Han2019Weight(0.2, 10.0), 0.0);    // |eps| >= 1e-2 |y|
  EXPECT_EQ(Han2019Weight(0.1, 10.0), 0.0);    // boundary belongs to "untrusted"
  EXPECT_EQ(Han2019Weight(0.05, 10.0), 0.1);   // 1e-4 |y| <= |eps| < 1e-2 |y|
  EXPECT_EQ(Han2019Weight(-5e-4, 10.0), 0.5);  // 1e-5 |y| <= |eps| < 1e-4 |y|
  EXPECT_EQ(Han2019Weight(5e-5, 10.0), 1.0);   // |eps| < 1e-5 |y|
  EXPECT_EQ(Han2019Weight(std::numeric_limits<double>::quiet_NaN(), 10.0), 0.0);
}

// Noise-free data: every variant identifies Rs and psi_f to 1e-9 relative.
TEST(DiscountedRls, NoiseFreeDataGiveTrueParameters) {
  const auto data = NoiseFree(4000);
  struct Case {
    const char* name;
    RlsConfig config;
    Eigen::Vector2d theta0;
  };
  const Case cases[] = {
      {"plain", RlsConfig::Plain(), Eigen::Vector2d(0.1, 0.01)},
      {"forgetting", RlsConfig::Forgetting(0.9995), Eigen::Vector2d(0.1, 0.01)},
      // eq. 23 rejects everything 1 % or more off, so DFRLS starts near the nameplate.
      {"dfrls", RlsConfig::Dfrls(0.9995), Eigen::Vector2d(0.283, 0.01815)},
  };
  for (const auto& c : cases) {
    DiscountedRls rls(c.config, c.theta0, 1e6);
    for (const auto& s : data) rls.Update(s.phi, s.y);
    EXPECT_NEAR(rls.theta()(kThetaResistance), kRs_ohm, 1e-9 * kRs_ohm) << c.name;
    EXPECT_NEAR(rls.theta()(kThetaFlux), kPsi_Wb, 1e-9 * kPsi_Wb) << c.name;
  }
}

// Oracle: the recursion of eq. 21 equals the batch weighted least squares of eq. 17 with the
// discount factors Gamma(k, i) = Lambda(i) lambda^(k - i) of eq. 15, including the prior term
// lambda^k P(0)^-1 (P(k)^-1 = lambda P(k-1)^-1 + Lambda(k) phi phi^T, eq. 18). Rejected samples
// (Lambda = 0) do not age the history (our decision): lambda's exponent counts accepted samples.
TEST(DiscountedRls, RecursiveEqualsBatchWeightedLeastSquares) {
  std::mt19937_64 rng(42);
  std::normal_distribution<double> noise(0.0, 1.0);
  const double lambda = 0.999;
  const Eigen::Vector2d theta0(0.27, 0.01815);  // within eq. 23's 1 % of y
  const double p0 = 10.0;
  DiscountedRls rls(RlsConfig::Dfrls(lambda), theta0, p0);
  std::vector<Sample> data;
  std::vector<double> weights;
  for (int k = 0; k < 3000; ++k) {
    const double iq = 2.0 + 1.0 * std::sin(0.01 * k) + 0.01 * noise(rng);
    const double w = 2000.0 + 100.0 * std::sin(0.003 * k);
    // Noise of 0.5 % of y with outliers, so that every weight level occurs.
    double y = kRs_ohm * iq + kPsi_Wb * w + 2e-3 * noise(rng);
    if (k % 97 == 0) y += 1.0;
    data.push_back({Eigen::Vector2d(iq, w), y});
    weights.push_back(rls.Update(data.back().phi, y).weight);
  }
  int levels[4] = {0, 0, 0, 0};
  for (double g : weights) levels[g == 0.0 ? 0 : g == 0.1 ? 1 : g == 0.5 ? 2 : 3]++;
  EXPECT_GT(levels[0], 0);
  EXPECT_GT(levels[1], 0);
  EXPECT_GT(levels[2], 0);
  EXPECT_GT(levels[3], 0);

  Eigen::Matrix2d info = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
  int accepted_after = 0;
  for (int i = static_cast<int>(data.size()) - 1; i >= 0; --i) {
    if (weights[i] == 0.0) continue;
    const double gamma = weights[i] * std::pow(lambda, accepted_after);
    info += gamma * data[i].phi * data[i].phi.transpose();
    rhs += gamma * data[i].phi * data[i].y;
    ++accepted_after;
  }
  const double prior = std::pow(lambda, accepted_after) / p0;
  info += prior * Eigen::Matrix2d::Identity();
  rhs += prior * theta0;
  const Eigen::Vector2d batch = info.ldlt().solve(rhs);
  EXPECT_NEAR(rls.theta()(0), batch(0), 1e-9 * std::abs(batch(0)));
  EXPECT_NEAR(rls.theta()(1), batch(1), 1e-9 * std::abs(batch(1)));
  const Eigen::Matrix2d p_batch = info.inverse();
  EXPECT_NEAR(rls.covariance()(0, 0), p_batch(0, 0), 1e-7 * p_batch(0, 0));
  EXPECT_NEAR(rls.covariance()(1, 1), p_batch(1, 1), 1e-7 * p_batch(1, 1));
}

// Lambda = 0 (and non-finite input) changes nothing: no covariance windup.
TEST(DiscountedRls, RejectedSampleLeavesStateUnchanged) {
  DiscountedRls rls(RlsConfig::Dfrls(0.9995), Eigen::Vector2d(0.28, 0.0182), 1.0);
  for (const auto& s : NoiseFree(100)) rls.Update(s.phi, s.y);
  const RlsState before = rls.Save();
  for (int k = 0; k < 10000; ++k) {
    const RlsStep step = rls.Update(Eigen::Vector2d(2.0, 2000.0), 100.0);  // 2.7x too high
    ASSERT_EQ(step.weight, 0.0);
  }
  rls.Update(Eigen::Vector2d(std::numeric_limits<double>::quiet_NaN(), 2000.0), 36.96);
  EXPECT_EQ(rls.theta(), before.theta);
  EXPECT_EQ(rls.covariance(), before.p);
  EXPECT_EQ(rls.Save().rejected, before.rejected + 10001);
}

// What eq. 21 would do instead: with Lambda -> 0 the gain vanishes but P is still divided by
// lambda on each sample; shown with the forgetting variant fed an unexciting regressor.
TEST(DiscountedRls, ForgettingWithoutExcitationWindsUp) {
  DiscountedRls rls(RlsConfig::Forgetting(0.9995), Eigen::Vector2d(0.28, 0.0182), 1.0);
  for (const auto& s : NoiseFree(2000)) rls.Update(s.phi, s.y);
  const double before = rls.covariance().trace();
  for (int k = 0; k < 20000; ++k)
    rls.Update(Eigen::Vector2d(2.0, 2000.0), 0.28 * 2 + 0.0182 * 2000);
  EXPECT_GT(rls.covariance().trace(), 100.0 * before);  // the direction without data grows
}

TEST(DiscountedRls, SaveRestoreRoundTrip) {
  const auto data = NoiseFree(600);
  DiscountedRls a(RlsConfig::Dfrls(), Eigen::Vector2d(0.281, 0.01819), 1.0);
  DiscountedRls b(RlsConfig::Dfrls(), Eigen::Vector2d(0.0, 0.0), 5.0);
  for (int k = 0; k < 300; ++k) a.Update(data[k].phi, data[k].y);
  b.Restore(a.Save());
  for (int k = 300; k < 600; ++k) {
    a.Update(data[k].phi, data[k].y);
    b.Update(data[k].phi, data[k].y);
  }
  EXPECT_EQ(a.theta(), b.theta());
  EXPECT_EQ(a.covariance(), b.covariance());
}

}  // namespace
}  // namespace pumptherm::estimators
