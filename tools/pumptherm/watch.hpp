#pragma once
/// The operator's live view of every pump from the gateway's LCM messages (`pumptherm watch`):
/// the last TEMPS, ALARM and TELEMETRY message of each pump, kept by pump name, and the views
/// printed from them: one line per pump within 100 columns, or the detail of one pump. No I/O
/// here: the command feeds messages in and prints the views. docs/lcm.md, "pumptherm watch".

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "pumptherm/alarm_t.hpp"
#include "pumptherm/telemetry_t.hpp"
#include "pumptherm/temperatures_t.hpp"

namespace pumptherm::tools {

/// The widest line Table() writes (a terminal's 100 columns).
inline constexpr std::size_t kWatchColumns = 100;

class PumpWatch {
 public:
  /// Keeps `m` as pump `m.pump`'s latest temperatures, received at `now_us` (the watcher's
  /// clock, microseconds since the Unix epoch).
  void OnTemperatures(const pumptherm::temperatures_t& m, std::int64_t now_us);
  /// Keeps `m` as pump `m.pump`'s latest alarm state, received at `now_us`.
  void OnAlarm(const pumptherm::alarm_t& m, std::int64_t now_us);
  /// Keeps `m` as pump `m.pump`'s latest telemetry (the direct readings), received at `now_us`.
  void OnTelemetry(const pumptherm::telemetry_t& m, std::int64_t now_us);
  /// The node pump `pump`'s sensor measures (from the gateway's configuration; "frame" when not
  /// told): the diagnosis speaks of it.
  void SetMeasuredNode(const std::string& pump, const std::string& node);

  /// Pumps heard from so far.
  std::size_t PumpCount() const { return pumps_.size(); }
  bool Has(const std::string& pump) const { return pumps_.count(pump) > 0; }

  /// One line per pump, sorted by name, none wider than kWatchColumns: the age of its last
  /// message (STALE after `stale_after_s` of silence), the alarm level with what raised it, the
  /// hottest node's estimate with its +-2 sd band, and the model diagnosis with since when; a
  /// pump's mark in `marks` other than "signed" (whether the gateway signed its messages,
  /// `--gateway-key`) takes the diagnosis's place.
  std::string Table(std::int64_t now_us, double stale_after_s,
                    const std::map<std::string, std::string>& marks = {}) const;
  /// The names of the pumps heard from, sorted.
  std::vector<std::string> Pumps() const;

  /// Everything known of one pump: every node with its band, the direct readings (frame sensor,
  /// ambient, winding from resistance, magnet from flux), the diagnosis and since when, every
  /// alarm condition with its cause, and the time to trip when there is one.
  std::string Detail(const std::string& pump, std::int64_t now_us, double stale_after_s) const;

 private:
  struct Entry {
    pumptherm::temperatures_t temps;
    pumptherm::alarm_t alarm;
    pumptherm::telemetry_t telemetry;
    std::int64_t temps_rx_us = -1;
    std::int64_t alarm_rx_us = -1;
    std::int64_t telemetry_rx_us = -1;
    std::string measured_node = "frame";
  };
  std::map<std::string, Entry> pumps_;
  std::map<std::string, std::string> measured_nodes_;
};

/// Name of an identifier status as the LCM message carries it ("tracking", ...).
std::string IdentStatusName(int status);
/// Name of an alarm reason as the LCM message carries it, in words ("stale telemetry", ...).
std::string AlarmReasonLabel(int reason);

}  // namespace pumptherm::tools
