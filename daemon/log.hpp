#pragma once
/// Logging to stderr. Under systemd (JOURNAL_STREAM set) each line carries the sd-daemon
/// priority prefix ("<4>") so journald records its level; on a terminal it reads
/// "pumpthermd: warning: ...".

#include <fmt/format.h>

#include <cstdint>
#include <string_view>

namespace pumptherm::daemon {

enum class LogLevel { kError = 3, kWarning = 4, kNotice = 5, kInfo = 6, kDebug = 7 };

/// Writes one line (no trailing newline needed) at `level`.
void LogLine(LogLevel level, std::string_view message);

template <typename... Args>
void Log(LogLevel level, fmt::format_string<Args...> format, Args&&... args) {
  LogLine(level, fmt::format(format, std::forward<Args>(args)...));
}

/// Rate limit for one kind of log line that outsiders can trigger at will (refused commands):
/// at most `burst` lines per window of `window_s`; the lines over that are counted, not written.
/// Time is the caller's (the pipeline's clock, us), so offline runs log as live ones do.
class LogRateLimiter {
 public:
  /// Throws std::invalid_argument for burst < 1 or a window not > 0.
  LogRateLimiter(int burst, double window_s);
  /// Whether a line at `now_us` may be written. When it may, `held_back` (if given) gets the
  /// number of lines not written since the last one that was (the caller says so in the line).
  bool Allow(std::int64_t now_us, std::uint64_t* held_back = nullptr);
  /// Lines held back and not yet reported, once their window has ended at `now_us` (0 while it
  /// runs or when there are none); reporting them resets the count. For a summary line when no
  /// further line comes to carry the count.
  std::uint64_t TakeHeldBack(std::int64_t now_us);
  /// Every line held back so far.
  std::uint64_t held_back_total() const { return held_back_total_; }

 private:
  int burst_;
  std::int64_t window_us_;
  std::int64_t window_start_us_ = 0;
  int in_window_ = 0;  // lines written in the present window
  bool started_ = false;
  std::uint64_t held_back_ = 0;  // since the last line written or reported
  std::uint64_t held_back_total_ = 0;
};

}  // namespace pumptherm::daemon
