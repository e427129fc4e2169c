#include "estimators/copper.hpp"

#include <gtest/gtest.h>

namespace pumptherm::estimators {
namespace {

// Han 2019 eq. 2 by hand: 0.28 ohm at 20 degC, alpha 4.1e-3: at 70 degC 0.28 * 1.205 = 0.3374.
TEST(Copper, ResistanceAtMatchesHandComputation) {
  const CopperLaw law{0.28, 20.0, kAlphaCuHan2019_per_K};
  EXPECT_NEAR(ResistanceAt(law, 70.0), 0.3374, 1e-12);
  EXPECT_NEAR(ResistanceAt(law, 20.0), 0.28, 1e-15);
}

TEST(Copper, TemperatureAtInvertsResistanceAt) {
  const CopperLaw law{0.022, 25.0, kAlphaCuSaheba2010_per_K};
  for (double t = -40.0; t <= 200.0; t += 7.5) {
    EXPECT_NEAR(TemperatureAt(law, ResistanceAt(law, t)), t, 1e-9) << "t=" << t;
  }
}

}  // namespace
}  // namespace pumptherm::estimators
