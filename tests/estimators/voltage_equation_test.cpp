// The q-axis voltage equation (Han et al. 2019 eq. 6 with the copper and magnet laws) against a
// hand computation and its gradient against finite differences; the voltage reading's gates.
#include "estimators/voltage_equation.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "estimators/readings/voltage_reading.hpp"

namespace pe = pumptherm::estimators;

namespace {

const pe::MotorDescription& Motor() {
  static const pe::MotorDescription motor = pe::MotorPreset("han2019-tmp");
  return motor;
}

TEST(VoltageEquation, MatchesTheLawsByHand) {
  const pe::VoltageLaw law = pe::VoltageLawOf(Motor());
  ASSERT_GT(law.r0_ohm, 0.0);
  ASSERT_LT(law.beta_per_K, 0.0) << "the shipped motor states its magnet law";
  const pe::QAxisPoint p{2.5, 2000.0};
  pe::QAxisState s;
  s.winding_degC = 80.0;
  s.magnet_degC = 60.0;
  s.dr = 0.02;
  s.dpsi = -0.01;
  s.u0_V = 0.05;
  const double r = law.r0_ohm * 1.02 * (1.0 + law.alpha_per_K * (80.0 - law.t0_degC));
  const double psi = law.psi0_Wb * 0.99 * (1.0 + law.beta_per_K * (60.0 - law.magnet_t0_degC));
  EXPECT_NEAR(pe::QAxisVoltage_V(law, p, s), r * 2.5 + 2000.0 * psi + 0.05, 1e-12);
  // The offset takes the sign of iq (dead time opposes the current).
  const pe::QAxisPoint braking{-2.5, 2000.0};
  EXPECT_NEAR(pe::QAxisVoltage_V(law, braking, s), -r * 2.5 + 2000.0 * psi - 0.05, 1e-12);
}

TEST(VoltageEquation, GradientMatchesFiniteDifferences) {
  const pe::VoltageLaw law = pe::VoltageLawOf(Motor());
  const pe::QAxisPoint p{3.0, 1800.0};
  pe::QAxisState s;
  s.winding_degC = 95.0;
  s.magnet_degC = 70.0;
  s.dr = -0.01;
  s.dpsi = 0.015;
  s.dbeta = -0.2;
  s.u0_V = 0.1;
  const pe::QAxisGradient g = pe::QAxisGradientAt(law, p, s);
  auto diff = [&](auto member, double h) {
    pe::QAxisState up = s, down = s;
    up.*member += h;
    down.*member -= h;
    return (pe::QAxisVoltage_V(law, p, up) - pe::QAxisVoltage_V(law, p, down)) / (2.0 * h);
  };
  EXPECT_NEAR(g.winding_V_per_K, diff(&pe::QAxisState::winding_degC, 1e-3), 1e-9);
  EXPECT_NEAR(g.magnet_V_per_K, diff(&pe::QAxisState::magnet_degC, 1e-3), 1e-9);
  EXPECT_NEAR(g.dr_V, diff(&pe::QAxisState::dr, 1e-6), 1e-7);
  EXPECT_NEAR(g.dpsi_V, diff(&pe::QAxisState::dpsi, 1e-6), 1e-7);
  EXPECT_NEAR(g.dbeta_V, diff(&pe::QAxisState::dbeta, 1e-6), 1e-7);
  EXPECT_NEAR(g.u0, diff(&pe::QAxisState::u0_V, 1e-4), 1e-7);
  // At rated speed a kelvin of magnet moves uq far more than a kelvin of winding (Han 2019):
  // what the identifier alone cannot separate.
  EXPECT_GT(std::abs(g.magnet_V_per_K), 5.0 * std::abs(g.winding_V_per_K));
}

pe::DriveAverages Steady(int samples, double iq_sd_A) {
  pe::DriveAverages d;
  d.samples = samples;
  d.id_A = 0.0;
  d.iq_A = 2.0;
  d.ud_V = -1.0;
  d.uq_V = 24.0;
  d.w_rad_per_s = 2000.0;
  d.iq_sd_A = iq_sd_A;
  return d;
}

TEST(VoltageReading, OffersTheVoltageLessItsKnownTerms) {
  pe::VoltageReading reading(Motor(), pe::VoltageReadingConfig{});
  reading.Prepare(Steady(100, 0.01), false);
  ASSERT_TRUE(reading.Offered());
  pe::ThermalReadings r;
  reading.Offer(r);
  EXPECT_NEAR(r.uq_V, 24.0 - pe::QAxisKnownTerms_V(Motor(), 0.0, 2.0, 2000.0), 1e-12);
  EXPECT_NEAR(r.uq_sd_V, pe::VoltageReadingConfig{}.uq_noise_V / 10.0, 1e-12);
  EXPECT_EQ(r.iq_A, 2.0);
  EXPECT_EQ(r.w_rad_per_s, 2000.0);
}

TEST(VoltageReading, LeavesOutWhatTheSteadyEquationDoesNotDescribe) {
  pe::VoltageReading reading(Motor(), pe::VoltageReadingConfig{});
  reading.Prepare(Steady(0, 0.0), false);
  EXPECT_EQ(reading.status().state, pe::ReadingState::kAbsent);
  reading.Prepare(Steady(5, 0.0), false);
  EXPECT_EQ(reading.status().state, pe::ReadingState::kStale);
  reading.Prepare(Steady(100, 0.5), false);  // a load change inside the period
  EXPECT_EQ(reading.status().state, pe::ReadingState::kGated);
  reading.Prepare(Steady(100, 0.01), true);  // no frame level to anchor it
  EXPECT_EQ(reading.status().state, pe::ReadingState::kSensorFault);
  EXPECT_FALSE(reading.Offered());
  pe::ThermalReadings r;
  reading.Offer(r);
  EXPECT_TRUE(std::isnan(r.uq_V));
}

}  // namespace
