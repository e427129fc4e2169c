// The pump estimator (estimators/pump_estimator.hpp) and its parts: the readings against their
// closed forms, the observer interface against the filters' own steps, health as data, and the
// saved state.
#include "estimators/pump_estimator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "estimators/frame_sensor_model.hpp"
#include "estimators/readings/magnet_flux_reading.hpp"
#include "protocol/dq_pairing.hpp"
#include "tests/bench/mismatch_cases.hpp"

namespace pe = pumptherm::estimators;
namespace mc = mismatch_cases;

namespace {

std::string EstimatorModelDir() {
  const char* src = std::getenv("PUMPTHERM_SOURCE_DIR");
  return std::string(src != nullptr ? src : PUMPTHERM_SOURCE_DIR) + "/estimators/models";
}

pe::ThermalModel TmpGeneric() {
  return pe::ThermalModel::Parse(mc::ReadFile(EstimatorModelDir() + "/tmp-generic.toml"),
                                 "tmp-generic",
                                 pe::ThermalModelFiles{EstimatorModelDir(), mc::ReadFile});
}

pe::ThermalInputs Running(double iq_A = 3.0) {
  pe::ThermalInputs in;
  in.speed_rpm = 21000.0;
  in.iq_A = iq_A;
  in.ambient_degC = in.coolant_degC = 22.0;
  return in;
}

pe::PumpPeriod Period(double t_s, double iq_A = 3.0) {
  pe::PumpPeriod p;
  p.end_us = static_cast<std::int64_t>(std::llround(t_s * 1e6));
  p.inputs = Running(iq_A);
  p.fresh_inputs = true;
  p.mean_iq_A = iq_A;
  p.ambient_degC = 22.0;
  p.fast_age_s = 0.0;
  return p;
}

TEST(MagnetFluxReading, ReadsTheMagnetPlusGTimesTheWindingExactly) {
  // The identifier's line E = psi_f + Rs iq/w with psi_f at a 60 degC magnet and Rs at an
  // 80 degC winding (Han 2019 eqs. 2 and 6, the magnet law of estimators/magnet.hpp): the row
  // z = Tm + g Tw, g = R0 alpha iq / (w psi0 beta).
  const pe::ThermalModel model = TmpGeneric();
  const pe::MotorDescription motor = pe::MotorPreset("han2019-tmp");
  pe::MagnetFluxReadingConfig c;
  c.magnet_node = "rotor";
  pe::MagnetFluxReading reading(motor, model, c);
  const double w = pe::ElectricalSpeed_rad_per_s(motor, 21000.0);
  const double iq_A = 3.0;
  reading.Prepare(mc::EmulatedIdentifier(motor, std::nan(""), 0.0, 60.0, 0.5, 80.0), iq_A, w);
  const double g = motor.copper.r0_ohm * motor.copper.alpha_per_K * iq_A /
                   (w * motor.flux_Wb * motor.magnet.flux_temperature_coefficient_per_K);
  ASSERT_TRUE(reading.Offered()) << pe::ReadingStateName(reading.status().state);
  EXPECT_NEAR(reading.status().observation, 60.0 + g * 80.0, 1e-9);
  EXPECT_NEAR(reading.MagnetAt_degC(80.0), 60.0, 1e-9);
  EXPECT_NEAR(reading.status().sd_K, 0.5, 1e-12);
  // Under load the winding's weight |g| passes the gate: published neither, nor fused.
  reading.Prepare(mc::EmulatedIdentifier(motor, std::nan(""), 0.0, 60.0, 0.5, 80.0), 20.0, w);
  EXPECT_FALSE(reading.Offered());
  EXPECT_EQ(reading.status().state, pe::ReadingState::kGated);
  // Below a tenth of rated speed: too slow.
  reading.Prepare(mc::EmulatedIdentifier(motor, std::nan(""), 0.0, 60.0, 0.5, 80.0), iq_A,
                  0.05 * w);
  EXPECT_EQ(reading.status().state, pe::ReadingState::kTooSlow);
}

TEST(DqPairing, PairsHalvesOfOneCycleAndCountsTheOnesLeftOver) {
  pumptherm::protocol::DqPairing pairing;
  pumptherm::protocol::DqPair out;
  EXPECT_FALSE(pairing.OnCurrents(1000, 0.1, 2.0, 3.0, out));
  ASSERT_TRUE(pairing.OnVoltages(1500, 0.2, 40.0, 3.0, out));
  EXPECT_EQ(out.t_us, 1500);
  EXPECT_EQ(out.iq_A, 2.0);
  EXPECT_EQ(out.uq_V, 40.0);
  // Another counter: no pair; the current half waits and is counted when replaced.
  EXPECT_FALSE(pairing.OnCurrents(20000, 0.1, 2.0, 4.0, out));
  EXPECT_FALSE(pairing.OnVoltages(20500, 0.2, 40.0, 5.0, out));
  EXPECT_TRUE(pairing.OnCurrents(30000, 0.1, 2.0, 5.0, out));  // pairs with the voltages
  EXPECT_EQ(pairing.unpaired(), 1u);
  // Too far apart (over 50 ms): no pair. Without counters (NaN), near halves pair.
  EXPECT_FALSE(pairing.OnCurrents(100000, 0.1, 2.0, std::nan(""), out));
  EXPECT_FALSE(pairing.OnVoltages(200000, 0.2, 40.0, std::nan(""), out));
  EXPECT_TRUE(pairing.OnCurrents(210000, 0.1, 2.0, std::nan(""), out));
}

TEST(ThermalObserver, TheStandardFiltersReadingsAreItsOwnRows) {
  // The observer step with a frame reading is the filter's step with that node measured.
  const pe::ThermalModel model = TmpGeneric();
  pe::VirtualSensorConfig c;
  pe::VirtualThermalSensor a(model, c), b(model, c);
  a.Initialise(25.0);
  b.Initialise(Eigen::VectorXd::Constant(model.StateCount(), 25.0));
  Eigen::VectorXd y(1);
  const pe::NodeMeasurements none;
  for (int k = 0; k < 200; ++k) {
    pe::ThermalReadings r;
    r.frame_degC = y(0) = 25.0 + 0.05 * k;
    const pe::ObserverReport& ra = a.Step(Running(), 1.0, r);
    const pe::KalmanUpdateReport& rb = b.Step(Running(), 1.0, y, none);
    ASSERT_TRUE(ra.frame.fused);
    EXPECT_NEAR(ra.frame.innovation_K, rb.innovation(0), 1e-12);
  }
  for (int i = 0; i < model.StateCount(); ++i) {
    EXPECT_NEAR(a.Node_degC(i), b.Estimate_degC()(i), 1e-9);
    EXPECT_NEAR(a.NodeSd_K(i), std::sqrt(b.Covariance_K2()(i, i)), 1e-9);
  }
}

TEST(FrameSensorModel, TheLagFollowsTheNodeAndTheReadingAddsTheOffset) {
  const pe::ThermalModel model = TmpGeneric();
  pe::FrameSensorModel s(model, "frame", 30.0, "test");
  const int n = model.StateCount();
  ASSERT_EQ(s.lag(), n);
  s.PlaceOffset(n + 1);
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n + 1, n + 1);
  s.AddLagRow(a);
  EXPECT_DOUBLE_EQ(a(n, s.node()), 1.0 / 30.0);
  EXPECT_DOUBLE_EQ(a(n, n), -1.0 / 30.0);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n + 2);
  Eigen::MatrixXd p = Eigen::MatrixXd::Zero(n + 2, n + 2);
  s.SetInitial(40.0, 20.0, 5.0, 0.5, x, p);
  x(n + 1) = 0.3;
  EXPECT_DOUBLE_EQ(s.PredictedReading_degC(x), 40.3);
  EXPECT_DOUBLE_EQ(s.PredictedReadingVar_K2(p), 20.0 * 20.0 + 5.0 * 5.0 + 0.25);
  EXPECT_THROW(pe::FrameSensorModel(model, "nope", 0.0, "test"), std::invalid_argument);
}

class PumpEstimatorTest : public ::testing::Test {
 protected:
  pe::ThermalModel model_ = TmpGeneric();
  pe::MotorDescription motor_ = pe::MotorPreset("han2019-tmp");
};

TEST_F(PumpEstimatorTest, StartsFromTheFirstReadingAndNotBefore) {
  pe::PumpEstimatorConfig c;
  pe::PumpEstimator e(c, motor_, model_);
  pe::PumpPeriod p = Period(1.0);
  p.ambient_degC = std::nan("");
  e.Step(p);  // neither a reading nor an ambient: nothing to start from
  EXPECT_FALSE(e.estimate().initialised);
  e.OnFrameReading(p.end_us + 500'000, 31.0);
  e.Step(Period(2.0));
  ASSERT_TRUE(e.estimate().initialised);
  EXPECT_NEAR(e.estimate().node_degC[0], 31.0, 0.5);
  EXPECT_EQ(e.estimate().frame_reading.state, pe::ReadingState::kFused);
  EXPECT_TRUE(e.disturbance_states()) << "tmp-generic's boundary reaches the frame alone";
}

TEST_F(PumpEstimatorTest, InputsTheModelCannotTakeAreRefusedAndCountedNotThrown) {
  pe::PumpEstimatorConfig c;
  pe::PumpEstimator e(c, motor_, model_);
  e.OnFrameReading(500'000, 30.0);
  e.Step(Period(1.0));
  const pe::PumpEstimate before = e.estimate();
  pe::PumpPeriod bad = Period(2.0);
  bad.inputs.iq_A = std::nan("");
  EXPECT_NO_THROW(e.Step(bad));
  EXPECT_EQ(e.counters().refused_steps, 1u);
  EXPECT_EQ(e.estimate().node_degC, before.node_degC);
}

TEST_F(PumpEstimatorTest, AFailedSensorIsLeftOutAndSaysWhy) {
  pe::PumpEstimatorConfig c;
  pe::PumpEstimator e(c, motor_, model_);
  for (int k = 1; k <= 20; ++k) {
    e.OnFrameReading(static_cast<std::int64_t>(k) * 1'000'000 - 100'000, 30.0 + 0.01 * (k % 3));
    e.Step(Period(k));
  }
  EXPECT_EQ(e.estimate().frame_reading.state, pe::ReadingState::kFused);
  // The sensor's frame stops (missing after stale_after_s) while the drive's frames go on.
  for (int k = 21; k <= 30; ++k) e.Step(Period(k));
  EXPECT_EQ(e.estimate().sensor_fault, pe::SensorFault::kMissing);
  EXPECT_EQ(e.estimate().frame_reading.state, pe::ReadingState::kStale);
  EXPECT_TRUE(std::isnan(e.estimate().frame_measured_degC));
}

TEST_F(PumpEstimatorTest, ASavedStateRestoredAtOnceGivesTheSameEstimate) {
  pe::PumpEstimatorConfig c;
  c.magnet.magnet_node = "rotor";
  pe::PumpEstimator a(c, motor_, model_), b(c, motor_, model_);
  for (int k = 1; k <= 600; ++k) {
    a.OnFrameReading(static_cast<std::int64_t>(k) * 1'000'000 - 1, 25.0 + 0.02 * k);
    pe::PumpPeriod p = Period(k);
    p.identifier =
        mc::EmulatedIdentifier(motor_, std::nan(""), 0.0, 30.0 + 0.03 * k, 0.5, 40.0 + 0.05 * k);
    a.Step(p);
  }
  const pe::PumpEstimatorState s = a.Save();
  ASSERT_EQ(s.observer_x.size(), a.observer().StateCount()) << "the whole state is saved";
  ASSERT_TRUE(b.Restore(s, s.time_us));
  for (std::size_t i = 0; i < a.estimate().node_degC.size(); ++i) {
    EXPECT_NEAR(b.estimate().node_degC[i], a.estimate().node_degC[i], 1e-9);
    EXPECT_NEAR(b.estimate().node_sd_K[i], a.estimate().node_filter_sd_K[i], 1e-9);
  }
  // A state of another model is refused, nothing changes.
  pe::PumpEstimatorState other = s;
  other.model_name = "another";
  EXPECT_FALSE(b.Restore(other, s.time_us));
}

// The loss scale's start sd as the configuration states it (model_losses_sd_rel): a state saved
// under 0.1 and restored where 0.3 is stated has its loss scale widened to 0.3, nothing else of it
// changed; restored under the same statement, or from an older file under 0.1, it is as saved.
TEST_F(PumpEstimatorTest, LossesStatedFurtherOffSinceTheSaveWidenTheRestoredLossScale) {
  pe::PumpEstimatorConfig c;
  c.magnet.magnet_node = "rotor";
  pe::PumpEstimator a(c, motor_, model_);
  for (int k = 1; k <= 600; ++k) {
    a.OnFrameReading(static_cast<std::int64_t>(k) * 1'000'000 - 1, 25.0 + 0.02 * k);
    a.Step(Period(k));
  }
  const pe::PumpEstimatorState s = a.Save();
  ASSERT_DOUBLE_EQ(s.losses_sd_rel, 0.1);
  const Eigen::MatrixXd& saved = a.observer().Covariance();
  pe::PumpEstimatorConfig wider = c;
  wider.disturbance.loss_scale_initial_sd = 0.3;
  pe::PumpEstimator b(wider, motor_, model_), same(c, motor_, model_), older(c, motor_, model_);
  ASSERT_TRUE(b.Restore(s, s.time_us));
  const Eigen::MatrixXd diff = b.observer().Covariance() - saved;
  Eigen::Index row = 0, col = 0;
  const double grown = diff.cwiseAbs().maxCoeff(&row, &col);
  EXPECT_EQ(row, col) << "one variance grew, no covariance";
  EXPECT_LT(saved(row, row), 0.09) << "the saved loss scale narrower than stated now";
  EXPECT_NEAR(b.observer().Covariance()(row, row), 0.09, 1e-12);
  EXPECT_NEAR(diff.cwiseAbs().sum(), grown, 1e-12) << "nothing else changed";
  ASSERT_TRUE(same.Restore(s, s.time_us));
  EXPECT_EQ(same.observer().Covariance(), saved);
  pe::PumpEstimatorState old_file = s;
  old_file.losses_sd_rel = std::nan("");  // written before the key: 0.1
  ASSERT_TRUE(older.Restore(old_file, s.time_us));
  EXPECT_EQ(older.observer().Covariance(), saved);
  pe::PumpEstimatorState damaged = s;
  damaged.losses_sd_rel = -0.1;
  EXPECT_FALSE(pe::PumpEstimator(c, motor_, model_).Restore(damaged, s.time_us));
}

}  // namespace
