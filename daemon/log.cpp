#include "daemon/log.hpp"

#include <cstdio>
#include <cstdlib>

namespace pumptherm::daemon {

void LogLine(LogLevel level, std::string_view message) {
  static const bool journal = std::getenv("JOURNAL_STREAM") != nullptr;
  if (journal) {
    fmt::print(stderr, "<{}>{}\n", static_cast<int>(level), message);
    return;
  }
  const char* tag = "";
  switch (level) {
    case LogLevel::kError: tag = "error: "; break;
    case LogLevel::kWarning: tag = "warning: "; break;
    default: break;
  }
  fmt::print(stderr, "pumpthermd: {}{}\n", tag, message);
}

}  // namespace pumptherm::daemon
