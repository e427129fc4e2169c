#include "estimators/quantisation.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>

namespace pumptherm::estimators {
namespace {

// The simulated drive's uq chain: 12 bits over +/-48 V (23.4 mV) with 10 mV of jitter.
constexpr double kStep_V = 96.0 / 4096.0;

double Quantise(double x, double step) { return step * std::round(x / step); }

struct MonteCarlo {
  double mean = 0.0;      // of the quantised samples
  double variance = 0.0;  // unbiased
  double standard_error = 0.0;
};

MonteCarlo MonteCarloSample(double mu, double sigma, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  double sum = 0.0, sum2 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double q = Quantise(mu + noise(rng), kStep_V) - mu;
    sum += q;
    sum2 += q * q;
  }
  MonteCarlo m;
  m.mean = mu + sum / n;
  m.variance = (sum2 - sum * sum / n) / (n - 1);
  m.standard_error = std::sqrt(m.variance / n);
  return m;
}

// The closed form (Widrow & Kollar 2008; derivation in quantisation.hpp) against a Monte Carlo
// of the quantiser, 2e6 samples per point: within 5 standard errors (~4e-5 V) at noise levels of
// 0.3, 0.43 and 0.6 steps and means at several places between two codes near 40 V.
TEST(Quantisation, MeanBiasMatchesMonteCarlo) {
  std::uint64_t seed = 1;
  for (const double sigma_steps : {0.3, 10.0 / 23.4375, 0.6}) {
    const double sigma = sigma_steps * kStep_V;
    for (const double phase : {0.1, 0.25, 0.4, 0.5, 0.7, 0.9}) {
      const double mu = (1707.0 + phase) * kStep_V;  // 40.0 V + phase steps
      const MonteCarlo mc = MonteCarloSample(mu, sigma, 2'000'000, seed++);
      const double predicted = QuantisedMeanBias(mu, sigma * sigma, kStep_V);
      EXPECT_NEAR(mc.mean - mu, predicted, 5.0 * mc.standard_error)
          << "sigma " << sigma_steps << " steps, phase " << phase;
    }
  }
  // The size the docs quote: about step/pi exp(-2 pi^2 sigma^2/step^2) = 0.2 mV at 10 mV noise.
  const double amplitude = QuantisedMeanBias((1707.0 + 0.75) * kStep_V, 1e-4, kStep_V);
  EXPECT_NEAR(std::abs(amplitude),
              kStep_V / std::numbers::pi *
                  std::exp(-2.0 * std::numbers::pi * std::numbers::pi * 1e-4 / (kStep_V * kStep_V)),
              1e-7);
  EXPECT_GT(std::abs(amplitude), 1.5e-4);
  EXPECT_LT(std::abs(amplitude), 2.5e-4);
}

// Sheppard's correction: the variance of the quantised samples is sigma^2 + step^2/12, up to a
// periodic term of amplitude (4 sigma^2 + step^2/pi^2) exp(-2 pi^2 sigma^2/step^2) (13 % of
// sigma^2 at 10 mV on a 23 mV step) and minus the squared bias of the mean, which
// CorrectQuantisedMean takes into account.
TEST(Quantisation, VarianceOfQuantisedSamples) {
  std::uint64_t seed = 100;
  constexpr double kPi = std::numbers::pi;
  for (const double sigma_steps : {0.3, 10.0 / 23.4375, 0.6}) {
    const double sigma = sigma_steps * kStep_V;
    for (const double phase : {0.0, 0.25, 0.5}) {
      const double mu = (1707.0 + phase) * kStep_V;
      const MonteCarlo mc = MonteCarloSample(mu, sigma, 2'000'000, seed++);
      const double periodic = -(4.0 * sigma * sigma + kStep_V * kStep_V / (kPi * kPi)) *
                              std::exp(-2.0 * kPi * kPi * sigma * sigma / (kStep_V * kStep_V)) *
                              std::cos(2.0 * kPi * phase);
      const double bias = QuantisedMeanBias(mu, sigma * sigma, kStep_V);
      // Monte Carlo error of a variance: sqrt(2/n) of it, 1e-3 relative here.
      EXPECT_NEAR(mc.variance, sigma * sigma + kStep_V * kStep_V / 12.0 + periodic - bias * bias,
                  0.01 * sigma * sigma)
          << "sigma " << sigma_steps << " steps, phase " << phase;
    }
  }
}

// The identifier's use: blocks of 100 samples, noise from each block's own variance. Averaged
// over 20000 blocks the corrected means keep at most 20 % of the bias (plus the Monte Carlo
// error) at the simulated drive's 10 mV on a 23 mV step; the uncorrected ones keep all of it.
TEST(Quantisation, CorrectedBlockMeansLoseTheBias) {
  const double sigma = 0.010;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise(0.0, sigma);
  for (const double phase : {0.2, 0.3, 0.7, 0.8}) {
    const double mu = (1707.0 + phase) * kStep_V;
    const double bias = QuantisedMeanBias(mu, sigma * sigma, kStep_V);
    const int blocks = 20000;
    double raw = 0.0, corrected = 0.0;
    for (int b = 0; b < blocks; ++b) {
      double sum = 0.0, sum2 = 0.0;
      for (int i = 0; i < 100; ++i) {
        const double q = Quantise(mu + noise(rng), kStep_V) - mu;
        sum += q;
        sum2 += q * q;
      }
      const double mean = mu + sum / 100.0;
      const double var = (sum2 - sum * sum / 100.0) / 99.0;
      raw += mean - mu;
      corrected += CorrectQuantisedMean(mean, var, 100, kStep_V) - mu;
    }
    raw /= blocks;
    corrected /= blocks;
    const double standard_error =
        std::sqrt((sigma * sigma + kStep_V * kStep_V / 12.0) / (100.0 * blocks));
    EXPECT_NEAR(raw, bias, 5.0 * standard_error) << "phase " << phase;
    EXPECT_LT(std::abs(corrected), 0.2 * std::abs(bias) + 5.0 * standard_error)
        << "phase " << phase << ": raw " << raw << " V, corrected " << corrected << " V";
  }
}

TEST(Quantisation, NoCorrectionWhereItIsNotDefined) {
  const double mean = 40.0123;
  EXPECT_EQ(CorrectQuantisedMean(mean, 1e-4, 100, 0.0), mean);    // step unknown
  EXPECT_EQ(CorrectQuantisedMean(mean, 1e-4, 1, kStep_V), mean);  // no variance from one sample
  // Noise below 0.3 step: not corrected.
  const double small = std::pow(0.25 * kStep_V, 2) + kStep_V * kStep_V / 12.0;
  EXPECT_EQ(CorrectQuantisedMean(mean, small, 100, kStep_V), mean);
  EXPECT_EQ(CorrectQuantisedMean(mean, std::numeric_limits<double>::quiet_NaN(), 100, kStep_V),
            mean);
  EXPECT_EQ(QuantisedMeanBias(mean, 1e-4, 0.0), 0.0);
  EXPECT_EQ(QuantisedMeanBias(std::numeric_limits<double>::infinity(), 1e-4, kStep_V), 0.0);
  // At a code and half-way between two codes the bias is zero by symmetry.
  EXPECT_NEAR(QuantisedMeanBias(1707.0 * kStep_V, 1e-4, kStep_V), 0.0, 1e-12);
  EXPECT_NEAR(QuantisedMeanBias(1707.5 * kStep_V, 1e-4, kStep_V), 0.0, 1e-12);
}

}  // namespace
}  // namespace pumptherm::estimators
