#include "tools/sim/sensor.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace pumptherm::sim {
namespace {

TEST(Sensor, QuantiseRoundsAndClamps) {
  EXPECT_DOUBLE_EQ(Quantise(0.26, 0.1, -1.0, 1.0), 0.3);
  EXPECT_DOUBLE_EQ(Quantise(5.0, 0.1, -1.0, 1.0), 1.0);
  EXPECT_DOUBLE_EQ(Quantise(0.123, 0.0, -1.0, 1.0), 0.123);
}

TEST(Sensor, QuantiseToADecimalStepGivesTheDecimalsDouble) {
  // 217 * 0.1 is 21.700000000000003 in binary; the reading 21.7 is the double nearest 21.7, so a
  // CSV writer printing the shortest round-trip form writes "21.7".
  EXPECT_EQ(Quantise(21.68, 0.1, -50.0, 200.0), 21.7);
  EXPECT_EQ(Quantise(22.21, 0.1, -50.0, 200.0), 22.2);
  EXPECT_EQ(Quantise(21.9049, 0.01, -50.0, 200.0), 21.9);
  // A binary step stays exact as before.
  EXPECT_EQ(Quantise(2.99, 0.01953125, -100.0, 100.0), 2.98828125);
}

// A first-order lag driven by a step reaches 1 - e^-1 of the step after one time constant.
TEST(Sensor, LagFollowsFirstOrderStepResponse) {
  Sensor s({.lag_tau_s = 30.0}, 1);
  s.Measure(20.0, 0.0);
  double y = 0.0;
  for (int k = 0; k < 300; ++k) y = s.Measure(30.0, 0.1);
  EXPECT_NEAR(y, 20.0 + 10.0 * (1.0 - std::exp(-1.0)), 1e-9);
}

TEST(Sensor, NoiseHasTheConfiguredSpreadAndIsRepeatable) {
  Sensor a({.noise_sd = 0.5}, 42);
  Sensor b({.noise_sd = 0.5}, 42);
  double sum = 0.0;
  double sum2 = 0.0;
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    const double y = a.Measure(1.0, 0.01);
    EXPECT_EQ(y, b.Measure(1.0, 0.01));
    sum += y - 1.0;
    sum2 += (y - 1.0) * (y - 1.0);
  }
  EXPECT_NEAR(sum / n, 0.0, 0.02);
  EXPECT_NEAR(std::sqrt(sum2 / n), 0.5, 0.02);
}

}  // namespace
}  // namespace pumptherm::sim
