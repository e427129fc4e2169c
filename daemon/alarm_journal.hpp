#pragma once
/// The journal's words for a pump's alarm changes and model diagnoses: one line an operator
/// reads ("pump3: trip: winding 121.3 degC (bound 126.1 = estimate + 2 sd) >= 120 degC; cause:
/// cooling lost (frame-to-ambient resistance x20 or more) since 2026-01-01 00:04:01 UTC"), with
/// every number in its unit, and the structured journal fields that find it
/// (`journalctl PUMP=pump3 LEVEL=trip`). docs/daemon.md, "The journal". Text only: the gateway
/// writes the entries.

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/log.hpp"
#include "daemon/operator_text.hpp"
#include "estimators/alarm_values.hpp"
#include "estimators/alarms.hpp"
#include "estimators/mismatch_detector.hpp"
#include "estimators/pump_estimator.hpp"

namespace pumptherm::daemon {

/// One journal entry: its priority, its text and its fields (keys are string literals).
struct JournalEntry {
  LogLevel level = LogLevel::kNotice;
  std::string text;
  std::vector<LogField> fields;
};

/// What an alarm line is made of.
struct AlarmLineInputs {
  std::string_view pump;
  const estimators::AlarmState* state = nullptr;
  /// The active conditions, worst first (Pump::ActiveConditions): the first is the one `state`
  /// names, with its detail and threshold.
  std::span<const estimators::AlarmCondition> conditions;
  /// The model's node names; the index one past them is the winding from resistance.
  const std::vector<std::string>* node_names = nullptr;
  /// The active reasons the previous line showed (bit 1 << reason): what was raised and cleared.
  std::uint16_t logged_reasons = 0;
  const estimators::AlarmConfig* config = nullptr;
  /// The node the pump's sensor measures (the diagnosis speaks of "the frame sensor").
  std::string_view measured_node = "frame";
  /// The model diagnosis at the same moment: its cause is named on the line while it blames the
  /// plant or the sensor.
  const estimators::MismatchFinding* mismatch = nullptr;
  /// Unix time minus the pipeline's time, us (Gateway::SetWallClockOffset; 0 offline).
  std::int64_t wall_offset_us = 0;
  /// The motor's largest current (A; 0: not stated). While the telemetry is silent and this is
  /// stated, an estimated over-temperature acts on the worst case of that current, and the line
  /// says so: the value is what the winding could have reached, not what was seen.
  double silence_worst_current_A = 0.0;
  /// For an estimated over-temperature, the rule that set the value its level acted on: the
  /// line names it (field RULE) and says what the value is (the estimate, or a worst case).
  estimators::AlarmRule rule = estimators::AlarmRule::kBand;
};

/// The line for an alarm change, e.g. "pump3: warning: no telemetry for 4.0 s (limit 2 s)";
/// warning priority unless back to normal (notice). Fields: PUMP, LEVEL (normal, warning, trip),
/// REASON (the reason's name, "none" back to normal), and when they apply NODE, VALUE_DEGC (a
/// temperature), THRESHOLD_DEGC, CAUSE (the diagnosis' effect name, or "unexplained").
JournalEntry AlarmEntry(const AlarmLineInputs& in);

/// The line for a new model diagnosis, e.g. "pump3: diagnosis: cooling lost (frame-to-ambient
/// resistance x20 or more) since 2026-01-01 00:04:01 UTC; the model no longer explains the frame
/// sensor (window NIS 9712 > 136)"; warning while it blames the plant or the sensor. Fields: PUMP,
/// DIAGNOSIS (the state's name), CAUSE (the effect's name, when one is named).
JournalEntry DiagnosisEntry(std::string_view pump, const estimators::MismatchFinding& f,
                            std::string_view measured_node, std::int64_t wall_offset_us);

/// The line for a start of the estimate (notice): cold (at rest at the ambient: this pump's R0
/// and psi0 are learnt in the run-up), warm (the readings that need them wait for a cold start)
/// or restored (with the saved calibration, or the nameplate's), e.g. "pump3: estimate started
/// warm (frame 45.0 degC, ambient 22.0 degC, 21000 r/min): ...". `calibrated` is false for a
/// pump whose readings do not depend on a calibration (no magnet node): no clause about it;
/// `voltage` is whether the pump filter fuses the drive's voltage (R0 is then learnt at the first
/// load change after a cold start). Fields: PUMP, START (cold, warm, restored).
JournalEntry StartEntry(std::string_view pump, const estimators::PumpEstimate& e, bool calibrated,
                        bool voltage = false);

/// The line for a change of R0's calibration (notice; PumpEstimate::r0_changes). Learnt (the
/// identification `tracking`: load changes pinned R0, the winding from resistance is published),
/// e.g. "pump1: R0 learnt: 0.2857 ohm at 20.0 degC, +2.0 % against the nameplate (sd 0.5 %); the
/// winding from resistance is published from now (52.3 degC)"; or R0's sd grew past
/// `max_calibration_sd_K` of winding at the filter's `winding_degC` (`converging` again: the same
/// relative sd is more kelvin in a warmer winding): the winding from resistance is withheld.
/// Fields: PUMP.
JournalEntry R0Entry(std::string_view pump, const estimators::PumpEstimate& e,
                     const estimators::CopperLaw& copper, double max_calibration_sd_K,
                     double winding_degC);

/// The line for the magnet law check (warning; PumpEstimate::magnet_law_suspect): the magnet from
/// the flux reads the rotor colder than the model lets it be, e.g. "pump1: the magnet from the
/// flux reads the rotor colder than the thermal model's rotor losses make it (the filter needs
/// -6.6 W, sd 1.5 W, of rotor heat to follow it): either the motor file's magnet law (-0.100 %/K)
/// is steeper than this magnet's ... or the thermal model's rotor losses are too high ...".
/// `law_per_K` is the motor file's flux temperature coefficient. Fields: PUMP.
JournalEntry MagnetLawEntry(std::string_view pump, const estimators::PumpEstimate& e,
                            double law_per_K);

}  // namespace pumptherm::daemon
