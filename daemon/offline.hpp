#pragma once
/// Offline mode: the gateway pipeline over a candump log instead of live sockets, as fast as
/// it can, with the log's timestamps as the clock.

#include <istream>
#include <string>

#include "daemon/gateway.hpp"

namespace pumptherm::daemon {

struct OfflineResult {
  std::uint64_t lines = 0;
  std::uint64_t frames = 0;
  std::uint64_t bad_lines = 0;   ///< malformed lines: reported (first few) and counted, skipped
};

/// Feeds every frame of the candump log in `in` to `gateway`. `source` names the log in error
/// messages ("FILE:LINE:COLUMN: what was expected"); at most `max_reported` bad lines are
/// reported on stderr, all are counted. Never throws for bad lines.
OfflineResult RunOffline(std::istream& in, const std::string& source, Gateway& gateway,
                         std::uint64_t max_reported = 20);

}  // namespace pumptherm::daemon
