#pragma once
/// Logging to stderr. Under systemd (JOURNAL_STREAM set) each line carries the sd-daemon
/// priority prefix ("<4>") so journald records its level; on a terminal it reads
/// "pumpthermd: warning: ...".

#include <fmt/format.h>

#include <string_view>

namespace pumptherm::daemon {

enum class LogLevel { kError = 3, kWarning = 4, kNotice = 5, kInfo = 6, kDebug = 7 };

/// Writes one line (no trailing newline needed) at `level`.
void LogLine(LogLevel level, std::string_view message);

template <typename... Args>
void Log(LogLevel level, fmt::format_string<Args...> format, Args&&... args) {
  LogLine(level, fmt::format(format, std::forward<Args>(args)...));
}

}  // namespace pumptherm::daemon
