// The mismatch detector on simulated pumps (tests/bench/mismatch_cases.hpp): tmp-generic truth,
// frame RTD with lag, noise, quantisation and a calibration offset, faults from one hour on.
#include "estimators/mismatch_detector.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "tests/bench/mismatch_cases.hpp"

namespace pe = pumptherm::estimators;
namespace mc = mismatch_cases;

namespace {

std::string ModelDir() {
  const char* src = std::getenv("PUMPTHERM_SOURCE_DIR");
  return std::string(src != nullptr ? src : PUMPTHERM_SOURCE_DIR) + "/estimators/models";
}

/// Faults start after an hour, when the pump has (nearly) reached its thermal equilibrium.
mc::CaseResult RunFault(mc::Fault fault, std::uint64_t seed, double duration_s = 3600.0 + 1500.0,
                        double magnet_white_sd_K = 0.0) {
  mc::CaseSpec spec;
  spec.magnet_noise_sd_K = magnet_white_sd_K;  // with the default 2 K slow bias
  spec.fault = fault;
  spec.fault_s = fault == mc::Fault::kNone ? duration_s + 1.0 : 3600.0;
  spec.duration_s = duration_s;
  spec.seed = seed;
  return mc::RunCase(spec, ModelDir());
}

TEST(ChiSquareQuantile, MatchesTables) {
  // chi-square upper quantiles (Abramowitz and Stegun, Table 26.8): 60 dof, 0.1 %: 99.607;
  // 100 dof, 1 %: 135.807. Wilson-Hilferty is within 0.5 % there.
  EXPECT_NEAR(pe::ChiSquareQuantile(60, 1e-3), 99.607, 0.5);
  EXPECT_NEAR(pe::ChiSquareQuantile(100, 1e-2), 135.807, 0.5);
}

TEST(MismatchDetector, NoFalseAlarmOnFaultFreeData) {
  for (std::uint64_t seed : {11u, 12u}) {
    const mc::CaseResult r = RunFault(mc::Fault::kNone, seed, 10800.0);
    EXPECT_EQ(r.false_alarms, 0) << "seed " << seed << " first at " << r.first_false_s << " s";
    EXPECT_EQ(r.at_end.state, pe::MismatchState::kConsistent) << "seed " << seed;
  }
}

TEST(MismatchDetector, DetectsLostCoolingAndNamesTheFramePath) {
  const mc::CaseResult r = RunFault(mc::Fault::kCoolingLost, 3);
  ASSERT_FALSE(std::isnan(r.detect_delay_s));
  EXPECT_LE(r.detect_delay_s, 60.0);
  EXPECT_EQ(r.at_end.state, pe::MismatchState::kPlantChange);
  EXPECT_EQ(r.at_end.effect, pe::MismatchEffect::kFrameAmbientResistance)
      << pe::DescribeFinding(r.at_end);
  // x4 in the truth. The regressor's frame temperature is the reading less the offset estimated
  // before the onset: with the offset after it (which soaks up the fault) the fit said x9.2.
  EXPECT_NEAR(r.at_end.value, 4.0, 0.5);
  EXPECT_EQ(r.false_alarms, 0);
}

TEST(MismatchDetector, NamesExtraRotorHeatWithItsSize) {
  const mc::CaseResult r = RunFault(mc::Fault::kRotorLoss, 4);
  ASSERT_FALSE(std::isnan(r.detect_delay_s));
  EXPECT_LE(r.detect_delay_s, 600.0);
  EXPECT_EQ(r.at_end.effect, pe::MismatchEffect::kRotorLoss) << pe::DescribeFinding(r.at_end);
  EXPECT_NEAR(r.at_end.value, 6.0, 1.5);
}

TEST(MismatchDetector, TheFluxReadingKeepsAnAmbientRiseOffTheRotor) {
  // From the frame alone an unmeasured ambient rise looks like heat inside the rotor (named
  // rotor_loss about 17 W); a rotor reading with a 2 K slow bias contradicts that size.
  const mc::CaseResult frame_only = RunFault(mc::Fault::kAmbientRise, 7);
  EXPECT_EQ(frame_only.at_end.effect, pe::MismatchEffect::kRotorLoss)
      << pe::DescribeFinding(frame_only.at_end);
  const mc::CaseResult r = RunFault(mc::Fault::kAmbientRise, 7, 3600.0 + 1500.0, 1.0);
  EXPECT_EQ(r.at_end.state, pe::MismatchState::kPlantChange);
  EXPECT_NE(r.at_end.effect, pe::MismatchEffect::kRotorLoss) << pe::DescribeFinding(r.at_end);
  EXPECT_EQ(r.false_alarms, 0);
}

TEST(MismatchDetector, AnAmbientRampHypothesisNamesARampOfItsOwnDurationOnly) {
  // The optional ramp form of the unmeasured ambient (off by default): a 10-minute hypothesis
  // names the matrix's 10-minute rise right with its size, and a 30-minute rise still as rotor
  // heat (slow boundary change and rotor heat look alike through the frame).
  mc::CaseSpec spec;
  spec.fault = mc::Fault::kAmbientRise;
  spec.fault_s = 3600.0;
  spec.duration_s = 3600.0 + 1500.0;
  spec.seed = 7;
  spec.fit_ambient_ramp_s = 600.0;
  const mc::CaseResult r = mc::RunCase(spec, ModelDir());
  EXPECT_EQ(r.at_end.effect, pe::MismatchEffect::kUnmeasuredAmbient)
      << pe::DescribeFinding(r.at_end);
  EXPECT_NEAR(r.at_end.value, 8.0, 0.5);
  EXPECT_NE(r.at_end.runner_up, pe::MismatchEffect::kUnmeasuredAmbient);
  spec.ambient_ramp_s = 1800.0;
  spec.duration_s = 3600.0 + 2400.0;
  const mc::CaseResult slow = mc::RunCase(spec, ModelDir());
  EXPECT_EQ(slow.at_end.effect, pe::MismatchEffect::kRotorLoss) << pe::DescribeFinding(slow.at_end);
}

TEST(MismatchDetector, TheFluxReadingNamesRotorHeatAtFirst) {
  // Seed 2: from the frame alone the first name is loss_scale; with the rotor reading, rotor_loss.
  const mc::CaseResult frame_only = RunFault(mc::Fault::kRotorLoss, 2, 3600.0 + 600.0);
  EXPECT_NE(frame_only.at_naming.effect, pe::MismatchEffect::kRotorLoss)
      << pe::DescribeFinding(frame_only.at_naming);
  const mc::CaseResult r = RunFault(mc::Fault::kRotorLoss, 2, 3600.0 + 600.0, 1.0);
  ASSERT_FALSE(std::isnan(r.name_delay_s));
  EXPECT_EQ(r.at_naming.effect, pe::MismatchEffect::kRotorLoss) << pe::DescribeFinding(r.at_naming);
}

TEST(MismatchDetector, TellsASensorOffsetFromAPlantChange) {
  const mc::CaseResult r = RunFault(mc::Fault::kSensorOffset, 5, 3600.0 + 300.0);
  ASSERT_FALSE(std::isnan(r.name_delay_s));
  EXPECT_EQ(r.at_naming.state, pe::MismatchState::kSensorFaultSuspected);
  EXPECT_EQ(r.at_naming.effect, pe::MismatchEffect::kSensorOffset);
  EXPECT_NEAR(r.at_naming.value, 3.0, 0.3);
}

TEST(MismatchDetector, TellsAStuckSensor) {
  // The pump's sensor-health test finds a frozen reading first (30 s flat) and leaves it out;
  // without it the reading is fused and the mismatch test names it.
  mc::CaseSpec spec;
  spec.fault = mc::Fault::kSensorStuck;
  spec.fault_s = 3600.0;
  spec.duration_s = 3600.0 + 600.0;
  spec.seed = 6;
  spec.flat_after_s = 0.0;
  const mc::CaseResult r = mc::RunCase(spec, ModelDir());
  ASSERT_FALSE(std::isnan(r.name_delay_s));
  EXPECT_EQ(r.at_naming.state, pe::MismatchState::kSensorFaultSuspected);
  EXPECT_EQ(r.at_naming.effect, pe::MismatchEffect::kSensorStuck);
}

/// The no-fault case with the RTD lagging `lag_s` and the estimator configured with
/// `configured_s`, seed `seed`, an hour.
mc::CaseResult RunLag(double lag_s, double configured_s, int seed) {
  mc::CaseSpec spec;
  spec.sensor_lag_s = lag_s;
  spec.configured_lag_s = configured_s;
  spec.fault_s = 0.0;
  spec.duration_s = 3600.0;
  spec.seed = static_cast<std::uint64_t>(seed);
  return mc::RunCase(spec, ModelDir());
}

TEST(MismatchDetector, NamesAFrameSensorLagOtherThanConfigured) {
  // RTDs lagging 90 s and 150 s (a deeper well, a loose fit), configured as 30 s, no fault: the
  // first name is the lag, with its size. Without the lag hypothesis the 90 s case was named
  // loss_scale x1.20, and the demo recorded with a 90 s sensor named its healthy pumps'
  // mismatch an unmeasured ambient (+1.6 and +2.1 K).
  for (const double lag_s : {90.0, 150.0}) {
    for (const int seed : {1, 2}) {
      const mc::CaseResult r = RunLag(lag_s, 30.0, seed);
      SCOPED_TRACE(testing::Message() << "lag " << lag_s << " s, seed " << seed << ": "
                                      << pe::DescribeFinding(r.at_naming));
      ASSERT_FALSE(std::isnan(r.name_delay_s));
      EXPECT_EQ(r.at_naming.state, pe::MismatchState::kSensorFaultSuspected);
      EXPECT_EQ(r.at_naming.effect, pe::MismatchEffect::kSensorLag);
      EXPECT_NEAR(r.at_naming.value, lag_s, 0.2 * lag_s);
    }
  }
}

TEST(MismatchDetector, NamesTheLagOfASensorConfiguredWithout) {
  // frame_sensor_lag_s left at 0 on an RTD of 30 s: where the test fails and names a cause, the
  // lag is named first in at least 3 of 4 seeds (measured: 31, 21 and 29 s; the fourth named an
  // unmeasured ambient of +1.7 K first), each within 10 s.
  int named_lag = 0;
  for (const int seed : {1, 2, 3, 4}) {
    const mc::CaseResult r = RunLag(30.0, 0.0, seed);
    SCOPED_TRACE(testing::Message() << "seed " << seed << ": " << pe::DescribeFinding(r.at_naming));
    if (r.at_naming.effect != pe::MismatchEffect::kSensorLag) continue;
    ++named_lag;
    EXPECT_NEAR(r.at_naming.value, 30.0, 10.0);
  }
  EXPECT_GE(named_lag, 3);
}

TEST(MismatchDetector, ANamedLagIsTakenAndALaterLostCoolingIsReadInTime) {
  // An RTD of 90 s configured as 30 s, the cooling lost (x4) an hour in. The lag is named in the
  // first quarter hour and the pump estimator reads the sensor with it from then: after the
  // fault the frame and the winding stay on the truth and the lost cooling is named. Without
  // taking the lag (measured, seeds 1-2): frame 4.5 K off, covered 84 %, winding 3.7-3.8 K, and
  // the diagnosis still says the lag.
  const auto node = [](const mc::CaseResult& r, const std::string& name) {
    const auto it = std::find(r.nodes.begin(), r.nodes.end(), name);
    return static_cast<std::size_t>(it - r.nodes.begin());
  };
  for (const int seed : {1, 2}) {
    for (const bool adopt : {true, false}) {
      mc::CaseSpec spec;
      spec.sensor_lag_s = 90.0;
      spec.configured_lag_s = 30.0;
      spec.adopt_named_sensor_lag = adopt;
      spec.fault = mc::Fault::kCoolingLost;
      spec.fault_s = 3600.0;
      spec.duration_s = 3600.0 + 2400.0;
      spec.seed = static_cast<std::uint64_t>(seed);
      const mc::CaseResult r = mc::RunCase(spec, ModelDir());
      SCOPED_TRACE(testing::Message() << "seed " << seed << (adopt ? ", lag taken: " : ", not: ")
                                      << pe::DescribeFinding(r.at_end));
      const std::size_t frame = node(r, "frame"), winding = node(r, "winding");
      ASSERT_LT(winding, r.nodes.size());
      if (adopt) {
        EXPECT_EQ(r.at_end.effect, pe::MismatchEffect::kFrameAmbientResistance);
        EXPECT_GE(r.dist_coverage_after_fault[frame], 0.95);
        EXPECT_LE(r.dist_max_error_after_fault_K[frame], 2.0);
        EXPECT_LE(r.dist_max_error_after_fault_K[winding], 1.0);
      } else {
        EXPECT_GT(r.dist_max_error_after_fault_K[winding], 3.0);
      }
    }
  }
}

TEST(MismatchDetector, ATakenLagOutlivesARestartWhileItsConfigurationStands) {
  // The RTD of 90 s configured as 30 s, its lag named and taken in the first quarter hour; the
  // daemon restarts at 30 min from its whole saved state, and the cooling is lost (x4) ten
  // minutes later, before the diagnosis could name the lag again.
  const auto node = [](const mc::CaseResult& r, const std::string& name) {
    const auto it = std::find(r.nodes.begin(), r.nodes.end(), name);
    return static_cast<std::size_t>(it - r.nodes.begin());
  };
  const auto run = [](int seed, double configured_after_s, bool forget) {
    mc::CaseSpec spec;
    spec.sensor_lag_s = 90.0;
    spec.configured_lag_s = 30.0;
    spec.restart_s = 1800.0;
    spec.restart_whole = true;
    spec.restart_configured_lag_s = configured_after_s;
    spec.restart_forgets_lag = forget;
    spec.fault = mc::Fault::kCoolingLost;
    spec.fault_s = 2400.0;
    spec.duration_s = 2400.0 + 1800.0;
    spec.seed = static_cast<std::uint64_t>(seed);
    return mc::RunCase(spec, ModelDir());
  };
  for (const int seed : {1, 2}) {
    const mc::CaseResult kept = run(seed, 30.0, false);
    SCOPED_TRACE(testing::Message() << "seed " << seed << ": " << pe::DescribeFinding(kept.at_end));
    const std::size_t frame = node(kept, "frame"), winding = node(kept, "winding");
    ASSERT_LT(winding, kept.nodes.size());
    EXPECT_TRUE(kept.dist_sensor_lag_restored);
    EXPECT_NEAR(kept.dist_sensor_lag_at_end_s, 90.0, 18.0);
    EXPECT_GE(kept.dist_coverage_after_fault[frame], 0.95);
    EXPECT_LE(kept.dist_max_error_after_fault_K[frame], 2.0);
    EXPECT_LE(kept.dist_max_error_after_fault_K[winding], 1.0);
    // A state without it (an older file): the configured lag again, the fault read late.
    const mc::CaseResult lost = run(seed, 30.0, true);
    EXPECT_GT(lost.dist_max_error_after_fault_K[winding], 3.0);
    // The configuration changed to the lag the journal named: the operator's lag is read.
    const mc::CaseResult set = run(seed, 90.0, false);
    EXPECT_FALSE(set.dist_sensor_lag_restored);
    EXPECT_EQ(set.dist_sensor_lag_at_end_s, 90.0);
    EXPECT_LE(set.dist_max_error_after_fault_K[winding], 1.0);
  }
}

TEST(MismatchDetector, RejectsAnUnknownNode) {
  const std::string text = mc::ReadFile(ModelDir() + "/tmp-generic.toml");
  const auto model = pe::ThermalModel::Parse(text, "tmp-generic");
  pe::MismatchDetectorConfig c;
  c.measured_node = "housing";
  try {
    pe::MismatchDetector d(model, c);
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'housing'"), std::string::npos) << e.what();
  }
}

TEST(MismatchDetector, DescribesFindings) {
  pe::MismatchFinding f;
  f.state = pe::MismatchState::kPlantChange;
  f.effect = pe::MismatchEffect::kFrameAmbientResistance;
  f.value = 3.8;
  EXPECT_EQ(pe::DescribeFinding(f), "frame-to-ambient resistance x3.8 (cooling lost)");
  f.state = pe::MismatchState::kConsistent;
  EXPECT_EQ(pe::DescribeFinding(f), "consistent");
}

}  // namespace
