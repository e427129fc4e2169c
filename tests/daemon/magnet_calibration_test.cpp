// The magnet from the flux is only as good as this pump's psi0 (docs/virtual-sensor.md, "The
// magnet before psi0 is learnt"): a pump started warm publishes no magnet from the flux and a
// magnet node no narrower than the nameplate's flux tolerance; a cold start learns psi0, and the
// calibration stays learnt across a saved state.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/pump.hpp"
#include "estimators/model_effects.hpp"
#include "estimators/voltage_equation.hpp"
#include "tests/common/test_files.hpp"

namespace pd = pumptherm::daemon;
namespace pe = pumptherm::estimators;

namespace {

/// tmp-generic, with `effects` (estimators/model_effects.hpp) for a plant that differs from it.
std::shared_ptr<const pe::ThermalModel> TmpGeneric(const std::vector<pe::Effect>& effects = {}) {
  const std::string path = pumptherm::test_files::ModelPath("tmp-generic");
  const std::string dir = pumptherm::test_files::DirectoryOf(path);
  std::string text = pumptherm::test_files::ReadFile(path);
  if (!effects.empty()) text = pe::ApplyModelEffects(text, "tmp-generic", effects, dir);
  return std::make_shared<const pe::ThermalModel>(pe::ThermalModel::Parse(
      text, "tmp-generic", pe::ThermalModelFiles{dir, &pumptherm::test_files::ReadFile}));
}

pd::PumpConfig Config() {
  pd::PumpConfig c;
  c.name = "p";
  c.magnet_node = "rotor";
  c.frame_sensor_lag_s = 30.0;
  c.disturbance_states = true;
  c.disturbance_states_explicit = true;
  return c;
}

class MagnetCalibration : public ::testing::Test {
 protected:
  /// One period ending at second `k` of a plant that is the model itself (its nodes integrated
  /// from `x_degC`, an ambient of 22 degC): ten paired current and voltage frames at
  /// `speed_rpm` and 3 A (or a load that steps), uq the motor's own at the plant's winding and
  /// rotor, and a status frame with the plant's frame temperature.
  void Period(pd::Pump& pump, int k, double speed_rpm) {
    pe::ThermalInputs in;
    in.speed_rpm = speed_rpm;
    const bool low = (k / 60) % 2 == 0 || k < load_steps_from_s;
    in.iq_A = k < current_from_s ? 0.0 : 3.0 + (low ? -plant_load_step_A : plant_load_step_A);
    in.ambient_degC = in.coolant_degC = 22.0;
    pe::ThermalLinearModel lin;
    for (int j = 0; j < 10; ++j) {
      plant_model_->Linearise(in, x_degC, lin);
      x_degC += 0.1 * (lin.a_per_s * x_degC + lin.f_K_per_s);
      const double extra_W = plant_rotor_heat_W + plant_rotor_heat_W_per_A * in.iq_A;
      x_degC(rotor_) += 0.1 * extra_W / plant_model_->Capacities_J_per_K()(rotor_);
    }
    const double w = pe::ElectricalSpeed_rad_per_s(motor_, speed_rpm);
    pe::QAxisState at;
    at.winding_degC = x_degC(winding_);
    at.magnet_degC = x_degC(rotor_);
    at.dpsi = plant_dpsi;
    at.dr = plant_dr;
    // The inverter's dead time: the drive reports more voltage than the motor sees, along the
    // current (realistic-signals.md).
    const double dead_time_V = plant_voltage_error_V * std::tanh(in.iq_A / 0.5);
    const std::int64_t t_us = static_cast<std::int64_t>(k) * 1'000'000;
    for (int j = 10; j > 0; --j) {
      const std::int64_t t = t_us - 20'000 - 10'000 * static_cast<std::int64_t>(j - 1);
      // The rotor's mechanical ripple is in its back-EMF, not in the drive's speed estimate.
      const double ripple_rpm =
          speed_rpm > 0.0 ? plant_ripple_rpm * std::sin(2.0 * kPi * 0.37 * 1e-6 * t) : 0.0;
      const double w_true = pe::ElectricalSpeed_rad_per_s(motor_, speed_rpm + ripple_rpm);
      const double uq_V = pe::QAxisVoltage_V(plant_law_, {in.iq_A, w_true}, at) +
                          pe::QAxisKnownTerms_V(motor_, 0.0, in.iq_A, w_true) + dead_time_V;
      // The current's noise and a step inside the period in the reported iq only: the plant
      // above runs at the period's set point.
      const double reported_iq_A = in.iq_A + plant_current_noise_A * current_noise_(random_) +
                                   (j <= 5 ? step_inside_A : 0.0);
      pump.OnCurrents(t, 0.0, reported_iq_A, w, 3.0);
      pump.OnVoltages(t + 1'000, -0.01, uq_V, 3.0);
    }
    const double frame_degC = std::isfinite(frame_stuck_degC)
                                  ? frame_stuck_degC
                                  : x_degC(frame_) + plant_frame_noise_K * current_noise_(random_);
    pump.OnStatus(t_us - 10'000, speed_rpm, 2.0, std::round(10.0 * frame_degC) / 10.0, 22.0);
    pump.Advance(t_us);
  }

  /// At rest, at the ambient, when the estimate starts (seconds 1-3): a cold start.
  void ColdStart(pd::Pump& pump) {
    for (int k = 1; k <= 3; ++k) Period(pump, k, 0.0);
  }
  /// The speed at second `k` of a run-up that starts at second `start_s` (after ColdStart: 3):
  /// at rest before it, rated two minutes later.
  static double RunUp_rpm(int k, int start_s = 3) {
    return 21000.0 * std::clamp((k - start_s) / 120.0, 0.0, 1.0);
  }

  /// How often a node's estimate lies inside its +-2 sd, and its largest error.
  struct Band {
    int judged = 0, inside = 0;
    double largest_K = 0.0;
    void Add(double error_K, double sd_K) {
      ++judged;
      inside += std::abs(error_K) <= 2.0 * sd_K;
      largest_K = std::max(largest_K, std::abs(error_K));
    }
  };

  const pe::MotorDescription motor_ = pe::MotorPreset("han2019-tmp");
  const pe::VoltageLaw law_ = pe::VoltageLawOf(motor_);
  pe::VoltageLaw plant_law_ = law_;  ///< the plant's own (its magnet's law may differ)
  const std::shared_ptr<const pe::ThermalModel> model_ = TmpGeneric();
  std::shared_ptr<const pe::ThermalModel> plant_model_ = model_;  ///< the plant's network
  const int frame_ = model_->StateIndex("frame");
  const int winding_ = model_->StateIndex("winding");
  const int rotor_ = model_->StateIndex("rotor");
  Eigen::VectorXd x_degC = Eigen::VectorXd::Constant(model_->StateCount(), 22.0);
  double plant_dpsi = 0.0;         ///< the plant's flux relative to the nameplate's psi0, minus one
  double plant_dr = 0.0;           ///< the plant's R0 relative to the nameplate's, minus one
  double plant_load_step_A = 0.0;  ///< iq is 3 A -+ this, changing every minute
  int load_steps_from_s = 0;       ///< before this second the load stays at 3 A - the step
  int current_from_s = 0;          ///< before this second no current flows (a pump at rest)
  double plant_voltage_error_V = 0.0;     ///< the reported uq less the motor's, at full current
  double plant_rotor_heat_W = 0.0;        ///< heat on the rotor the model does not have
  double plant_rotor_heat_W_per_A = 0.0;  ///< and more of it per ampere of iq
  double plant_ripple_rpm = 0.0;  ///< the rotor's speed ripple (0.37 Hz) the drive does not see
  double plant_current_noise_A = 0.0;  ///< rms noise of each reported iq sample
  double plant_frame_noise_K = 0.0;    ///< rms noise of the frame sensor's reading
  double step_inside_A = 0.0;          ///< added to the second half of each period's iq samples
  std::mt19937 random_{20261130};
  std::normal_distribution<double> current_noise_{0.0, 1.0};
  static constexpr double kPi = 3.14159265358979323846;
  /// The frame sensor's reading when it is stuck (NaN: it reads the plant's frame).
  double frame_stuck_degC = std::numeric_limits<double>::quiet_NaN();
  /// psi0's prior sd (2 %) through the motor's magnet law (-0.1 %/K).
  const double tolerance_K = 0.02 / std::abs(motor_.magnet.flux_temperature_coefficient_per_K);
};

TEST_F(MagnetCalibration, AWarmStartPublishesNoMagnetAndTheNameplatesToleranceOnTheRotor) {
  pd::Pump pump(Config(), motor_, model_, 1.0);
  x_degC.setConstant(45.0);  // warm from an earlier run, cooling towards the ambient
  for (int k = 1; k <= 300; ++k) Period(pump, k, 21000.0);
  const auto& s = pump.snapshot();
  ASSERT_TRUE(s.initialised);
  EXPECT_EQ(s.voltage_reading.state, pe::ReadingState::kFused);
  EXPECT_TRUE(std::isnan(s.magnet_flux_degC)) << s.magnet_flux_degC;
  EXPECT_GE(s.node_sd_K[static_cast<std::size_t>(rotor_)], tolerance_K - 1e-9);
  EXPECT_LT(s.node_filter_sd_K[static_cast<std::size_t>(rotor_)], 0.5 * tolerance_K)
      << "the filter's own sd is kept";
  EXPECT_LT(s.node_sd_K[static_cast<std::size_t>(winding_)], 5.0)
      << "the other nodes are not widened";
  EXPECT_EQ(s.start, pe::EstimateStart::kWarm);
  EXPECT_FALSE(s.calibrated_at_cold_start);
  EXPECT_EQ(s.starts, 1u);
}

TEST_F(MagnetCalibration, AColdStartLearnsPsi0AndTheSavedStateKeepsIt) {
  pd::Pump pump(Config(), motor_, model_, 1.0);
  ColdStart(pump);
  ASSERT_TRUE(pump.snapshot().initialised);
  for (int k = 4; k <= 300; ++k) Period(pump, k, 21000.0);
  const auto& s = pump.snapshot();
  ASSERT_TRUE(s.initialised);
  ASSERT_TRUE(std::isfinite(s.magnet_flux_degC));
  EXPECT_LT(s.node_sd_K[static_cast<std::size_t>(rotor_)], 0.5 * tolerance_K);
  EXPECT_EQ(s.start, pe::EstimateStart::kCold);
  EXPECT_TRUE(s.calibrated_at_cold_start);

  const pd::PumpSavedState saved = pump.Save();
  EXPECT_TRUE(saved.cold_started);
  pd::Pump restored(Config(), motor_, model_, 1.0);
  ASSERT_TRUE(restored.Restore(saved, saved.time_us));
  for (int k = 301; k <= 305; ++k) Period(restored, k, 21000.0);
  EXPECT_TRUE(std::isfinite(restored.snapshot().magnet_flux_degC));
  EXPECT_EQ(restored.snapshot().start, pe::EstimateStart::kRestored);
  EXPECT_TRUE(restored.snapshot().calibrated_at_cold_start);

  // The same state from a run that started warm: the calibration is the nameplate's.
  pd::PumpSavedState warm = saved;
  warm.cold_started = false;
  pd::Pump from_warm(Config(), motor_, model_, 1.0);
  ASSERT_TRUE(from_warm.Restore(warm, warm.time_us));
  for (int k = 301; k <= 305; ++k) Period(from_warm, k, 21000.0);
  EXPECT_TRUE(std::isnan(from_warm.snapshot().magnet_flux_degC));
  EXPECT_GE(from_warm.snapshot().node_sd_K[static_cast<std::size_t>(rotor_)], tolerance_K - 1e-9);
}

// Without the voltage rows the back-EMF line takes the nameplate's psi0; on a motor 1.6 % off it,
// the line is 16 K off. Started warm, that bias is unknown: no magnet from the flux, and a rotor
// whose sd covers it. Started cold, the run-up teaches the bias: the magnet is published and
// both it and the rotor cover the truth. The plant's load steps: the identifier's line follows
// the flux only with them.
// A pump stopped 20 minutes ago after an hour's run: its frame is back within 3 K of the
// ambient, its rotor (cooling slower, in vacuum) still several kelvin warmer. A daemon started
// now without a saved state takes a cold start; taken at the frame's temperature, the rotor
// taught psi0 a flux too low and the magnet read cold (on a recording so made: 7.7 K off, inside
// +-2 sd 0 % of the time, and the magnet law check blamed the motor file 14 minutes in). The
// nodes that cool slower start between the frame's temperature and the model's decay at rest.
TEST_F(MagnetCalibration, AColdStartWithTheFrameStillWarmFromARunLeavesTheRotorOpen) {
  plant_load_step_A = 0.5;
  {
    pd::Pump before(Config(), motor_, model_, 1.0);  // the run, watched by another daemon
    for (int k = 1; k <= 3600; ++k) Period(before, k, 21000.0);
    current_from_s = 1 << 30;  // then at rest, no current
    for (int k = 3601; k <= 4800; ++k) Period(before, k, 0.0);
  }
  ASSERT_GT(x_degC(frame_) - 22.0, 1.5) << "the frame still warm";
  ASSERT_LT(x_degC(frame_) - 22.0, 3.0) << "within the cold start's band";
  ASSERT_GT(x_degC(rotor_) - x_degC(frame_), 5.0) << "the rotor warmer still";
  pd::Pump pump(Config(), motor_, model_, 1.0);
  current_from_s = 4804;
  for (int k = 4801; k <= 4803; ++k) Period(pump, k, 0.0);
  EXPECT_EQ(pump.snapshot().start, pe::EstimateStart::kCold);
  EXPECT_GT(pump.snapshot().start_span_K, 5.0);
  Band rotor_band, magnet_band;
  for (int k = 4804; k <= 4803 + 1800; ++k) {
    Period(pump, k, RunUp_rpm(k, 4803));
    const auto& s = pump.snapshot();
    if (k < 4803 + 300) continue;
    rotor_band.Add(s.node_degC[static_cast<std::size_t>(rotor_)] - x_degC(rotor_),
                   s.node_sd_K[static_cast<std::size_t>(rotor_)]);
    if (std::isfinite(s.magnet_flux_degC))
      magnet_band.Add(s.magnet_flux_degC - x_degC(rotor_), s.magnet_flux_sd_K);
  }
  const auto& s = pump.snapshot();
  EXPECT_EQ(s.magnet_law_changes, 0u) << "the motor file blamed for a warm rotor";
  EXPECT_GE(rotor_band.inside, 0.9 * rotor_band.judged) << rotor_band.largest_K;
  EXPECT_LT(rotor_band.largest_K, 5.0);  // measured 3.7 K (10.7 K taken at the frame's)
  EXPECT_GE(magnet_band.judged, 0.9 * rotor_band.judged) << "the magnet from the flux published";
  EXPECT_GE(magnet_band.inside, 0.9 * magnet_band.judged) << magnet_band.largest_K;
  EXPECT_LT(s.node_sd_K[static_cast<std::size_t>(rotor_)], 6.0) << "not the nameplate's 20 K";
}

// Without the voltage rows, the same pump ten minutes after its stop: the frame more than 3 K
// above the ambient, a warm start; taken at the frame's temperature within the warm start's 5 K
// spread, the rotor (25 K warmer) was outside its +-2 sd for the whole run (on a recording so
// made: 12.6 K off, 0 %). Its sd now spans the model's decay at rest.
TEST_F(MagnetCalibration, WithoutTheVoltageAWarmStartAtRestAfterARunCoversTheRotor) {
  plant_load_step_A = 0.5;
  {
    pd::Pump before(Config(), motor_, model_, 1.0);
    for (int k = 1; k <= 3600; ++k) Period(before, k, 21000.0);
    current_from_s = 1 << 30;
    for (int k = 3601; k <= 4200; ++k) Period(before, k, 0.0);
  }
  ASSERT_GT(x_degC(frame_) - 22.0, 3.0) << "a warm start";
  ASSERT_GT(x_degC(rotor_) - x_degC(frame_), 12.0) << "the rotor far warmer";
  pd::PumpConfig config = Config();
  config.voltage_reading = false;
  pd::Pump pump(config, motor_, model_, 1.0);
  current_from_s = 4204;
  for (int k = 4201; k <= 4203; ++k) Period(pump, k, 0.0);
  EXPECT_EQ(pump.snapshot().start, pe::EstimateStart::kWarm);
  EXPECT_GT(pump.snapshot().start_span_K, 10.0);
  Band rotor_band;
  for (int k = 4204; k <= 4203 + 1800; ++k) {
    Period(pump, k, RunUp_rpm(k, 4203));
    if (k < 4203 + 300) continue;
    const auto& s = pump.snapshot();
    rotor_band.Add(s.node_degC[static_cast<std::size_t>(rotor_)] - x_degC(rotor_),
                   s.node_sd_K[static_cast<std::size_t>(rotor_)]);
  }
  EXPECT_GE(rotor_band.inside, 0.9 * rotor_band.judged) << rotor_band.largest_K;
}

TEST_F(MagnetCalibration, WithoutTheVoltageTheLinesBiasIsLearntOnlyAtAColdStart) {
  pd::PumpConfig config = Config();
  config.voltage_reading = false;
  plant_dpsi = -0.016;
  plant_load_step_A = 0.5;  // the identifier's line needs load changes to follow the flux
  const auto rotor = static_cast<std::size_t>(rotor_);
  pd::Pump warm(config, motor_, model_, 1.0);
  x_degC.setConstant(45.0);
  for (int k = 1; k <= 600; ++k) {
    Period(warm, k, 21000.0);
    const auto& s = warm.snapshot();
    if (k < 300 || !s.initialised) continue;
    ASSERT_TRUE(std::isnan(s.magnet_flux_degC)) << "t " << k << " s";
    ASSERT_LE(std::abs(s.node_degC[rotor] - x_degC(rotor_)), 2.0 * s.node_sd_K[rotor])
        << "t " << k << " s: rotor " << s.node_degC[rotor] << " sd " << s.node_sd_K[rotor]
        << " truth " << x_degC(rotor_);
  }

  x_degC.setConstant(22.0);
  pd::Pump cold(config, motor_, model_, 1.0);
  for (int k = 1; k <= 3; ++k) Period(cold, k, 0.0);
  int published = 0;
  std::array<int, pe::kReadingStateCount> states{};
  for (int k = 4; k <= 600; ++k) {
    Period(cold, k, 21000.0);
    const auto& s = cold.snapshot();
    if (k < 30) continue;
    ASSERT_TRUE(s.initialised);
    ASSERT_LE(std::abs(s.node_degC[rotor] - x_degC(rotor_)), 2.0 * s.node_sd_K[rotor])
        << "t " << k << " s: rotor " << s.node_degC[rotor] << " sd " << s.node_sd_K[rotor]
        << " truth " << x_degC(rotor_);
    ++states[static_cast<std::size_t>(s.magnet_reading.state)];
    if (std::isnan(s.magnet_flux_degC)) continue;
    ++published;
    ASSERT_LE(std::abs(s.magnet_flux_degC - x_degC(rotor_)), 2.0 * s.magnet_flux_sd_K)
        << "t " << k << " s: magnet " << s.magnet_flux_degC << " sd " << s.magnet_flux_sd_K
        << " truth " << x_degC(rotor_);
  }
  // On this noise-free plant the identifier's line is fresh in about a third of the periods
  // (stale in the rest); published in every fresh one.
  EXPECT_EQ(published, states[static_cast<std::size_t>(pe::ReadingState::kFused)]);
  EXPECT_GT(published, 100) << "the magnet from the flux, of 571 periods; line states "
                            << ::testing::PrintToString(states);
}

// The identifier's line is fitted to uq/w, so the inverter's voltage error moves it by e/w: 3.8 K
// at 21000 r/min, twice that at half the speed. A pump that waits at half speed after its cold
// start (a standby) would, taking that error as part of a constant bias, learn the bias at half
// speed and be short by the difference at full speed; the filter's state for the error, which
// enters with the line's 1/w gain, tells the two apart from the two speeds.
TEST_F(MagnetCalibration, WithoutTheVoltageTwoSpeedsTellTheInvertersErrorFromTheFluxTolerance) {
  pd::PumpConfig config = Config();
  config.voltage_reading = false;
  plant_dpsi = -0.016;
  plant_load_step_A = 0.5;
  plant_voltage_error_V = 0.15;
  const auto rotor = static_cast<std::size_t>(rotor_);
  pd::Pump cold(config, motor_, model_, 1.0);
  for (int k = 1; k <= 3; ++k) Period(cold, k, 0.0);
  auto speed_rpm = [](int k) {  // 1 min up to half speed, 4 min there, 1 min up to full speed
    if (k < 60) return 10500.0 * k / 60.0;
    if (k < 300) return 10500.0;
    return std::min(10500.0 * (1.0 + (k - 300) / 60.0), 21000.0);
  };
  double largest_K = 0.0;
  int published = 0;
  for (int k = 4; k <= 1200; ++k) {
    Period(cold, k, speed_rpm(k));
    const auto& s = cold.snapshot();
    if (k < 420) continue;
    const double error_K = s.node_degC[rotor] - x_degC(rotor_);
    largest_K = std::max(largest_K, std::abs(error_K));
    ASSERT_LE(std::abs(error_K), 2.0 * s.node_sd_K[rotor])
        << "t " << k << " s: rotor " << s.node_degC[rotor] << " sd " << s.node_sd_K[rotor]
        << " truth " << x_degC(rotor_);
    if (std::isnan(s.magnet_flux_degC)) continue;
    ++published;
    ASSERT_LE(std::abs(s.magnet_flux_degC - x_degC(rotor_)), 2.0 * s.magnet_flux_sd_K)
        << "t " << k << " s: magnet " << s.magnet_flux_degC << " sd " << s.magnet_flux_sd_K;
  }
  // Taken as part of the bias, the error learnt at half speed leaves the rotor 2.5-3.9 K high at
  // full speed on this plant; with the state the rotor is 0.9-2.8 K low (the rest is not the
  // voltage error's: the line also lags the ramps).
  EXPECT_LE(largest_K, 3.0);
  EXPECT_GT(published, 100);
}

// 40 W on the rotor from 10 min on, with the voltage rows: uq moves faster than the filter
// expects and its rows fail the gate. Left out for good, they would leave the rotor to run away
// from its estimate; after ten rejections in a row the row is fused again with the magnet's
// variance raised to meet it.
TEST_F(MagnetCalibration, AVoltageBeyondItsGateForLongIsFusedAgain) {
  pd::Pump pump(Config(), motor_, model_, 1.0);
  plant_load_step_A = 0.5;
  ColdStart(pump);
  const auto rotor = static_cast<std::size_t>(rotor_);
  int fused = 0, judged = 0;
  double largest_K = 0.0;
  for (int k = 4; k <= 1800; ++k) {
    if (k == 600) plant_rotor_heat_W = 40.0;
    Period(pump, k, RunUp_rpm(k));
    const auto& s = pump.snapshot();
    if (k < 700) continue;
    ++judged;
    fused += s.voltage_reading.state == pe::ReadingState::kFused;
    largest_K = std::max(largest_K, std::abs(s.node_degC[rotor] - x_degC(rotor_)));
  }
  EXPECT_GT(fused, 0.8 * judged) << "voltage rows fused after the step";
  EXPECT_LT(largest_K, 10.0) << "the rotor, truth " << x_degC(rotor_);
}

// A drive's voltage can carry more noise than its quantisation: a mechanical speed ripple of
// 30 r/min that the speed estimate does not show moves the back-EMF by about 60 mV at 0.37 Hz.
// The filter learns that noise from its innovations, so the run-up does not teach psi0 the
// ripple and the magnet from the flux stays inside its band.
TEST_F(MagnetCalibration, AVoltageNoisierThanAssumedIsLearntAndTheMagnetStaysCovered) {
  pd::Pump pump(Config(), motor_, model_, 1.0);
  plant_dpsi = -0.016;
  plant_load_step_A = 0.5;
  plant_ripple_rpm = 30.0;
  ColdStart(pump);
  const auto rotor = static_cast<std::size_t>(rotor_);
  Band band;
  for (int k = 4; k <= 1200; ++k) {
    Period(pump, k, RunUp_rpm(k));
    const auto& s = pump.snapshot();
    if (k < 300) continue;
    ASSERT_TRUE(s.initialised);
    band.Add(s.node_degC[rotor] - x_degC(rotor_), s.node_sd_K[rotor]);
  }
  EXPECT_GE(band.inside, 0.9 * band.judged) << "rotor inside +-2 sd";
  EXPECT_LT(band.largest_K, 4.0) << "the rotor, truth " << x_degC(rotor_);
}

// A load change inside a period is left out (the steady-state equation does not hold through the
// current loop's transient); a current whose samples are noisy is no load change. At 0.06 A of
// noise per sample (a drive with a coarser current measurement than the 10 mA of
// realistic-signals.md) the period's sd of iq alone would leave out nearly every period, the
// run-up's included, where psi0 is learnt.
TEST_F(MagnetCalibration, ANoisyCurrentIsNoLoadChangeButAStepInsideThePeriodIs) {
  pd::Pump pump(Config(), motor_, model_, 1.0);
  plant_current_noise_A = 0.06;
  ColdStart(pump);
  int fused = 0, judged = 0;
  for (int k = 4; k <= 300; ++k) {
    Period(pump, k, RunUp_rpm(k));
    if (k < 10) continue;
    ++judged;
    fused += pump.snapshot().voltage_reading.state == pe::ReadingState::kFused;
  }
  EXPECT_GE(fused, 0.9 * judged);
  step_inside_A = 0.5;
  Period(pump, 301, 21000.0);
  EXPECT_EQ(pump.snapshot().voltage_reading.state, pe::ReadingState::kGated);
}

// The published identification (Rs, psi_f and their status on CAN, LCM and in the CSV) is the
// pump filter's. A cold start at a constant current cannot tell R0 from the inverter's offset:
// `converging`, neither the winding from resistance nor the resistance published. The first load
// change pins R0: `tracking`. The resistance and the flux, where published, cover the plant's.
TEST_F(MagnetCalibration, ThePublishedIdentificationIsTheFiltersAndALoadChangePinsR0) {
  plant_dr = 0.02;
  plant_dpsi = -0.016;
  plant_voltage_error_V = 0.15;
  plant_load_step_A = 0.5;
  load_steps_from_s = 600;  // the first change at 660 s
  pd::Pump pump(Config(), motor_, model_, 1.0);
  ColdStart(pump);
  using S = pe::ResistanceStatus;
  const auto& cu = motor_.copper;
  const double beta = motor_.magnet.flux_temperature_coefficient_per_K;
  int judged = 0, tracking = 0;
  // Until 18 min: later the noise-free plant's frame reads flat long enough to be taken as a
  // stuck sensor (its reading is rounded to 0.1 K).
  for (int k = 4; k <= 1080; ++k) {
    Period(pump, k, RunUp_rpm(k));
    const auto& s = pump.snapshot();
    if (k < 150) continue;
    const pe::PublishedIdentification& id = s.identification;
    const double r_ohm =
        cu.r0_ohm * (1.0 + plant_dr) * (1.0 + cu.alpha_per_K * (x_degC(winding_) - cu.t0_degC));
    const double flux_Wb = motor_.flux_Wb * (1.0 + plant_dpsi) *
                           (1.0 + beta * (x_degC(rotor_) - motor_.magnet.t0_degC));
    if (std::isfinite(id.resistance_ohm)) {
      ASSERT_LE(std::abs(id.resistance_ohm - r_ohm), 2.0 * id.resistance_sd_ohm)
          << "t " << k << " s: Rs " << id.resistance_ohm << " sd " << id.resistance_sd_ohm
          << " truth " << r_ohm;
    }
    ASSERT_LE(std::abs(id.flux_Wb - flux_Wb), 2.0 * id.flux_sd_Wb)
        << "t " << k << " s: psi_f " << id.flux_Wb << " sd " << id.flux_sd_Wb << " truth "
        << flux_Wb;
    if (k < 660) {
      ASSERT_EQ(id.status, S::kConverging) << "t " << k << " s";
      ASSERT_EQ(s.r0_changes, 0u) << "t " << k << " s";
      ASSERT_TRUE(std::isnan(id.resistance_ohm)) << "left out while converging, t " << k << " s";
      ASSERT_TRUE(std::isnan(s.winding_resistance_degC)) << "t " << k << " s";
      ASSERT_EQ(s.resistance.status, S::kHeld) << "the identifier's own, t " << k << " s";
    } else if (k >= 720) {
      ++judged;
      tracking += id.status == S::kTracking && std::isfinite(s.winding_resistance_degC);
    }
  }
  EXPECT_GT(tracking, 0.9 * judged) << "of " << judged << " periods after the first change";
  EXPECT_EQ(pump.snapshot().r0_changes, 1u) << "R0 learnt once: the journal says it once";
}

// A pump at rest before its run-up (the daemon started before the pumps, as at a plant's start):
// no current flows, the drive reports the voltage of no current, and the inverter's dead time,
// which follows the current, is not there. A voltage row at rest would teach the offset state
// that the drive's voltage error is zero, and the run-up's error along its current then reads as
// resistance (R0 +20 %, the rotor 10 K off on a recording with ten minutes at rest). Below the
// drive's knee the voltage is no row. Nor does the rotor heat state heat a rotor that does not
// turn: its prior (5 W) would spread the rotor's temperature by some 7 K over ten minutes, and
// the run-up would learn psi0 no better than that (here -1.35 % for the plant's -1.6 %, the
// rotor 2.4 K off). The run-up then learns both as it does from a cold start at once.
TEST_F(MagnetCalibration, APumpAtRestBeforeItsRunUpLearnsR0FromTheRunUp) {
  plant_dr = 0.02;
  plant_dpsi = -0.016;
  plant_voltage_error_V = 0.15;
  plant_current_noise_A = 0.01;
  plant_frame_noise_K = 0.05;  // a flat reading for ten minutes would be a stuck sensor
  plant_load_step_A = 0.5;
  current_from_s = 600;
  load_steps_from_s = 900;
  pd::Pump pump(Config(), motor_, model_, 1.0);
  ColdStart(pump);
  const auto rotor = static_cast<std::size_t>(rotor_);
  const auto& cu = motor_.copper;
  Band resistance, magnet;
  for (int k = 4; k <= 1500; ++k) {
    Period(pump, k, RunUp_rpm(k, current_from_s));
    const auto& s = pump.snapshot();
    if (k == 599) {
      EXPECT_NE(s.voltage_reading.state, pe::ReadingState::kFused) << "at rest, no current";
    }
    if (k == 730) {
      EXPECT_LT(s.calibration.dpsi_sd, 0.003) << "psi0 learnt in the run-up";
      EXPECT_NEAR(s.calibration.dpsi, plant_dpsi, 2.0 * s.calibration.dpsi_sd);
    }
    if (k < 900) continue;
    const double r_ohm =
        cu.r0_ohm * (1.0 + plant_dr) * (1.0 + cu.alpha_per_K * (x_degC(winding_) - cu.t0_degC));
    const pe::PublishedIdentification& id = s.identification;
    if (std::isfinite(id.resistance_ohm)) {
      resistance.Add(id.resistance_ohm - r_ohm, id.resistance_sd_ohm);
    }
    magnet.Add(s.node_degC[rotor] - x_degC(rotor_), s.node_sd_K[rotor]);
  }
  EXPECT_GE(resistance.judged, 500) << "the resistance published after the first load change";
  EXPECT_EQ(resistance.inside, resistance.judged) << "Rs inside +-2 sd";
  EXPECT_GE(magnet.inside, 0.9 * magnet.judged) << "rotor inside +-2 sd";
  EXPECT_LT(magnet.largest_K, 1.0) << "the rotor, truth " << x_degC(rotor_);
}

// A motor file whose magnet law is steeper than the magnet's (the plant's flux falls 0.05 %/K,
// the file says 0.1 %/K): the magnet from the flux reads the rotor colder than its losses let it
// be, the filter needs a negative rotor heat to follow it, and the magnet law check says so and
// stops publishing the magnet from the flux. With the file's own law it never does.
TEST_F(MagnetCalibration, AMagnetLawSteeperThanTheMagnetsIsFoundAndItsMagnetLeftOut) {
  plant_load_step_A = 0.5;
  for (const double plant_law_scale : {1.0, 0.5}) {
    SCOPED_TRACE(plant_law_scale);
    pe::MotorDescription plant_motor = motor_;
    plant_motor.magnet.flux_temperature_coefficient_per_K *= plant_law_scale;
    plant_law_ = pe::VoltageLawOf(plant_motor);
    x_degC.setConstant(22.0);
    pd::Pump pump(Config(), motor_, model_, 1.0);
    ColdStart(pump);
    int found_s = -1;
    double found_heat_W = 0.0;  // the rotor heat that made the check say so
    for (int k = 4; k <= 1500; ++k) {
      Period(pump, k, RunUp_rpm(k));
      const auto& s = pump.snapshot();
      if (s.magnet_law_suspect && found_s < 0) {
        found_s = k;
        found_heat_W = s.rotor_heat_W;
      }
      if (found_s >= 0) {
        ASSERT_TRUE(std::isnan(s.magnet_flux_degC)) << "t " << k << " s";
        ASSERT_EQ(s.magnet_law_changes, 1u) << "t " << k << " s";
      }
    }
    const auto& s = pump.snapshot();
    if (plant_law_scale == 1.0) {
      EXPECT_EQ(found_s, -1) << "rotor heat " << s.rotor_heat_W << " W, sd " << s.rotor_heat_sd_W;
      EXPECT_TRUE(std::isfinite(s.magnet_flux_degC));
    } else {
      EXPECT_GT(found_s, 0) << "rotor heat " << s.rotor_heat_W << " W, sd " << s.rotor_heat_sd_W;
      EXPECT_LT(found_heat_W, -3.0);
    }
  }
}

// Once the check has found the law wrong, the filter gives it up (FreeMagnetLaw): the flux the
// voltage reads no longer follows the rotor but walks freely, so the voltage measures the winding
// through the resistance its load changes show, and the rotor is the thermal model's with the
// sd that leaves it. Two plants: a cold start with the magnet at half the file's law, and a warm
// start with a flux that does not move with temperature at all (the file says -0.1 %/K). With
// the law kept after the check, the rotor stayed 15-30 K too cold, never inside its band, and
// the warm start's winding 7-10 K low with an sd of 1.5 K.
TEST_F(MagnetCalibration, AfterTheMagnetLawIsGivenUpTheVoltageReadsTheWindingAlone) {
  plant_load_step_A = 0.5;
  const auto winding = static_cast<std::size_t>(winding_);
  const auto rotor = static_cast<std::size_t>(rotor_);
  for (const double plant_law_scale : {0.5, 0.0}) {
    SCOPED_TRACE(plant_law_scale);
    pe::MotorDescription plant_motor = motor_;
    plant_motor.magnet.flux_temperature_coefficient_per_K *= plant_law_scale;
    plant_law_ = pe::VoltageLawOf(plant_motor);
    const bool warm = plant_law_scale == 0.0;
    x_degC.setConstant(warm ? 30.0 : 22.0);
    pd::Pump pump(Config(), motor_, model_, 1.0);
    for (int k = 1; k <= 3; ++k) Period(pump, k, warm ? 21000.0 : 0.0);
    int found_s = -1;
    Band winding_band, rotor_band;
    for (int k = 4; k <= 2400; ++k) {
      Period(pump, k, warm ? 21000.0 : RunUp_rpm(k));
      const auto& s = pump.snapshot();
      if (s.magnet_law_suspect && found_s < 0) found_s = k;
      if (found_s < 0 || k < found_s + 60) continue;
      winding_band.Add(s.node_degC[winding] - x_degC(winding_), s.node_sd_K[winding]);
      rotor_band.Add(s.node_degC[rotor] - x_degC(rotor_), s.node_sd_K[rotor]);
    }
    const auto& s = pump.snapshot();
    ASSERT_GT(found_s, 0) << "rotor heat " << s.rotor_heat_W << " W";
    EXPECT_LT(found_s, 900);
    EXPECT_GE(winding_band.inside, 0.9 * winding_band.judged)
        << "largest winding error " << winding_band.largest_K;
    EXPECT_LT(winding_band.largest_K, 3.0);
    EXPECT_GE(rotor_band.inside, 0.9 * rotor_band.judged)
        << "rotor " << s.node_degC[rotor] << " sd " << s.node_sd_K[rotor] << " truth "
        << x_degC(rotor_);
    EXPECT_LT(s.node_sd_K[rotor], tolerance_K) << "the filter's own sd, not psi0's tolerance";
    EXPECT_EQ(s.magnet_law_changes, 1u);
    if (warm) continue;

    // Restarted from the saved state, the law stays given up (said once, in the run that found
    // it); with a motor file that now states the magnet's own law, the calibration starts afresh.
    const pd::PumpSavedState saved = pump.Save();
    ASSERT_EQ(saved.magnet_law_given_up_per_K, motor_.magnet.flux_temperature_coefficient_per_K);
    pd::Pump restored(Config(), motor_, model_, 1.0);
    ASSERT_TRUE(restored.Restore(saved, saved.time_us));
    pd::Pump corrected(Config(), plant_motor, model_, 1.0);
    ASSERT_TRUE(corrected.Restore(saved, saved.time_us));
    int restored_judged = 0, restored_covered = 0;
    for (int k = 2401; k <= 2700; ++k) {
      Period(restored, k, 21000.0);
      const auto& r = restored.snapshot();
      ASSERT_TRUE(r.magnet_law_suspect) << "t " << k << " s";
      ASSERT_EQ(r.magnet_law_changes, 0u) << "t " << k << " s";
      ++restored_judged;
      restored_covered +=
          std::abs(r.node_degC[winding] - x_degC(winding_)) <= 2.0 * r.node_sd_K[winding] &&
          std::abs(r.node_degC[rotor] - x_degC(rotor_)) <= 2.0 * r.node_sd_K[rotor];
    }
    EXPECT_GE(restored_covered, 0.9 * restored_judged);
    Period(corrected, 2401, 21000.0);
    EXPECT_FALSE(corrected.snapshot().magnet_law_suspect);
    EXPECT_FALSE(corrected.snapshot().calibrated_at_cold_start);
  }
}

// The rotor's losses twice the model's gas-friction share (3 W more per ampere of iq: 6-12 W
// under the load steps). The rotor heat state takes them; the loss scale, which leaves the rotor
// node's losses to that state, does not. With the rotor's losses in the loss scale too, the
// filter took the rotor's heat as every loss higher and a negative rotor heat, R0 drifted to
// -3 %, and the winding was 9.5 K high with an sd of 1.2 K (never inside its band).
TEST_F(MagnetCalibration, RotorLossesTheModelLacksStayOffTheWinding) {
  plant_load_step_A = 1.0;
  plant_rotor_heat_W_per_A = 3.0;
  pd::Pump pump(Config(), motor_, model_, 1.0);
  ColdStart(pump);
  const auto winding = static_cast<std::size_t>(winding_);
  Band band;
  for (int k = 4; k <= 1800; ++k) {
    Period(pump, k, RunUp_rpm(k));
    const auto& s = pump.snapshot();
    if (k < 300) continue;
    band.Add(s.node_degC[winding] - x_degC(winding_), s.node_sd_K[winding]);
  }
  const auto& s = pump.snapshot();
  EXPECT_GE(band.inside, 0.9 * band.judged) << "largest winding error " << band.largest_K << " K";
  EXPECT_LT(band.largest_K, 5.0);
  EXPECT_GT(s.rotor_heat_W, 3.0) << "sd " << s.rotor_heat_sd_W;
  EXPECT_FALSE(s.magnet_law_suspect);
}

// A plant whose stator iron makes 1.8 times the model's losses: the extra heat reaches the frame
// sensor late and R0 is learnt against a winding already warmer than the model's. Stated as a
// model checked against this pump (model_losses_sd_rel 0.1, the default), the filter puts that
// heat on the frame path and into R0: the winding runs 2-3 K cold inside a band of 1.3 K sd
// (covered 40 % of the time, x + 2 sd up to 0.7 K below the truth: a trip would come late).
// Stated as a model not checked (0.3), the band covers it 95 % of the time; the bias itself
// still grows (3 K at the end, where x + 2 sd falls 0.3 K short for a while).
TEST_F(MagnetCalibration, IronLossesBeyondTheStatedModelErrorAreCoveredWhenStated) {
  plant_model_ = TmpGeneric({pe::Effect{"iron_loss_scale", {1.8}, ""}});
  plant_load_step_A = 1.0;
  plant_dr = 0.02;
  for (const double losses_sd : {0.1, 0.3}) {
    SCOPED_TRACE(losses_sd);
    x_degC.setConstant(22.0);
    pd::PumpConfig config = Config();
    config.model_losses_sd_rel = losses_sd;
    pd::Pump pump(config, motor_, model_, 1.0);
    ColdStart(pump);
    const auto winding = static_cast<std::size_t>(winding_);
    Band band;
    double lowest_K = 0.0;  // the most the estimate's upper bound fell short of the truth
    for (int k = 4; k <= 2400; ++k) {
      Period(pump, k, RunUp_rpm(k));
      if (k < 300) continue;
      const auto& s = pump.snapshot();
      const double error_K = s.node_degC[winding] - x_degC(winding_);
      band.Add(error_K, s.node_sd_K[winding]);
      lowest_K = std::min(lowest_K, error_K + 2.0 * s.node_sd_K[winding]);
    }
    if (losses_sd < 0.2) {
      EXPECT_LT(band.inside, 0.5 * band.judged) << "the case: the winding uncovered at 0.1";
      EXPECT_LT(lowest_K, 0.0) << "its x + 2 sd below the truth: a trip would come late";
      EXPECT_GT(band.largest_K, 2.0);
    } else {
      EXPECT_GE(band.inside, 0.9 * band.judged) << "largest winding error " << band.largest_K;
    }
  }
}

// Where the filter does not fuse the voltage (no voltage rows, or a failed frame sensor) the
// published identification is the DFRLS identifier's status alone. On this plant (R0 3 % above the
// nameplate, load steps of 2 A) the identifier tracks for minutes, but its Rs is then inside its
// +-2 sd about a quarter of the time, and the winding it gives (Han 2019 eq. 3, the nameplate's R0)
// up to 17 K off: its values are a diagnostic (the CSV's identifier_winding_degC), neither the
// identification nor the winding from resistance.
TEST_F(MagnetCalibration, TheIdentifiersValuesAreADiagnosticOnly) {
  const auto& cu = motor_.copper;
  for (const bool voltage : {false, true}) {
    SCOPED_TRACE(voltage);
    pd::PumpConfig config = Config();
    config.voltage_reading = voltage;
    plant_dr = 0.03;
    plant_load_step_A = 1.0;
    x_degC.setConstant(22.0);
    frame_stuck_degC = std::numeric_limits<double>::quiet_NaN();
    pd::Pump pump(config, motor_, model_, 1.0);
    ColdStart(pump);
    int tracking = 0, rs_covered = 0;
    for (int k = 4; k <= 2400; ++k) {
      if (voltage && k == 1200) frame_stuck_degC = x_degC(frame_);  // the RTD sticks
      Period(pump, k, RunUp_rpm(k));
      const auto& s = pump.snapshot();
      if (voltage && s.sensor_fault == pe::SensorFault::kNone) continue;
      const pe::PublishedIdentification& id = s.identification;
      ASSERT_EQ(id.status, s.resistance.status) << "t " << k << " s";
      ASSERT_TRUE(std::isnan(id.resistance_ohm)) << "t " << k << " s";
      ASSERT_TRUE(std::isnan(id.flux_Wb)) << "t " << k << " s";
      ASSERT_TRUE(std::isnan(s.winding_resistance_degC)) << "t " << k << " s";
      if (s.resistance.status != pe::ResistanceStatus::kTracking) continue;
      ++tracking;
      EXPECT_TRUE(std::isfinite(s.identifier_winding_degC)) << "t " << k << " s";
      const double r_ohm =
          cu.r0_ohm * (1.0 + plant_dr) * (1.0 + cu.alpha_per_K * (x_degC(winding_) - cu.t0_degC));
      rs_covered +=
          std::abs(s.resistance.resistance_ohm - r_ohm) <= 2.0 * s.resistance.resistance_sigma_ohm;
    }
    EXPECT_GT(tracking, 100) << "the case this test is about: the identifier tracks";
    EXPECT_LT(rs_covered, 0.5 * tracking) << "and its Rs is then outside its band";
  }
}

// A reload that states the losses further off widens the restored loss scale, but the heat the
// filter had put on the frame path and into R0 by then stays there: the same plant as above,
// 0.1 until a reload to 0.3 at 10 min, is covered more than at 0.1 throughout, far less than
// at 0.3 from the start (docs/operator-guide.md, section 4).
TEST_F(MagnetCalibration, LossesStatedWiderAtAReloadCoverMoreThanBeforeLessThanFromTheStart) {
  plant_model_ = TmpGeneric({pe::Effect{"iron_loss_scale", {1.8}, ""}});
  plant_load_step_A = 1.0;
  plant_dr = 0.02;
  constexpr int kReload_s = 600;
  const auto winding = static_cast<std::size_t>(winding_);
  std::map<bool, double> inside;  // reloaded or not: the share inside +-2 sd after the reload
  for (const bool reload : {false, true}) {
    SCOPED_TRACE(reload);
    x_degC.setConstant(22.0);
    pd::PumpConfig config = Config();
    auto pump = std::make_unique<pd::Pump>(config, motor_, model_, 1.0);
    ColdStart(*pump);
    Band band;
    for (int k = 4; k <= 2400; ++k) {
      Period(*pump, k, RunUp_rpm(k));
      if (reload && k == kReload_s) {
        const pd::PumpSavedState saved = pump->Save();
        config.model_losses_sd_rel = 0.3;
        auto next = std::make_unique<pd::Pump>(config, motor_, model_, 1.0);
        ASSERT_TRUE(next->Restore(saved, saved.time_us));
        EXPECT_NEAR(next->snapshot().losses_sd_widened_from, 0.1, 1e-12);
        pump = std::move(next);
      }
      if (k < kReload_s) continue;
      const auto& s = pump->snapshot();
      band.Add(s.node_degC[winding] - x_degC(winding_), s.node_sd_K[winding]);
    }
    inside[reload] = static_cast<double>(band.inside) / band.judged;
  }
  EXPECT_GT(inside[true], inside[false] + 0.1);
  EXPECT_LT(inside[true], 0.9) << "as a start at 0.3: docs/operator-guide.md section 4 to change";
}

}  // namespace
