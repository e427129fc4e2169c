#include "daemon/offline.hpp"

#include "daemon/log.hpp"
#include "protocol/candump_log.hpp"

namespace pumptherm::daemon {

OfflineResult RunOffline(std::istream& in, const std::string& source, Gateway& gateway,
                         std::uint64_t max_reported) {
  OfflineResult r;
  std::string line;
  std::string last_interface;
  std::size_t last_index = 0;
  while (std::getline(in, line)) {
    ++r.lines;
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    if (p.skip) continue;
    if (!p.ok) {
      if (++r.bad_lines <= max_reported) {
        Log(LogLevel::kWarning, "{}:{}:{}: {}; line skipped", source, r.lines, p.column, p.error);
      }
      continue;
    }
    if (p.record.interface != last_interface) {
      last_interface = p.record.interface;
      last_index = gateway.Interface(last_interface);
    }
    gateway.OnFrame(last_index, protocol::TimedFrame{p.record.time_us, p.record.frame});
    ++r.frames;
  }
  if (r.bad_lines > max_reported) {
    Log(LogLevel::kWarning, "{}: {} more malformed lines skipped", source, r.bad_lines - max_reported);
  }
  return r;
}

}  // namespace pumptherm::daemon
