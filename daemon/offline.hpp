#pragma once
/// Offline mode: the gateway pipeline over a candump log instead of live sockets, as fast as
/// it can (or paced), with the log's timestamps as the clock. The output frames go to a candump
/// log, the LCM messages to an LCM log file (lcm-logplayer plays it), and per-pump estimates to
/// CSV files, as asked.

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <functional>
#include <istream>
#include <limits>
#include <memory>
#include <string>

#include "daemon/gateway.hpp"
#include "protocol/candump_log.hpp"

namespace lcm {
class LCM;
}

namespace pumptherm::daemon {

struct OfflineOptions {
  std::string output_log;  ///< candump log of the frames the gateway sends ("" = none)
  std::string lcm_log;     ///< LCM log file of the messages it publishes ("" = none)
  std::string csv_dir;     ///< per-pump CSV of every thermal step ("" = none)
  /// The CSV of the first pump into this file instead ("-": standard output; "" = none).
  std::string csv_file;
  /// Subtracted from the Unix time in the CSV's time_s; NaN: the recording's first frame's
  /// whole second (time since the recording's start, docs/daemon.md "Time in CSV files").
  double csv_time_origin_s = std::numeric_limits<double>::quiet_NaN();
  bool table = false;               ///< print the pump table while running
  double table_period_s = 60.0;     ///< of log time between tables
  double pace = 0.0;                ///< log seconds per wall second (0 = as fast as possible)
  std::uint64_t max_reported = 20;  ///< malformed lines reported on stderr (all are counted)
  /// Also publish every LCM message here as it is made (`pumptherm replay --pace`: watch and the
  /// spy follow a recording); nullptr: only the LCM log file. Not owned.
  lcm::LCM* lcm_publish = nullptr;
  /// Called after each Advance that ran, with the pipeline's time (us): what a tool reads from
  /// the pumps' snapshots as the recording plays (`pumptherm replay`, `--check-config --against`).
  std::function<void(const Gateway&, std::int64_t)> after_advance;
  /// Called with every frame before the gateway gets it: its interface (FrameCounter index),
  /// the frame at the pipeline's time and the log line it came from.
  std::function<void(std::size_t, const protocol::TimedFrame&, std::uint64_t)> on_frame;
};

struct OfflineResult {
  std::uint64_t lines = 0;
  std::uint64_t frames = 0;
  std::uint64_t bad_lines = 0;  ///< malformed lines: reported (first few) and counted, skipped
  /// Screen-format lines without a timestamp (candump without -t a): the pipeline needs the
  /// receive time; reported (first few), counted, skipped.
  std::uint64_t untimed_lines = 0;
  /// Stamps more than OfflineClock::kClockStepUs behind the one before (two logs concatenated,
  /// the recording host's clock set back): warned with file:line (first few) and counted; their
  /// frames are used, time holding at the step (OfflineClock).
  std::uint64_t time_steps_back = 0;
  std::uint64_t frames_out = 0;
  std::uint64_t lcm_out = 0;
  /// What the recording's stamps count: relative ones (-t z, -t d) become seconds since its
  /// start (ClassifyCandumpStamps; a notice names the file and the format found).
  protocol::CandumpTimeBase time_base = protocol::CandumpTimeBase::kAbsolute;
  std::int64_t first_us = -1;  ///< the pipeline's time of the first and last frame (-1: none)
  std::int64_t last_us = -1;
};

/// The pipeline's clock in offline mode, from the log's stamps (kernel receive times, the wall
/// clock of the recording host). Elapsed time never runs backward: a stamp up to
/// kClockStepUs before the previous one (frames of two interfaces slightly out of order) is
/// taken at the later time; a larger backward step is the recording host's clock being set
/// back, so time holds there and runs on at the pace of the new stamps. A forward step cannot be
/// told from a silence in the recording and is elapsed time (the model ages the estimate over
/// it; stale telemetry is raised).
class OfflineClock {
 public:
  static constexpr std::int64_t kClockStepUs = 1'000'000;
  /// The pipeline time (us) for a frame stamped `stamp_us`.
  std::int64_t Now(std::int64_t stamp_us);
  /// Backward steps over kClockStepUs seen so far, and the size of the last one (us).
  std::uint64_t steps_back() const { return steps_back_; }
  std::int64_t last_step_back_us() const { return last_step_back_us_; }

 private:
  std::int64_t last_stamp_us_ = -1;
  std::int64_t last_now_us_ = -1;
  std::int64_t offset_us_ = 0;
  std::uint64_t steps_back_ = 0;
  std::int64_t last_step_back_us_ = 0;
};

/// Feeds every frame of the candump recording in `in` (any format ParseCandumpLine reads; read
/// in large blocks) to `gateway`, advancing it whenever its NextDueUs() is reached. `source`
/// names the log in warnings ("FILE:LINE:COLUMN: what was expected"). The first
/// kCandumpStampsToClassify stamps say what they count (ClassifyCandumpStamps); relative ones
/// are read as time since the recording's start (its frames are held until then, so nothing
/// runs on a wrong clock). Throws std::runtime_error naming the file when an output file cannot
/// be written or the log cannot be read.
OfflineResult RunOffline(std::istream& in, const std::string& source, Gateway& gateway,
                         const OfflineOptions& options = {});

/// Opens the candump log at `path` for RunOffline. Throws std::runtime_error naming the file
/// when it does not exist, is a directory, or cannot be opened.
std::ifstream OpenLog(const std::string& path);

/// Throws std::runtime_error naming `source` and what it held when a run found no frame to run
/// on: an empty file, only blank or comment lines, or lines none of which is a timed frame
/// (how many were malformed, how many lacked a timestamp).
void RequireFrames(const OfflineResult& r, const std::string& source);

}  // namespace pumptherm::daemon
