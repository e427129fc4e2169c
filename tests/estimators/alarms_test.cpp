#include "estimators/alarms.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace pumptherm::estimators {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

AlarmConfig Config() {
  AlarmConfig c;
  c.hysteresis_K = 2.0;
  c.hold_s = 2.0;
  c.not_converged_grace_s = 10.0;
  c.forecast_horizon_s = 300.0;
  c.sensor_node = 0;
  return c;
}

struct Fixture {
  AlarmMonitor m{Config(), {{80.0, 100.0}, {120.0, 140.0}}, {70.0, 90.0}};
  double nodes[2] = {kNaN, kNaN};
  AlarmInputs in;
  Fixture() { in.node_degC = nodes; }
  const AlarmState& At(double t) { return m.Step(t, in); }
};

TEST(Alarms, TripActsOnMeanPlusTwoSdWarningOnTheMean) {
  Fixture f;
  double sd[2] = {4.0, 0.0};
  f.in.node_sd_K = sd;
  f.nodes[1] = 20.0;
  f.nodes[0] = 91.0;  // mean below the trip level 100, mean + 2 sd = 99: a warning only
  for (double t = 0; t <= 5; t += 1) f.At(t);
  EXPECT_EQ(f.At(6).level, AlarmLevel::kWarning);
  EXPECT_TRUE(std::isnan(f.At(6).bound) || f.At(6).bound == 91.0) << "k_w = 0: the mean itself";
  f.nodes[0] = 92.5;  // mean + 2 sd = 100.5 >= 100: trip, though the mean is 7.5 K below
  for (double t = 7; t <= 12; t += 1) f.At(t);
  EXPECT_EQ(f.At(13).level, AlarmLevel::kTrip);
  EXPECT_EQ(f.At(13).reason, AlarmReason::kEstimatedOverTemperature);
  // The published state says which bound crossed the level: the value and the value + 2 sd.
  EXPECT_DOUBLE_EQ(f.At(13).value, 92.5);
  EXPECT_DOUBLE_EQ(f.At(13).bound, 100.5);
}

TEST(Alarms, SdFactorsAreSettings) {
  AlarmConfig c = Config();
  c.trip_sd_factor = 0.0;
  c.warning_sd_factor = 1.0;
  AlarmMonitor m(c, {{80.0, 100.0}}, {70.0, 90.0});
  double node = 77.0, sd = 4.0;  // mean + 1 sd = 81 >= 80: warning; trip on the mean
  AlarmInputs in;
  in.node_degC = &node;
  in.node_sd_K = &sd;
  for (double t = 0; t <= 5; t += 1) m.Step(t, in);
  EXPECT_EQ(m.state().level, AlarmLevel::kWarning);
  node = 97.0;  // mean + 1 sd above 100, the mean not: no trip with k = 0
  for (double t = 6; t <= 12; t += 1) m.Step(t, in);
  EXPECT_EQ(m.state().level, AlarmLevel::kWarning);
}

TEST(Alarms, QuietBelowLevels) {
  Fixture f;
  f.nodes[0] = 79.9;
  f.nodes[1] = 20.0;
  f.in.sensor_degC = 60.0;
  for (double t = 0; t < 100; t += 1) EXPECT_EQ(f.At(t).level, AlarmLevel::kNone) << t;
}

TEST(Alarms, WarningNeedsTheHoldTimeAndASpikeDoesNothing) {
  Fixture f;
  f.nodes[1] = 20.0;
  f.nodes[0] = 50.0;
  f.At(0);
  f.nodes[0] = 150.0;  // one wild sample, then back
  EXPECT_EQ(f.At(1).level, AlarmLevel::kNone);
  f.nodes[0] = 50.0;
  EXPECT_EQ(f.At(2).level, AlarmLevel::kNone);
  EXPECT_EQ(f.At(10).level, AlarmLevel::kNone);
  f.nodes[0] = 85.0;
  EXPECT_EQ(f.At(11).level, AlarmLevel::kNone);
  EXPECT_EQ(f.At(12).level, AlarmLevel::kNone);  // 1 s of 2 s hold
  const auto& s = f.At(13);
  EXPECT_EQ(s.level, AlarmLevel::kWarning);
  EXPECT_EQ(s.reason, AlarmReason::kEstimatedOverTemperature);
  EXPECT_EQ(s.node, 0);
  EXPECT_DOUBLE_EQ(s.value, 85.0);
}

TEST(Alarms, WarningClearsOnlyBelowLevelMinusHysteresis) {
  Fixture f;
  f.nodes[1] = 20.0;
  f.nodes[0] = 85.0;
  f.At(0);
  ASSERT_EQ(f.At(2).level, AlarmLevel::kWarning);
  f.nodes[0] = 78.5;  // below 80 but above 80 - 2
  for (double t = 3; t < 30; t += 1) EXPECT_EQ(f.At(t).level, AlarmLevel::kWarning) << t;
  f.nodes[0] = 77.9;
  f.At(30);
  EXPECT_EQ(f.At(31).level, AlarmLevel::kWarning);  // hold applies to clearing too
  EXPECT_EQ(f.At(32).level, AlarmLevel::kNone);
}

TEST(Alarms, TripLatchesUntilClearedAndReassertsWhenStillHot) {
  Fixture f;
  f.nodes[1] = 20.0;
  f.nodes[0] = 101.0;
  f.At(0);
  const auto s = f.At(2);
  EXPECT_EQ(s.level, AlarmLevel::kTrip);
  EXPECT_TRUE(s.trip_latched);
  f.nodes[0] = 30.0;  // cooled down: still latched
  for (double t = 3; t < 60; t += 1) EXPECT_EQ(f.At(t).level, AlarmLevel::kTrip) << t;
  EXPECT_TRUE(f.m.Clear());
  f.At(60);
  f.At(61);
  EXPECT_EQ(f.At(62).level, AlarmLevel::kNone);
  EXPECT_FALSE(f.m.Clear());
  // Clearing while still hot: the trip comes back after the hold time.
  f.nodes[0] = 105.0;
  f.At(70);
  ASSERT_EQ(f.At(72).level, AlarmLevel::kTrip);
  EXPECT_TRUE(f.m.Clear());
  EXPECT_FALSE(f.m.state().trip_latched);
  EXPECT_EQ(f.At(73).level, AlarmLevel::kTrip);
  EXPECT_TRUE(f.At(74).trip_latched);
}

TEST(Alarms, LatchedTripsSaveAndRestoreAcrossARestart) {
  Fixture f;
  f.nodes[0] = 50.0;
  f.nodes[1] = 150.0;       // node 1 over its trip level (140)
  f.in.sensor_degC = 95.0;  // the sensor over its own trip level (90)
  for (double t = 0; t <= 3; t += 1) f.At(t);
  ASSERT_TRUE(f.m.state().trip_latched);
  const auto trips = f.m.LatchedTrips();
  ASSERT_EQ(trips.size(), 2U);
  EXPECT_EQ(trips[0].node, 1);
  EXPECT_DOUBLE_EQ(trips[0].value, 150.0);
  EXPECT_EQ(trips[1].node, AlarmMonitor::kSensorTrip);
  EXPECT_DOUBLE_EQ(trips[1].value, 95.0);

  // A new monitor (the restarted daemon), the motor cool by now: still tripped until cleared.
  Fixture g;
  EXPECT_FALSE(g.m.RestoreLatchedTrip({2, 150.0}, 100.0)) << "node index out of range";
  EXPECT_FALSE(g.m.RestoreLatchedTrip({1, kNaN}, 100.0));
  EXPECT_FALSE(g.m.state().trip_latched);
  for (const auto& t : trips) EXPECT_TRUE(g.m.RestoreLatchedTrip(t, 100.0));
  EXPECT_EQ(g.m.state().level, AlarmLevel::kTrip);
  EXPECT_TRUE(g.m.state().trip_latched);
  EXPECT_EQ(g.m.state().node, 1);
  g.nodes[0] = 30.0;
  g.nodes[1] = 30.0;
  g.in.sensor_degC = 30.0;
  for (double t = 100; t <= 110; t += 1) EXPECT_EQ(g.At(t).level, AlarmLevel::kTrip) << t;
  EXPECT_EQ(g.m.LatchedTrips().size(), 2U);
  EXPECT_TRUE(g.m.Clear());
  for (double t = 111; t <= 115; t += 1) g.At(t);
  EXPECT_EQ(g.m.state().level, AlarmLevel::kNone);
  EXPECT_TRUE(g.m.LatchedTrips().empty());
}

TEST(Alarms, ClearingOneNodeLeavesTheOthersLatched) {
  Fixture f;
  f.nodes[0] = 50.0;
  f.nodes[1] = 150.0;
  f.in.sensor_degC = 95.0;
  for (double t = 0; t <= 3; t += 1) f.At(t);
  ASSERT_EQ(f.m.LatchedTrips().size(), 2U);
  EXPECT_FALSE(f.m.Clear(0)) << "node 0 was never latched";
  EXPECT_FALSE(f.m.Clear(AlarmMonitor::kStateLostTrip));
  EXPECT_FALSE(f.m.Clear(7)) << "no such node";
  EXPECT_TRUE(f.m.Clear(AlarmMonitor::kSensorTrip));
  ASSERT_EQ(f.m.LatchedTrips().size(), 1U);
  EXPECT_EQ(f.m.LatchedTrips()[0].node, 1);
  EXPECT_TRUE(f.m.state().trip_latched);
  EXPECT_FALSE(f.m.Clear(AlarmMonitor::kSensorTrip)) << "cleared already";
  EXPECT_TRUE(f.m.Clear(1));
  EXPECT_FALSE(f.m.state().trip_latched);
}

TEST(Alarms, StateLostIsALatchedTripOfThePumpUntilCleared) {
  Fixture f;
  f.nodes[0] = 30.0;
  f.nodes[1] = 30.0;
  f.m.LatchStateLost(0.0);
  EXPECT_EQ(f.m.state().level, AlarmLevel::kTrip);
  EXPECT_EQ(f.m.state().reason, AlarmReason::kSafetyStateLost);
  EXPECT_EQ(f.m.state().node, -1);
  EXPECT_TRUE(f.m.state().trip_latched);
  for (double t = 1; t <= 30; t += 1) EXPECT_EQ(f.At(t).level, AlarmLevel::kTrip) << t;
  const auto trips = f.m.LatchedTrips();
  ASSERT_EQ(trips.size(), 1U);
  EXPECT_EQ(trips[0].node, AlarmMonitor::kStateLostTrip);
  // Saved and restored like any latched trip; cleared, it is gone at once (no condition keeps it).
  Fixture g;
  EXPECT_TRUE(g.m.RestoreLatchedTrip(trips[0], 40.0));
  EXPECT_TRUE(g.m.state().trip_latched);
  EXPECT_TRUE(g.m.Clear(AlarmMonitor::kStateLostTrip));
  EXPECT_EQ(g.m.state().level, AlarmLevel::kNone);
  EXPECT_FALSE(g.m.state().trip_latched);
  EXPECT_EQ(std::string(AlarmReasonName(AlarmReason::kSafetyStateLost)), "safety_state_lost");
}

TEST(Alarms, SecondSenderWarnsAtOnceAndClearsAfterItsQuietTime) {
  AlarmConfig c = Config();
  c.second_sender_clear_s = 100.0;
  AlarmMonitor m(c, {{80.0, 100.0}}, {70.0, 90.0});
  double node = 30.0;
  AlarmInputs in;
  in.node_degC = &node;
  m.Step(0.0, in);
  m.RaiseSecondSender(5.0);
  EXPECT_EQ(m.state().level, AlarmLevel::kWarning);
  EXPECT_EQ(m.state().reason, AlarmReason::kSecondSender);
  EXPECT_FALSE(m.state().trip_latched);
  m.RaiseSecondSender(50.0);  // more evidence: the quiet time starts again
  EXPECT_EQ(m.Step(140.0, in).level, AlarmLevel::kWarning);
  EXPECT_EQ(m.Step(151.0, in).level, AlarmLevel::kNone);
  EXPECT_EQ(std::string(AlarmReasonName(AlarmReason::kSecondSender)), "second_sender");
}

TEST(Alarms, MeasuredSensorHasItsOwnLevels) {
  Fixture f;
  f.nodes[0] = 60.0;
  f.nodes[1] = 60.0;
  f.in.sensor_degC = 91.0;
  f.At(0);
  const auto& s = f.At(2);
  EXPECT_EQ(s.level, AlarmLevel::kTrip);
  EXPECT_EQ(s.reason, AlarmReason::kMeasuredOverTemperature);
  EXPECT_EQ(s.node, 0);
  EXPECT_DOUBLE_EQ(s.value, 91.0);
  const auto active = f.m.ActiveConditions();
  ASSERT_EQ(active.size(), 1U);
  EXPECT_DOUBLE_EQ(active[0].threshold, 90.0);
  EXPECT_TRUE(active[0].latched);
}

TEST(Alarms, TripOutranksAnEarlierWarning) {
  Fixture f;
  f.nodes[0] = 85.0;
  f.nodes[1] = 20.0;
  f.At(0);
  ASSERT_EQ(f.At(2).level, AlarmLevel::kWarning);
  f.nodes[1] = 141.0;
  f.At(3);
  const auto& s = f.At(5);
  EXPECT_EQ(s.level, AlarmLevel::kTrip);
  EXPECT_EQ(s.node, 1);
  EXPECT_EQ(s.active_reasons, 1U << static_cast<unsigned>(AlarmReason::kEstimatedOverTemperature));
  // Both conditions are listed, the trip first.
  const auto active = f.m.ActiveConditions();
  ASSERT_EQ(active.size(), 2U);
  EXPECT_EQ(active[0].level, AlarmLevel::kTrip);
  EXPECT_EQ(active[0].node, 1);
  EXPECT_DOUBLE_EQ(active[0].threshold, 140.0);
  EXPECT_EQ(active[1].level, AlarmLevel::kWarning);
  EXPECT_EQ(active[1].node, 0);
}

TEST(Alarms, NaNNeitherRaisesNorClears) {
  Fixture f;
  f.nodes[1] = 20.0;
  f.nodes[0] = 85.0;
  f.At(0);
  ASSERT_EQ(f.At(2).level, AlarmLevel::kWarning);
  f.nodes[0] = kNaN;
  for (double t = 3; t < 20; t += 1) EXPECT_EQ(f.At(t).level, AlarmLevel::kWarning);
}

TEST(Alarms, RateOfRise) {
  AlarmConfig c = Config();
  c.max_rise_K_per_min = 3.0;
  c.rate_window_s = 60.0;
  AlarmMonitor m(c, {{200.0, 250.0}}, {200.0, 250.0});
  double node = 20.0;
  AlarmInputs in;
  in.node_degC = &node;
  // 2 K/min for 5 minutes: quiet; then 6 K/min: warning at the end of the next window.
  double t = 0;
  for (; t <= 300; t += 1) {
    node = 20.0 + 2.0 * t / 60.0;
    EXPECT_EQ(m.Step(t, in).level, AlarmLevel::kNone) << t;
  }
  bool warned = false;
  for (; t <= 430; t += 1) {
    node = 30.0 + 6.0 * (t - 300.0) / 60.0;
    const auto& s = m.Step(t, in);
    if (s.level == AlarmLevel::kWarning) {
      EXPECT_EQ(s.reason, AlarmReason::kRateOfRise);
      EXPECT_NEAR(s.value, 6.0, 1e-9);
      warned = true;
      break;
    }
  }
  EXPECT_TRUE(warned);
  EXPECT_LE(t, 421);  // within one window (+1 s) of the change
}

TEST(Alarms, StaleTelemetryFollowsTheHoldBothWays) {
  Fixture f;
  f.in.telemetry_age_s = 1.0;
  EXPECT_EQ(f.At(0).level, AlarmLevel::kNone);
  f.in.telemetry_age_s = 2.5;
  EXPECT_EQ(f.At(1).level, AlarmLevel::kNone);  // 0 s of the 2 s hold
  f.in.telemetry_age_s = 0.01;                  // one frame got through: the hold restarts
  EXPECT_EQ(f.At(2).level, AlarmLevel::kNone);
  f.in.telemetry_age_s = 2.5;
  f.At(3);
  EXPECT_EQ(f.At(4).level, AlarmLevel::kNone);
  const auto s = f.At(5);
  EXPECT_EQ(s.level, AlarmLevel::kWarning);
  EXPECT_EQ(s.reason, AlarmReason::kStaleTelemetry);
  f.in.telemetry_age_s = 0.01;
  EXPECT_EQ(f.At(6).level, AlarmLevel::kWarning);  // clearing holds too
  EXPECT_EQ(f.At(7).level, AlarmLevel::kWarning);
  EXPECT_EQ(f.At(8).level, AlarmLevel::kNone);
}

TEST(Alarms, SensorFaultIsItsOwnAlarmWithTheHold) {
  Fixture f;
  f.in.sensor_raw_degC = 40.0;
  f.in.sensor_fault = SensorFault::kMissing;
  EXPECT_EQ(f.At(0).level, AlarmLevel::kNone);
  const auto s = f.At(2);
  EXPECT_EQ(s.level, AlarmLevel::kWarning);
  EXPECT_EQ(s.reason, AlarmReason::kSensorFault);
  EXPECT_TRUE(s.active_reasons & (1U << static_cast<unsigned>(AlarmReason::kSensorFault)));
  const auto c = f.m.ActiveConditions();
  ASSERT_EQ(c.size(), 1U);
  EXPECT_STREQ(c[0].detail, "missing");
  // The off-delay: one good reading for 5 s is no recovery (a lossy link); 30 s are.
  f.in.sensor_fault = SensorFault::kNone;
  f.At(3);
  EXPECT_EQ(f.At(8).level, AlarmLevel::kWarning);
  f.in.sensor_fault = SensorFault::kMissing;
  EXPECT_EQ(f.At(9).level, AlarmLevel::kWarning);
  f.in.sensor_fault = SensorFault::kNone;
  f.At(10);
  EXPECT_EQ(f.At(39).level, AlarmLevel::kWarning);
  EXPECT_EQ(f.At(40).level, AlarmLevel::kNone);
}

TEST(Alarms, SensorStuckAndDisagreeing) {
  Fixture f;
  f.in.sensor_degC = f.in.sensor_raw_degC = 40.0;
  f.At(3);
  // Stuck: the reading frozen at 40.0 since t = 3 while the model moves 5 K in 120 s: the
  // alarm comes once the reading has been frozen for 120 s (t = 123) and the model moved > 2 K,
  // after the hold (t = 125).
  for (double t = 6; t < 125; t += 1) {
    f.in.sensor_model_degC = 40.0 + 5.0 * (t - 6) / 120.0;
    EXPECT_EQ(f.At(t).level, AlarmLevel::kNone) << t;
  }
  f.in.sensor_model_degC = 44.9;
  EXPECT_EQ(f.At(125).reason, AlarmReason::kImplausibleSensor);
  f.in.sensor_degC = f.in.sensor_raw_degC = 40.1;
  f.At(126);
  EXPECT_EQ(f.At(128).level, AlarmLevel::kNone);

  // Disagreement: NIS above 10.83 for 30 s.
  f.in.sensor_nis = 25.0;
  f.At(130);
  EXPECT_EQ(f.At(159).level, AlarmLevel::kNone);
  EXPECT_EQ(f.At(160).reason, AlarmReason::kImplausibleSensor);
}

// A reading that stepped away from the frame (the disturbance-state filter's sum of offset steps)
// by more than max_sensor_offset_K (1 K) is implausible, "offset", after the hold; a step back
// clears it; a slow drift of the offset state is not an input here, and 0.6 K is within.
TEST(Alarms, AReadingSteppedAwayFromTheFrameIsAnImplausibleOffset) {
  Fixture f;
  f.in.sensor_degC = f.in.sensor_raw_degC = 40.0;
  f.in.sensor_offset_K = 0.6;
  for (double t = 0; t <= 10; t += 1) EXPECT_EQ(f.At(t).level, AlarmLevel::kNone) << t;
  f.in.sensor_offset_K = 3.0;
  f.At(11);
  EXPECT_EQ(f.At(12).level, AlarmLevel::kNone);
  const AlarmState& s = f.At(13);
  EXPECT_EQ(s.level, AlarmLevel::kWarning);
  EXPECT_EQ(s.reason, AlarmReason::kImplausibleSensor);
  EXPECT_DOUBLE_EQ(s.value, 3.0);
  const auto c = f.m.ActiveConditions();
  ASSERT_EQ(c.size(), 1U);
  EXPECT_STREQ(c[0].detail, "offset");
  f.in.sensor_offset_K = -2.0;  // stepped the other way past it: still implausible
  EXPECT_EQ(f.At(20).level, AlarmLevel::kWarning);
  f.in.sensor_offset_K = 0.1;  // back
  f.At(21);
  EXPECT_EQ(f.At(23).level, AlarmLevel::kNone);
}

// The hold counts time in a band or above: 110/125 alternating against 100/120 is a warning.
TEST(Alarms, ValueMovingBetweenBandsKeepsTheWarningHold) {
  AlarmMonitor m(Config(), {{100.0, 120.0}}, {});
  double node = 0.0;
  AlarmInputs in;
  in.node_degC = &node;
  AlarmLevel level = AlarmLevel::kNone;
  for (int t = 0; t <= 3; ++t) {
    node = t % 2 == 0 ? 110.0 : 125.0;
    level = m.Step(t, in).level;
  }
  EXPECT_EQ(level, AlarmLevel::kWarning);
  // Then above trip for the hold: trip (the trip band's own hold started at its first sample).
  node = 125.0;
  m.Step(4, in);
  m.Step(5, in);
  EXPECT_EQ(m.Step(6, in).level, AlarmLevel::kTrip);
}

// NaN (a lost sample) never restarts a pending trip: 125/NaN alternating trips after the hold.
TEST(Alarms, NaNNeverRestartsAPendingTrip) {
  AlarmMonitor m(Config(), {{100.0, 120.0}}, {});
  double node = 0.0;
  AlarmInputs in;
  in.node_degC = &node;
  node = 125.0;
  EXPECT_EQ(m.Step(0, in).level, AlarmLevel::kNone);
  node = kNaN;
  EXPECT_EQ(m.Step(1, in).level, AlarmLevel::kNone);
  node = 125.0;
  EXPECT_EQ(m.Step(2, in).level, AlarmLevel::kTrip);
}

TEST(SensorHealth, MissingStuckOutOfRangeAndJumping) {
  AlarmConfig c = Config();
  c.stale_after_s = 2.0;
  c.flat_after_s = 30.0;
  c.max_step_K = 5.0;
  c.jump_recover_s = 30.0;
  SensorHealth h(c);
  EXPECT_EQ(h.Fault(0.0), SensorFault::kMissing);  // never read
  // A live sensor at 10 Hz: the last digit moves.
  double t = 0.0;
  for (; t < 60.0; t += 0.1) {
    h.OnReading(t, 40.0 + 0.1 * (static_cast<int>(t * 10) % 2));
    ASSERT_EQ(h.Fault(t), SensorFault::kNone) << t;
  }
  // Frozen: stuck once 30 s without a change.
  const double frozen_at = t;
  for (; t < frozen_at + 29.9; t += 0.1) {
    h.OnReading(t, 40.0);
    ASSERT_EQ(h.Fault(t), SensorFault::kNone) << t;
  }
  h.OnReading(frozen_at + 30.05, 40.0);
  EXPECT_EQ(h.Fault(frozen_at + 30.05), SensorFault::kStuck);
  // Silent: missing after 2 s; NaN readings (not available) do not count as readings.
  h.OnReading(100.0, 40.1);
  h.OnReading(101.0, kNaN);
  EXPECT_EQ(h.Fault(102.0), SensorFault::kNone);
  EXPECT_EQ(h.Fault(102.1), SensorFault::kMissing);
  // Out of range.
  h.OnReading(103.0, 300.0);
  EXPECT_EQ(h.Fault(103.0), SensorFault::kOutOfRange);
  // A jump of more than 5 K between consecutive readings: out for 30 s after the last jump.
  // Across a silence (7 s here) a step is no jump: the node may have warmed meanwhile.
  h.OnReading(110.0, 40.0);
  h.OnReading(110.1, 40.1);
  EXPECT_EQ(h.Fault(110.1), SensorFault::kNone);
  h.OnReading(110.2, 30.0);
  EXPECT_EQ(h.Fault(110.2), SensorFault::kJumping);
  h.OnReading(140.0, 40.2);
  EXPECT_EQ(h.Fault(140.0), SensorFault::kJumping);  // 30 s after 110.2, not yet over
  h.OnReading(140.3, 40.3);
  EXPECT_EQ(h.Fault(140.3), SensorFault::kNone);
  h.OnReading(140.4, 47.0);
  EXPECT_EQ(h.Fault(140.4), SensorFault::kJumping);
  h.OnReading(170.5, 47.1);
  EXPECT_EQ(h.Fault(170.5), SensorFault::kNone);
}

// A steady motor gives a steady reading: frozen while the model is flat too is not "stuck".
TEST(Alarms, FrozenSensorWithAFlatModelIsNotStuck) {
  Fixture f;
  f.in.sensor_degC = f.in.sensor_raw_degC = 40.0;
  f.in.sensor_model_degC = 40.0;
  for (double t = 0; t < 1000; t += 1) {
    f.in.sensor_model_degC = 40.0 + 0.5 * std::sin(t / 50.0);
    EXPECT_EQ(f.At(t).level, AlarmLevel::kNone) << t;
  }
}

TEST(Alarms, NotConvergedOnlyAfterTheGracePeriod) {
  Fixture f;
  f.in.estimators_converged = false;
  EXPECT_EQ(f.At(0).level, AlarmLevel::kNone);
  EXPECT_EQ(f.At(9).level, AlarmLevel::kNone);
  f.At(10);
  EXPECT_EQ(f.At(12).reason, AlarmReason::kEstimatorNotConverged);
}

TEST(Alarms, ForecastWarnsBelowTheHorizonWithHysteresis) {
  Fixture f;
  f.in.time_to_trip_s = 400.0;
  f.At(0);
  EXPECT_EQ(f.At(5).level, AlarmLevel::kNone);
  f.in.time_to_trip_s = 250.0;
  f.in.time_to_trip_node = 1;
  f.At(6);
  const auto s = f.At(8);
  EXPECT_EQ(s.reason, AlarmReason::kForecast);
  EXPECT_EQ(s.node, 1);
  EXPECT_DOUBLE_EQ(s.time_to_trip_s, 250.0);
  f.in.time_to_trip_s = 320.0;  // above 300 but below 330: stays
  EXPECT_EQ(f.At(20).level, AlarmLevel::kWarning);
  f.in.time_to_trip_s = std::numeric_limits<double>::infinity();
  f.At(21);
  // The off-delay: beyond the horizon for forecast_clear_s (60 s) before it clears.
  EXPECT_EQ(f.At(23).level, AlarmLevel::kWarning);
  EXPECT_EQ(f.At(80).level, AlarmLevel::kWarning);
  EXPECT_EQ(f.At(82).level, AlarmLevel::kNone);
}

// A load alternating every 20 s between a phase that forecasts a trip and one that does not: one
// forecast warning, held through the light phases, not one per cycle.
TEST(Alarms, ForecastOnAnAlternatingLoadDoesNotChatter) {
  Fixture f;
  int changes = 0;
  AlarmLevel last = AlarmLevel::kNone;
  for (double t = 0; t < 600; t += 1) {
    const bool heavy = static_cast<int>(t / 20.0) % 2 == 1;
    f.in.time_to_trip_s = heavy ? 200.0 : std::numeric_limits<double>::infinity();
    const AlarmLevel level = f.At(t).level;
    if (level != last) ++changes;
    last = level;
  }
  EXPECT_EQ(changes, 1);
  EXPECT_EQ(last, AlarmLevel::kWarning);
}

TEST(Alarms, RejectsTripBelowWarning) {
  EXPECT_THROW(AlarmMonitor(Config(), {{100.0, 90.0}}, {}), std::invalid_argument);
}

}  // namespace
}  // namespace pumptherm::estimators
