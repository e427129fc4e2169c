#include "estimators/readings/frame_reading.hpp"

#include <cmath>

namespace pumptherm::estimators {

void FrameReading::Prepare(double now_s, bool link_silent) {
  fault_ = health_.Fault(now_s);
  raw_degC_ = fault_ == SensorFault::kMissing ? std::nan("") : health_.last_degC();
  offered_degC_ = fault_ == SensorFault::kNone ? raw_degC_ : std::nan("");
  alarm_fault_ = fault_ == SensorFault::kMissing && link_silent ? SensorFault::kNone : fault_;
  const bool none_yet = std::isnan(health_.last_s());
  status_.Reset(none_yet                          ? ReadingState::kAbsent
                : fault_ == SensorFault::kMissing ? ReadingState::kStale
                                                  : ReadingState::kSensorFault);
  status_.observation = offered_degC_;
}

void FrameReading::Record(const ReadingRow& row) {
  last_fault_ = fault_;
  if (std::isnan(offered_degC_)) return;
  status_.Record(row, ReadingState::kRejected);
}

}  // namespace pumptherm::estimators
