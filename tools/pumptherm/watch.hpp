#pragma once
/// The operator's live view of every pump from the gateway's LCM messages (`pumptherm watch`):
/// the last TEMPS and ALARM message of each pump, kept by pump name, and the table printed from
/// them. No I/O here: the command feeds messages in and prints the table.

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "pumptherm/alarm_t.hpp"
#include "pumptherm/temperatures_t.hpp"

namespace pumptherm::tools {

class PumpWatch {
 public:
  /// Keeps `m` as pump `m.pump`'s latest temperatures, received at `now_us` (the watcher's
  /// clock, microseconds since the Unix epoch).
  void OnTemperatures(const pumptherm::temperatures_t& m, std::int64_t now_us);
  /// Keeps `m` as pump `m.pump`'s latest alarm state, received at `now_us`.
  void OnAlarm(const pumptherm::alarm_t& m, std::int64_t now_us);

  /// Pumps heard from so far.
  std::size_t PumpCount() const { return pumps_.size(); }

  /// One line per pump, sorted by name: age of the last message, every node's estimate with its
  /// standard deviation, the winding from resistance with its status, the filter's status and
  /// NIS, the alarm level with every active condition (reason and node) and the forecast.
  /// A pump silent for more than `stale_after_s` is marked STALE; `marks` adds a pump's text
  /// (whether the gateway signed its messages, `--gateway-key`).
  std::string Table(std::int64_t now_us, double stale_after_s,
                    const std::map<std::string, std::string>& marks = {}) const;
  /// The names of the pumps heard from, sorted.
  std::vector<std::string> Pumps() const;

 private:
  struct Entry {
    pumptherm::temperatures_t temps;
    pumptherm::alarm_t alarm;
    std::int64_t temps_rx_us = -1;
    std::int64_t alarm_rx_us = -1;
  };
  std::map<std::string, Entry> pumps_;
};

/// Name of an identifier status as the LCM message carries it ("tracking", ...).
std::string IdentStatusName(int status);
/// Name of an alarm reason as the LCM message carries it ("forecast", ...).
std::string AlarmReasonLabel(int reason);

}  // namespace pumptherm::tools
