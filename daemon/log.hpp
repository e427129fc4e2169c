#pragma once
/// Logging to stderr. Under systemd (JOURNAL_STREAM set) each line carries the sd-daemon
/// priority prefix ("<4>") so journald records its level (journald stamps the time); elsewhere it
/// reads "2026-01-01 00:04:01.250 UTC pumpthermd: warning: ...", stamped with the log time:
/// the wall clock, or the pipeline's time once SetLogTime() was called (offline: the
/// recording's).

#include <fmt/format.h>

#include <cstdint>
#include <functional>
#include <initializer_list>
#include <span>
#include <string>
#include <string_view>

namespace pumptherm::daemon {

enum class LogLevel { kError = 3, kWarning = 4, kNotice = 5, kInfo = 6, kDebug = 7 };

/// One structured journal field: `key` in journald's form (upper case letters, digits and '_',
/// not starting with '_', e.g. "PUMP"), `value` any text (control characters are escaped).
struct LogField {
  std::string_view key;
  std::string value;
};

/// `text` with every control character (below 0x20, and 0x7f) written as a visible escape:
/// "\n", "\r", "\t", else "\xNN"; a backslash is doubled. A logged string that came from
/// outside (a command's source, a comment, a file name) cannot then start a line of its own or
/// forge a priority prefix.
std::string EscapeControl(std::string_view text);

/// Writes one line (no trailing newline needed) at `level`; control characters in `message`
/// are escaped (EscapeControl). Under journald (JOURNAL_STREAM set) with `fields`, the line goes
/// through the journal's native protocol with MESSAGE=, PRIORITY=, SYSLOG_IDENTIFIER=pumpthermd
/// and the fields, so that `journalctl PUMP=pump3` finds it (if the journal socket refuses it,
/// the line goes to stderr as without fields). Elsewhere the fields are not written.
void LogLine(LogLevel level, std::string_view message, std::span<const LogField> fields = {});

/// SetLogTime's "no time": the lines carry none (an offline run before its recording's first
/// frame: they are about the run, not about a moment of the recording).
inline constexpr std::int64_t kNoLogTime = INT64_MIN;

/// Stamps the lines written from now on with `unix_us` (microseconds since the Unix epoch):
/// offline runs call it with the pipeline's time before each frame, so a line says when in the
/// recording it happened. Until the first call, lines carry the wall clock.
void SetLogTime(std::int64_t unix_us);

/// While it lives, every line LogLine would write goes to `sink` instead (unescaped, without
/// fields): for a command that runs the pipeline to report on it (`pumpthermd --check-config
/// --against` runs it once per candidate sensor lag). Captures nest; one thread only.
class LogCapture {
 public:
  using Sink = std::function<void(LogLevel, std::string_view)>;
  explicit LogCapture(Sink sink);
  ~LogCapture();
  LogCapture(const LogCapture&) = delete;
  LogCapture& operator=(const LogCapture&) = delete;

 private:
  friend void LogLine(LogLevel, std::string_view, std::span<const LogField>);
  Sink sink_;
  LogCapture* outer_;
};

template <typename... Args>
void Log(LogLevel level, fmt::format_string<Args...> format, Args&&... args) {
  LogLine(level, fmt::format(format, std::forward<Args>(args)...));
}

/// Log with structured journal fields: LogFields(kWarning, {{"PUMP", name}}, "pump {}: ...", ...).
template <typename... Args>
void LogFields(LogLevel level, std::initializer_list<LogField> fields,
               fmt::format_string<Args...> format, Args&&... args) {
  LogLine(level, fmt::format(format, std::forward<Args>(args)...),
          std::span<const LogField>(fields.begin(), fields.size()));
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
