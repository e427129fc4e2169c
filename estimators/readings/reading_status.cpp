#include "estimators/readings/reading_status.hpp"

namespace pumptherm::estimators {

const char* ReadingStateName(ReadingState state) {
  switch (state) {
    case ReadingState::kFused:
      return "fused";
    case ReadingState::kAbsent:
      return "absent";
    case ReadingState::kSensorFault:
      return "sensor_fault";
    case ReadingState::kStale:
      return "stale";
    case ReadingState::kNotIdentified:
      return "not_identified";
    case ReadingState::kTooSlow:
      return "too_slow";
    case ReadingState::kGated:
      return "gated";
    case ReadingState::kNotFused:
      return "not_fused";
    case ReadingState::kRejected:
      return "rejected";
  }
  return "unknown";
}

}  // namespace pumptherm::estimators
