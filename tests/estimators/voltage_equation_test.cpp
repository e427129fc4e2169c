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

pe::DriveAverages Steady(int samples, double iq_change_sd_A) {
  pe::DriveAverages d;
  d.samples = samples;
  d.id_A = 0.0;
  d.iq_A = 2.0;
  d.ud_V = -1.0;
  d.uq_V = 24.0;
  d.w_rad_per_s = 2000.0;
  d.iq_change_sd_A = iq_change_sd_A;
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

TEST(VoltageReading, CalibratedMagnetSolvesTheEquationAtTheHeldCalibration) {
  // A voltage made by the equation at a known winding, magnet and calibration: with the frame
  // failed the reading is no row, but solved at that calibration it gives the magnet back.
  const pe::VoltageLaw law = pe::VoltageLawOf(Motor());
  pe::QAxisState truth;
  truth.winding_degC = 95.0;
  truth.magnet_degC = 72.0;
  truth.dr = 0.02;
  truth.dpsi = -0.016;
  truth.u0_V = 0.04;
  pe::DriveAverages d = Steady(100, 0.01);
  const pe::QAxisPoint p{d.iq_A, d.w_rad_per_s};
  d.uq_V = pe::QAxisVoltage_V(law, p, truth) +
           pe::QAxisKnownTerms_V(Motor(), d.id_A, d.iq_A, d.w_rad_per_s);
  pe::VoltageReading reading(Motor(), pe::VoltageReadingConfig{});
  reading.Prepare(d, true);
  ASSERT_FALSE(reading.Offered());
  pe::ThermalObserver::Calibration c;
  c.dr = truth.dr;
  c.dpsi = truth.dpsi;
  c.dbeta = 0.0;
  c.u0_V = truth.u0_V;
  c.dr_sd = c.dpsi_sd = c.dbeta_sd = c.u0_sd_V = 0.0;
  const pe::VoltageMagnet m = reading.CalibratedMagnet(c, truth.winding_degC);
  ASSERT_TRUE(m.Valid());
  EXPECT_NEAR(m.z_degC - m.winding_gain * truth.winding_degC, truth.magnet_degC, 1e-6);
  // Only the voltage's noise is left: 1 mV over a slope of w psi0 beta.
  const double slope = std::abs(pe::QAxisGradientAt(law, p, truth).magnet_V_per_K);
  EXPECT_NEAR(m.sd_K, pe::VoltageReadingConfig{}.uq_noise_V / 10.0 / slope, 1e-9);
  // The nameplate instead (the identifier's line takes it) is off by the flux's 1.6 %: about
  // 16 K at 0.1 %/K. An sd of psi0 of that size says so.
  pe::ThermalObserver::Calibration nameplate;
  nameplate.dr = nameplate.dpsi = nameplate.dbeta = nameplate.u0_V = 0.0;
  const pe::VoltageMagnet n = reading.CalibratedMagnet(nameplate, truth.winding_degC);
  EXPECT_GT(std::abs(n.z_degC - n.winding_gain * truth.winding_degC - truth.magnet_degC), 10.0);
  c.dpsi_sd = 0.016;
  const pe::VoltageMagnet wide = reading.CalibratedMagnet(c, truth.winding_degC);
  EXPECT_GT(wide.sd_K, 10.0);
  EXPECT_LT(wide.sd_K, 25.0);
}

TEST(VoltageReading, CalibratedMagnetNeedsAVoltageAndACalibration) {
  pe::VoltageReading reading(Motor(), pe::VoltageReadingConfig{});
  pe::ThermalObserver::Calibration c;  // NaN: an observer without the voltage's states
  reading.Prepare(Steady(100, 0.01), true);
  EXPECT_FALSE(reading.CalibratedMagnet(c, 80.0).Valid());
  c.dr = c.dpsi = c.dbeta = c.u0_V = 0.0;
  EXPECT_TRUE(reading.CalibratedMagnet(c, 80.0).Valid());
  reading.Prepare(Steady(100, 0.5), true);  // a load change: the steady equation does not hold
  EXPECT_FALSE(reading.CalibratedMagnet(c, 80.0).Valid());
}

}  // namespace
