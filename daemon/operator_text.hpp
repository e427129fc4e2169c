#pragma once
/// Words an operator reads, shared by the journal (daemon/alarm_journal.hpp) and the tools that
/// show the gateway's messages (`pumptherm watch`): times, durations, alarm reasons, node names
/// and the model diagnosis' cause, so that each thing is said one way everywhere. Pure text.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "estimators/alarms.hpp"
#include "estimators/mismatch_detector.hpp"

namespace pumptherm::daemon {

/// `unix_us` (us since the Unix epoch) as local time with the zone's abbreviation, e.g.
/// "2026-01-01 00:04:01 UTC" (`with_ms`: "2026-01-01 00:04:01.250 UTC"); the zone is the
/// process's (TZ).
std::string LocalTimeText(std::int64_t unix_us, bool with_ms = false);

/// A duration for people: "45 s", "4 min 36 s", "5 min", "2 h 05 min"; "never" when not finite.
std::string DurationText(double s);

/// A reason in words: "estimated over temperature", "stale telemetry".
std::string ReasonWords(estimators::AlarmReason reason);

/// The name a node index has in alarm messages: the model's node, or "winding_resistance" one
/// past them; "" for none (-1) or out of range.
std::string AlarmNodeName(int node, const std::vector<std::string>& node_names);

/// The same as a person reads it: the model's node, or "winding from resistance".
std::string NodeWords(std::string_view alarm_node_name);

/// Whether a diagnosis blames the plant or the sensor (plant change, sensor fault suspected,
/// unexplained).
bool DiagnosisBlames(estimators::MismatchState state);

/// The cause a diagnosis names, in words first and its size after, e.g. "cooling lost
/// (frame-to-ambient resistance x20 or more)"; "" unless the diagnosis blames the plant or the
/// sensor. `value` in the effect's unit (estimators::MismatchEffect).
std::string CauseText(estimators::MismatchState state, estimators::MismatchEffect effect,
                      double value, std::string_view measured_node);

}  // namespace pumptherm::daemon
