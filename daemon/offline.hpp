#pragma once
/// Offline mode: the gateway pipeline over a candump log instead of live sockets, as fast as
/// it can (or paced), with the log's timestamps as the clock. The output frames go to a candump
/// log, the LCM messages to an LCM log file (lcm-logplayer plays it), and per-pump estimates to
/// CSV files, as asked.

#include <cstdio>
#include <istream>
#include <memory>
#include <string>

#include "daemon/gateway.hpp"

namespace pumptherm::daemon {

struct OfflineOptions {
  std::string output_log;   ///< candump log of the frames the gateway sends ("" = none)
  std::string lcm_log;      ///< LCM log file of the messages it publishes ("" = none)
  std::string csv_dir;      ///< per-pump CSV of every thermal step ("" = none)
  double csv_time_origin_s = 0.0;  ///< subtracted from the Unix time in the CSV's time_s
  bool table = false;       ///< print the pump table while running
  double table_period_s = 60.0;  ///< of log time between tables
  double pace = 0.0;        ///< log seconds per wall second (0 = as fast as possible)
  std::uint64_t max_reported = 20;  ///< malformed lines reported on stderr (all are counted)
};

struct OfflineResult {
  std::uint64_t lines = 0;
  std::uint64_t frames = 0;
  std::uint64_t bad_lines = 0;   ///< malformed lines: reported (first few) and counted, skipped
  std::uint64_t frames_out = 0;
  std::uint64_t lcm_out = 0;
};

/// Feeds every frame of the candump log in `in` to `gateway`. `source` names the log in error
/// messages ("FILE:LINE:COLUMN: what was expected"). Throws std::runtime_error only when an
/// output file cannot be written.
OfflineResult RunOffline(std::istream& in, const std::string& source, Gateway& gateway,
                         const OfflineOptions& options = {});

}  // namespace pumptherm::daemon
