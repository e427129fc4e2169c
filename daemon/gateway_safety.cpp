// The gateway's safety state (docs/daemon.md, "State across restarts"): the latched trips and
// the clear counters, collected, committed through the live loop's writer, and taken back at
// start, or, when they were lost, replaced by a latched "safety state lost" trip.
#include <fmt/format.h>

#include <cmath>

#include "daemon/gateway.hpp"
#include "daemon/log.hpp"

namespace pumptherm::daemon {

SafetyState Gateway::CollectSafetyState() const {
  SafetyState s;
  for (const auto& p : pumps_) {
    auto& latches = s.latched[p->config().name];
    for (const auto& t : p->Save().latched_trips) {
      // A trip without a value ("safety state lost") is saved with 0.
      latches.push_back({t.node, std::isfinite(t.value_degC) ? t.value_degC : 0.0});
    }
  }
  s.counters = clear_auth_.counters();
  s.refused_up_to_us = clear_auth_.refused_up_to_us();
  return s;
}

bool Gateway::CommitSafetyState() {
  if (!safety_commit_) return true;
  std::string error;
  if (safety_commit_(FormatSafetyState(CollectSafetyState()), &error)) return true;
  // Worded apart from the estimator state's "state not saved" line (a full disk shows both).
  Log(LogLevel::kError,
      "the safety state cannot be written: {} (a trip latched since may not survive a restart)",
      error);
  return false;
}

void Gateway::ApplySafetyState(const SafetyState& s, std::int64_t now_us) {
  MarkAllDue();
  clear_auth_.MergeCounters(s.counters);
  clear_auth_.RefuseSignedUpTo(s.refused_up_to_us);
  std::string lost;
  for (auto& pump : pumps_) {
    const auto it = s.latched.find(pump->config().name);
    if (it == s.latched.end()) continue;  // configured since the file was written
    PumpSavedState saved;
    for (const auto& l : it->second) saved.latched_trips.push_back({l.node, l.value_degC});
    // Exactly the saved latches: a clear committed after the last estimator save stays done.
    pump->ClearTrips();
    if (!pump->RestoreLatchedTrips(saved, now_us)) {
      pump->LatchStateLost(now_us);
      lost += fmt::format("{}{}", lost.empty() ? "" : ", ", pump->config().name);
    }
  }
  if (!lost.empty()) {
    Log(LogLevel::kWarning,
        "safety state: latched trips of pump(s) {} name alarm nodes the configured model lacks; "
        "they latch 'safety state lost' instead (clear them once the pumps are checked)",
        lost);
  }
}

void Gateway::SafetyStateLost(const std::string& why, std::int64_t now_us,
                              std::int64_t wall_now_us) {
  MarkAllDue();
  clear_auth_.RefuseSignedUpTo(wall_now_us);
  const bool latch = config_.gateway.lost_safety_state == LostSafetyState::kLatch;
  for (auto& pump : pumps_) {
    if (!latch) continue;
    pump->LatchStateLost(now_us);
    LogFields(LogLevel::kWarning, {{"PUMP", pump->config().name}, {"REASON", "safety_state_lost"}},
              "pump {}: latched trip 'safety state lost': {}; whether a trip was latched before is "
              "not known, so it is latched now (clear it once the pump is checked; "
              "gateway.lost_safety_state)",
              pump->config().name, why);
  }
  if (!latch) {
    Log(LogLevel::kWarning,
        "safety state lost: {}; gateway.lost_safety_state = \"warn\": the pumps start without "
        "latched trips (any trip latched before is gone)",
        why);
  }
  Log(LogLevel::kNotice,
      "clear commands signed before now are refused (their counters are not known any more)");
}

}  // namespace pumptherm::daemon
