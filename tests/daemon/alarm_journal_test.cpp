// The journal's words for alarm changes and diagnoses: every number in its unit, seconds never
// read as degC, the sensor fault's kind, the cause named with its date, and the structured fields
// that find the line (journalctl PUMP=pump3 LEVEL=trip).
#include "daemon/alarm_journal.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <ctime>
#include <map>

namespace pumptherm::daemon {
namespace {

using estimators::AlarmCondition;
using estimators::AlarmLevel;
using estimators::AlarmReason;
using estimators::AlarmState;

const std::vector<std::string> kNodes{"frame", "stator", "winding", "rotor"};

/// 2026-01-01 00:04:01 UTC in the pipeline's seconds, with the wall offset 0 (offline).
constexpr double kOnset_s = 1767225841.0;

class AlarmJournal : public testing::Test {
 protected:
  void SetUp() override {
    setenv("TZ", "UTC", 1);
    tzset();
    config_.sensor_node = 0;
    config_.stale_after_s = 2.0;
    config_.trip_sd_factor = 2.0;
  }
  JournalEntry Entry(const AlarmState& a, std::vector<AlarmCondition> conditions,
                     std::uint16_t logged = 0, const estimators::MismatchFinding* f = nullptr) {
    conditions_ = std::move(conditions);
    return AlarmEntry({"pump3", &a, conditions_, &kNodes, logged, &config_, "frame", f, 0});
  }
  static std::map<std::string, std::string> Fields(const JournalEntry& e) {
    std::map<std::string, std::string> m;
    for (const LogField& f : e.fields) m[std::string(f.key)] = f.value;
    return m;
  }
  estimators::AlarmConfig config_;
  std::vector<AlarmCondition> conditions_;
};

constexpr std::uint16_t Bit(AlarmReason r) {
  return static_cast<std::uint16_t>(1u << static_cast<unsigned>(r));
}

estimators::MismatchFinding CoolingLost() {
  estimators::MismatchFinding f;
  f.state = estimators::MismatchState::kPlantChange;
  f.effect = estimators::MismatchEffect::kFrameAmbientResistance;
  f.value = 20.0;
  f.onset_s = kOnset_s;
  f.window_nis = 9712.4;
  f.threshold = 135.7;
  return f;
}

TEST_F(AlarmJournal, TripSaysTheBoundTheLevelAndTheCauseWithItsDate) {
  AlarmState a;
  a.level = AlarmLevel::kTrip;
  a.reason = AlarmReason::kEstimatedOverTemperature;
  a.node = 2;
  a.value = 121.34;
  a.bound = 126.12;
  a.active_reasons = Bit(AlarmReason::kEstimatedOverTemperature) | Bit(AlarmReason::kForecast);
  a.trip_latched = true;
  const auto f = CoolingLost();
  const JournalEntry e =
      Entry(a,
            {{AlarmLevel::kTrip, AlarmReason::kEstimatedOverTemperature, "", 2, 121.34, 120.0,
              1767226700.0, true},
             {AlarmLevel::kWarning, AlarmReason::kForecast, "", 2, 0.0, NAN, 1767226500.0, false}},
            Bit(AlarmReason::kEstimatedOverTemperature) | Bit(AlarmReason::kForecast), &f);
  EXPECT_EQ(e.text,
            "pump3: trip: winding 121.3 degC (bound 126.1 = estimate + 2 sd) >= 120 degC; cause: "
            "cooling lost (frame-to-ambient resistance x20 or more) since 2026-01-01 00:04:01 UTC; "
            "also active: forecast; trip latched until cleared");
  EXPECT_EQ(e.level, LogLevel::kError);  // journalctl -p err lists every trip
  const auto m = Fields(e);
  EXPECT_EQ(m.at("PUMP"), "pump3");
  EXPECT_EQ(m.at("LEVEL"), "trip");
  EXPECT_EQ(m.at("REASON"), "estimated_over_temperature");
  EXPECT_EQ(m.at("NODE"), "winding");
  EXPECT_EQ(m.at("VALUE_DEGC"), "121.34");
  EXPECT_EQ(m.at("THRESHOLD_DEGC"), "120");
  EXPECT_EQ(m.at("CAUSE"), "frame_ambient_resistance");
  EXPECT_EQ(m.at("RULE"), "band");
}

// Running blind, the value is the worst case of a cooling failure nothing could see: the line
// says so rather than calling it the estimate, and RULE finds such trips. The status frames'
// silence that made it blind is no telemetry silence's worst case: no such cause.
TEST_F(AlarmJournal, ATripOnTheBlindWorstCaseSaysSo) {
  AlarmState a;
  a.level = AlarmLevel::kTrip;
  a.reason = AlarmReason::kEstimatedOverTemperature;
  a.node = 2;
  a.value = 118.2;
  a.bound = 121.0;
  a.active_reasons = Bit(AlarmReason::kEstimatedOverTemperature) |
                     Bit(AlarmReason::kStaleTelemetry) | Bit(AlarmReason::kSensorFault);
  conditions_ = {{AlarmLevel::kTrip, AlarmReason::kEstimatedOverTemperature, "", 2, 118.2, 120.0,
                  1767225757.0, true}};
  const JournalEntry e = AlarmEntry({"pump3", &a, conditions_, &kNodes, a.active_reasons, &config_,
                                     "frame", nullptr, 0, 15.0, estimators::AlarmRule::kBlind});
  EXPECT_EQ(e.text,
            "pump3: trip: winding 118.2 degC (bound 121.0 = blind worst case of an unseen cooling "
            "failure + 2 sd) >= 120 degC; also active: stale telemetry, sensor fault");
  EXPECT_EQ(Fields(e).at("RULE"), "blind");
  EXPECT_EQ(Fields(e).count("CAUSE"), 0u);
}

TEST_F(AlarmJournal, ATripDuringASilenceSaysItActsOnTheLargestCurrentsWorstCase) {
  AlarmState a;
  a.level = AlarmLevel::kTrip;
  a.reason = AlarmReason::kEstimatedOverTemperature;
  a.node = 2;
  a.value = 124.1;
  a.bound = 129.3;
  a.active_reasons =
      Bit(AlarmReason::kEstimatedOverTemperature) | Bit(AlarmReason::kStaleTelemetry);
  a.trip_latched = true;
  conditions_ = {
      {AlarmLevel::kTrip, AlarmReason::kEstimatedOverTemperature, "", 2, 124.1, 120.0, 1767225757.0,
       true},
      {AlarmLevel::kWarning, AlarmReason::kStaleTelemetry, "", -1, 4.1, NAN, 1767225724.0, false}};
  const auto f = CoolingLost();
  const std::uint16_t logged = Bit(AlarmReason::kStaleTelemetry);
  const JournalEntry e = AlarmEntry({"pump3", &a, conditions_, &kNodes, logged, &config_, "frame",
                                     &f, 0, 15.0, estimators::AlarmRule::kSilence});
  EXPECT_EQ(e.text,
            "pump3: trip: winding 124.1 degC (bound 129.3 = worst case of the load the telemetry "
            "silence may hide + 2 sd) >= 120 degC; cause: no telemetry: the level acts on the "
            "worst case of the drive's largest current (15 A) "
            "since the last frame; also active: stale telemetry; raised: estimated over "
            "temperature; trip latched until cleared");
  EXPECT_EQ(Fields(e).at("CAUSE"), "telemetry_silence");
  EXPECT_EQ(Fields(e).at("RULE"), "silence");
  // Without the largest current stated, the levels act on the estimate: no such cause.
  const JournalEntry plain =
      AlarmEntry({"pump3", &a, conditions_, &kNodes, logged, &config_, "frame", nullptr, 0, 0.0});
  EXPECT_EQ(plain.text.find("largest current"), std::string::npos);
  EXPECT_EQ(Fields(plain).count("CAUSE"), 0u);
}

TEST_F(AlarmJournal, ATripLatchedAgainAfterARestartSaysItsBoundReachedTheLevel) {
  // RestoreLatchedTrip keeps the value that raised the trip (the estimate), not its bound.
  AlarmState a;
  a.level = AlarmLevel::kTrip;
  a.reason = AlarmReason::kEstimatedOverTemperature;
  a.node = 2;
  a.value = 116.8;
  a.active_reasons = Bit(AlarmReason::kEstimatedOverTemperature);
  a.trip_latched = true;
  const JournalEntry e = Entry(a, {{AlarmLevel::kTrip, AlarmReason::kEstimatedOverTemperature, "",
                                    2, 116.8, 120.0, 0.0, true}});
  EXPECT_EQ(e.text,
            "pump3: trip: winding 116.8 degC with estimate + 2 sd >= 120 degC; raised: estimated "
            "over temperature; trip latched until cleared");
  EXPECT_EQ(Fields(e).count("RULE"), 0u);  // not saved, like the bound
}

TEST_F(AlarmJournal, SecondsAreSecondsNeverDegC) {
  AlarmState a;
  a.level = AlarmLevel::kWarning;
  a.reason = AlarmReason::kForecast;
  a.node = 2;
  a.value = 276.21;
  a.active_reasons = Bit(AlarmReason::kForecast);
  config_.forecast_horizon_s = 300.0;
  JournalEntry e =
      Entry(a, {{AlarmLevel::kWarning, AlarmReason::kForecast, "", 2, 276.21, NAN, 0.0, false}});
  EXPECT_EQ(e.text,
            "pump3: warning: winding reaches its trip level in 4 min 36 s at the present load "
            "(horizon 5 min); raised: forecast");
  EXPECT_EQ(Fields(e).count("VALUE_DEGC"), 0u) << "a time to trip is no temperature";

  a.reason = AlarmReason::kStaleTelemetry;
  a.node = -1;
  a.value = 4.0;
  a.active_reasons = Bit(AlarmReason::kStaleTelemetry);
  e = Entry(a, {{AlarmLevel::kWarning, AlarmReason::kStaleTelemetry, "", -1, 4.0, NAN,
                 kOnset_s + 4.25, false}});
  // The last frame's time, which stays true on a later line of the same silence.
  EXPECT_EQ(e.text,
            "pump3: warning: no telemetry since 2026-01-01 00:04:01 UTC (limit 2 s); raised: "
            "stale telemetry");
  EXPECT_EQ(Fields(e).count("VALUE_DEGC"), 0u);
  EXPECT_EQ(Fields(e).count("NODE"), 0u);
}

TEST_F(AlarmJournal, SensorFaultsNameTheirKind) {
  AlarmState a;
  a.level = AlarmLevel::kWarning;
  a.reason = AlarmReason::kSensorFault;
  a.node = 0;
  a.active_reasons = Bit(AlarmReason::kSensorFault);
  for (const auto& [kind, words] : std::map<std::string, std::string>{
           {"missing", "missing (no reading for 2 s)"},
           {"stuck", "stuck (unchanged to the last bit for 30 s)"},
           {"out of range", "out of range (-40 to 250 degC)"},
           {"jumping", "jumping (a step above 5 K between readings)"}}) {
    const JournalEntry e = Entry(a, {{AlarmLevel::kWarning, AlarmReason::kSensorFault, kind.c_str(),
                                      0, 31.5, NAN, 0, false}});
    EXPECT_EQ(e.text,
              "pump3: warning: frame sensor fault: " + words +
                  ", last reading 31.5 degC; left out of the estimate; raised: sensor fault");
    EXPECT_EQ(Fields(e).at("VALUE_DEGC"), "31.50");
    EXPECT_EQ(Fields(e).at("NODE"), "frame");
  }
}

TEST_F(AlarmJournal, BackToNormalSaysWhatCleared) {
  AlarmState a;
  const JournalEntry e = Entry(a, {}, Bit(AlarmReason::kStaleTelemetry));
  EXPECT_EQ(e.text, "pump3: normal: no alarm; cleared: stale telemetry");
  EXPECT_EQ(e.level, LogLevel::kNotice);
  EXPECT_EQ(Fields(e).at("LEVEL"), "normal");
  EXPECT_EQ(Fields(e).at("REASON"), "none");
}

TEST_F(AlarmJournal, TheWindingFromResistanceHasItsName) {
  AlarmState a;
  a.level = AlarmLevel::kWarning;
  a.reason = AlarmReason::kEstimatedOverTemperature;
  a.node = 4;  // one past the model's nodes
  a.value = 101.0;
  a.active_reasons = Bit(AlarmReason::kEstimatedOverTemperature);
  const JournalEntry e = Entry(a, {{AlarmLevel::kWarning, AlarmReason::kEstimatedOverTemperature,
                                    "", 4, 101.0, 100.0, 0, false}});
  EXPECT_EQ(
      e.text,
      "pump3: warning: winding from resistance 101.0 degC >= 100 degC; raised: estimated over "
      "temperature");
  EXPECT_EQ(Fields(e).at("NODE"), "winding_resistance");
}

TEST_F(AlarmJournal, AStartSaysWhetherTheCalibrationCameFromAColdStart) {
  estimators::PumpEstimate s;
  s.start = estimators::EstimateStart::kWarm;
  s.frame_measured_degC = 45.04;
  s.ambient_degC = 22.0;
  s.speed_rpm = 21000.0;
  JournalEntry e = StartEntry("pump3", s, true);
  EXPECT_EQ(e.text,
            "pump3: estimate started warm (frame 45.0 degC, ambient 22.0 degC, 21000 r/min): the "
            "magnet from the flux waits for a cold start (the pump at rest at the ambient) to "
            "learn this pump's psi0, and its node is published with the nameplate flux's "
            "tolerance until then");
  EXPECT_EQ(e.level, LogLevel::kNotice);
  EXPECT_EQ(Fields(e).at("START"), "warm");
  e = StartEntry("pump3", s, false);
  EXPECT_EQ(e.text,
            "pump3: estimate started warm (frame 45.0 degC, ambient 22.0 degC, 21000 r/min)");

  s.start = estimators::EstimateStart::kCold;
  s.calibrated_at_cold_start = true;
  s.frame_measured_degC = s.ambient_degC = 22.0;
  s.speed_rpm = 0.0;
  e = StartEntry("pump1", s, true);
  EXPECT_EQ(e.text,
            "pump1: estimate started cold (frame 22.0 degC, ambient 22.0 degC, 0 r/min): this "
            "pump's R0 and psi0 are learnt from a cold start");
  // With the voltage fused, the run-up at a constant current learns psi0; R0 needs a load change.
  e = StartEntry("pump1", s, true, true);
  EXPECT_EQ(e.text,
            "pump1: estimate started cold (frame 22.0 degC, ambient 22.0 degC, 0 r/min): this "
            "pump's psi0 is learnt in the run-up, its R0 at the first load change (the winding "
            "from resistance waits for it)");
  // The frame still warm from a run (PumpEstimatorConfig::cold_start_warm_frame_K).
  s.frame_measured_degC = 24.9;
  s.start_span_K = 10.83;
  e = StartEntry("pump1", s, true, true);
  EXPECT_EQ(e.text,
            "pump1: estimate started cold (frame 24.9 degC, ambient 22.0 degC, 0 r/min; the frame "
            "still warm from a run, so the nodes that cool slower are taken between its "
            "temperature and up to 10.8 K above it): this pump's psi0 is learnt in the run-up, "
            "its R0 at the first load change (the winding from resistance waits for it)");

  s.start = estimators::EstimateStart::kWarm;
  s.calibrated_at_cold_start = false;
  s.frame_measured_degC = 29.0;
  s.start_span_K = 25.12;
  e = StartEntry("pump1", s, false);
  EXPECT_EQ(e.text,
            "pump1: estimate started warm (frame 29.0 degC, ambient 22.0 degC, 0 r/min; the frame "
            "still warm from a run, so the nodes that cool slower may be up to 25.1 K above it)");
  s.start_span_K = 0.0;
  s.calibrated_at_cold_start = true;

  s.start = estimators::EstimateStart::kRestored;
  e = StartEntry("pump1", s, true);
  EXPECT_EQ(e.text,
            "pump1: estimate restored from the saved state: this pump's R0 and psi0 are learnt "
            "from a cold start");
  EXPECT_EQ(Fields(e).at("START"), "restored");
  // A configuration that states the losses further off than the saved state did.
  s.losses_sd_widened_from = 0.1;
  s.losses_sd_widened_to = 0.3;
  e = StartEntry("pump1", s, false);
  EXPECT_EQ(e.text,
            "pump1: estimate restored from the saved state, its loss scale widened to the 0.3 now "
            "stated (model_losses_sd_rel; saved with 0.1); what the filter had learnt stays, so "
            "it covers less than a start at 0.3 would");
}

TEST_F(AlarmJournal, R0LinesSayTheResistanceLearntOrLostAgain) {
  estimators::PumpEstimate s;
  s.calibration.dr = 0.0203;
  s.calibration.dr_sd = 0.0048;
  s.winding_resistance_degC = 52.34;
  s.identification.status = estimators::ResistanceStatus::kTracking;
  estimators::CopperLaw cu;
  cu.r0_ohm = 0.28;
  cu.t0_degC = 20.0;
  cu.alpha_per_K = 0.0039;
  JournalEntry e = R0Entry("pump1", s, cu, 3.0, 52.34);
  EXPECT_EQ(e.text,
            "pump1: R0 learnt: 0.2857 ohm at 20.0 degC, +2.0 % against the nameplate (sd 0.5 %); "
            "the winding from resistance is published from now (52.3 degC)");
  EXPECT_EQ(e.level, LogLevel::kNotice);
  EXPECT_EQ(Fields(e).at("PUMP"), "pump1");
  s.identification.status = estimators::ResistanceStatus::kConverging;
  s.calibration.dr_sd = 0.0112;
  e = R0Entry("pump1", s, cu, 3.0, 71.24);
  EXPECT_EQ(e.text,
            "pump1: R0's sd (1.1 %) grew past 3.0 K of winding at 71.2 degC: the winding from "
            "resistance is withheld until a load change pins R0 again");
}

TEST_F(AlarmJournal, MagnetLawLineSaysWhatTheFilterNeedsAndWhatToSet) {
  estimators::PumpEstimate s;
  s.rotor_heat_W = -6.62;
  s.rotor_heat_sd_W = 1.51;
  const JournalEntry e = MagnetLawEntry("pump1", s, -0.001);
  EXPECT_EQ(e.text,
            "pump1: the magnet from the flux reads the rotor colder than the thermal model's "
            "rotor losses make it (the filter needs -6.6 W, sd 1.5 W, of rotor heat to follow "
            "it): either the motor file's magnet law (-0.100 %/K) is steeper than this magnet's "
            "(NdFeB about -0.09 to -0.13 %/K, SmCo -0.03 to -0.05 %/K), or the thermal model's "
            "rotor losses are too high. The estimate gives that law up from now on (kept across "
            "restarts while the motor file states it): the voltage reads the winding through its "
            "resistance alone, the rotor is the thermal model's with a wider sd, and no magnet "
            "from the flux is published (a failed frame sensor then leaves the pump blind); "
            "check the magnet's flux_temperature_coefficient_per_K in the motor file and the "
            "rotor's losses in the thermal model");
  EXPECT_EQ(e.level, LogLevel::kWarning);
  EXPECT_EQ(Fields(e).at("PUMP"), "pump1");
}

TEST_F(AlarmJournal, DiagnosisSaysTheCauseFirstAndTheTestLast) {
  JournalEntry e = DiagnosisEntry("pump3", CoolingLost(), "frame", 0);
  EXPECT_EQ(e.text,
            "pump3: diagnosis: cooling lost (frame-to-ambient resistance x20 or more) since "
            "2026-01-01 00:04:01 UTC; the model no longer explains the frame sensor (window NIS "
            "9712 > 136)");
  EXPECT_EQ(e.level, LogLevel::kWarning);
  EXPECT_EQ(Fields(e).at("CAUSE"), "frame_ambient_resistance");
  EXPECT_EQ(Fields(e).at("DIAGNOSIS"), "plant_change");
  // Live, the pipeline's clock is monotonic: the wall offset makes the date right.
  auto f = CoolingLost();
  f.onset_s = 100.0;
  e = DiagnosisEntry("pump3", f, "frame", static_cast<std::int64_t>((kOnset_s - 100.0) * 1e6));
  EXPECT_NE(e.text.find("since 2026-01-01 00:04:01 UTC"), std::string::npos) << e.text;

  f = CoolingLost();
  f.state = estimators::MismatchState::kUnexplained;
  f.effect = estimators::MismatchEffect::kNone;
  f.onset_s = NAN;
  f.detected_s = kOnset_s + 60.0;
  e = DiagnosisEntry("pump3", f, "frame", 0);
  EXPECT_EQ(e.text,
            "pump3: diagnosis: the model no longer explains the frame sensor (window NIS 9712 > "
            "136), found 2026-01-01 00:05:01 UTC; cause not named yet");
  EXPECT_EQ(Fields(e).at("CAUSE"), "unexplained");

  estimators::MismatchFinding ok;
  ok.state = estimators::MismatchState::kConsistent;
  ok.window_nis = 61;
  ok.threshold = 135.7;
  e = DiagnosisEntry("pump1", ok, "frame", 0);
  EXPECT_EQ(e.text, "pump1: diagnosis: the model explains the frame sensor (window NIS 61 <= 136)");
  EXPECT_EQ(e.level, LogLevel::kNotice);
  EXPECT_EQ(Fields(e).count("CAUSE"), 0u);
}

TEST(OperatorText, DurationsAndCauses) {
  EXPECT_EQ(DurationText(45.4), "45 s");
  EXPECT_EQ(DurationText(276.2), "4 min 36 s");
  EXPECT_EQ(DurationText(7500.0), "2 h 05 min");
  EXPECT_EQ(DurationText(INFINITY), "never");
  using estimators::MismatchEffect;
  using estimators::MismatchState;
  EXPECT_EQ(CauseText(MismatchState::kPlantChange, MismatchEffect::kFrameAmbientResistance, 1.81,
                      "frame"),
            "cooling reduced (frame-to-ambient resistance x1.81)");
  EXPECT_EQ(
      CauseText(MismatchState::kSensorFaultSuspected, MismatchEffect::kSensorOffset, 3.04, "frame"),
      "frame sensor reads +3.0 K off (the sensor, not the plant)");
  EXPECT_EQ(CauseText(MismatchState::kUnexplained, MismatchEffect::kNone, NAN, "frame"),
            "the model no longer explains the frame sensor, cause not named yet");
  EXPECT_EQ(CauseText(MismatchState::kConsistent, MismatchEffect::kNone, NAN, "frame"), "");
}

}  // namespace
}  // namespace pumptherm::daemon
