#include "estimators/resistance_equation.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace pumptherm::estimators {
namespace {

// Two exact points of uq = Rs iq + w_r psi_f (Han 2019 eq. 7) give Rs and psi_f (eq. 8).
TEST(TwoPoint, NoiseFreePointsGiveTrueParameters) {
  const double rs = 0.28, psi = 0.0182;
  const QAxisPoint accel{8.0, rs * 8.0 + 1100.0 * psi, 1100.0};
  const QAxisPoint steady{2.0, rs * 2.0 + 2199.1 * psi, 2199.1};
  const TwoPointResult r = IdentifyTwoPoint(accel, steady);
  ASSERT_TRUE(r.valid);
  EXPECT_NEAR(r.resistance_ohm, rs, 1e-9 * rs);
  EXPECT_NEAR(r.flux_Wb, psi, 1e-9 * psi);
}

// Proportional points (iq / w_r equal) carry no independent information.
TEST(TwoPoint, DependentPointsAreInvalid) {
  const QAxisPoint p1{1.0, 10.0, 1000.0};
  const QAxisPoint p2{2.0, 20.0, 2000.0};
  const TwoPointResult r = IdentifyTwoPoint(p1, p2);
  EXPECT_FALSE(r.valid);
  EXPECT_TRUE(std::isnan(r.resistance_ohm));
  EXPECT_FALSE(IdentifyTwoPoint(p1, {2.0, 1.0, 0.0}).valid);  // w_r2 = 0
}

}  // namespace
}  // namespace pumptherm::estimators
