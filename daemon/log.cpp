#include "daemon/log.hpp"

#include <sys/uio.h>
#include <systemd/sd-journal.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <vector>

#include "daemon/operator_text.hpp"

namespace pumptherm::daemon {
namespace {

/// The time lines are stamped with (SetLogTime); kWallClock: the wall clock when written.
constexpr std::int64_t kWallClock = INT64_MIN + 1;
std::int64_t g_log_time_us = kWallClock;

/// "2026-01-01 00:04:01.250 UTC " for the line written now; "" with kNoLogTime.
std::string LinePrefixTime() {
  if (g_log_time_us == kNoLogTime) return "";
  const std::int64_t t = g_log_time_us != kWallClock
                             ? g_log_time_us
                             : std::chrono::duration_cast<std::chrono::microseconds>(
                                   std::chrono::system_clock::now().time_since_epoch())
                                   .count();
  return LocalTimeText(t, true) + " ";
}

bool IsControl(char c) {
  const auto u = static_cast<unsigned char>(c);
  return u < 0x20 || u == 0x7f;
}

/// The journal's native protocol: one entry of MESSAGE=, PRIORITY=, SYSLOG_IDENTIFIER= and the
/// caller's fields. Returns false when journald did not take it.
bool SendToJournal(LogLevel level, std::string_view message, std::span<const LogField> fields) {
  std::vector<std::string> items;
  items.reserve(fields.size() + 3);
  items.push_back(fmt::format("MESSAGE={}", message));
  items.push_back(fmt::format("PRIORITY={}", static_cast<int>(level)));
  items.emplace_back("SYSLOG_IDENTIFIER=pumpthermd");
  for (const LogField& f : fields)
    items.push_back(fmt::format("{}={}", f.key, EscapeControl(f.value)));
  std::vector<iovec> iov(items.size());
  for (std::size_t i = 0; i < items.size(); ++i) {
    iov[i].iov_base = items[i].data();
    iov[i].iov_len = items[i].size();
  }
  return sd_journal_sendv(iov.data(), static_cast<int>(iov.size())) >= 0;
}

}  // namespace

void SetLogTime(std::int64_t unix_us) { g_log_time_us = unix_us; }

std::string EscapeControl(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    if (c == '\\') {
      out += "\\\\";
    } else if (!IsControl(c)) {
      out += c;
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else {
      out += fmt::format("\\x{:02x}", static_cast<unsigned>(static_cast<unsigned char>(c)));
    }
  }
  return out;
}

namespace {
LogCapture* active_capture = nullptr;
}  // namespace

LogCapture::LogCapture(Sink sink) : sink_(std::move(sink)), outer_(active_capture) {
  active_capture = this;
}

LogCapture::~LogCapture() { active_capture = outer_; }

void LogLine(LogLevel level, std::string_view raw, std::span<const LogField> fields) {
  if (active_capture != nullptr) {
    active_capture->sink_(level, raw);
    return;
  }
  static const bool journal = std::getenv("JOURNAL_STREAM") != nullptr;
  // Only what needs it is copied: most lines have no control character and no backslash.
  std::string escaped;
  std::string_view message = raw;
  for (const char c : raw) {
    if (IsControl(c) || c == '\\') {
      escaped = EscapeControl(raw);
      message = escaped;
      break;
    }
  }
  if (journal) {
    if (!fields.empty() && SendToJournal(level, message, fields)) return;
    fmt::print(stderr, "<{}>{}\n", static_cast<int>(level), message);
    return;
  }
  const char* tag = "";
  switch (level) {
    case LogLevel::kError:
      tag = "error: ";
      break;
    case LogLevel::kWarning:
      tag = "warning: ";
      break;
    default:
      break;
  }
  fmt::print(stderr, "{}pumpthermd: {}{}\n", LinePrefixTime(), tag, message);
}

LogRateLimiter::LogRateLimiter(int burst, double window_s)
    : burst_(burst), window_us_(static_cast<std::int64_t>(std::llround(window_s * 1e6))) {
  if (burst < 1 || !(window_s > 0.0))
    throw std::invalid_argument("LogRateLimiter: burst >= 1, window > 0 s");
}

bool LogRateLimiter::Allow(std::int64_t now_us, std::uint64_t* held_back) {
  // A window starts with the first line after the last one ended; a clock going back (a new
  // time origin) starts one too.
  if (!started_ || now_us - window_start_us_ >= window_us_ || now_us < window_start_us_) {
    started_ = true;
    window_start_us_ = now_us;
    in_window_ = 0;
  }
  if (in_window_ >= burst_) {
    ++held_back_;
    ++held_back_total_;
    return false;
  }
  ++in_window_;
  if (held_back != nullptr) *held_back = held_back_;
  held_back_ = 0;
  return true;
}

std::uint64_t LogRateLimiter::TakeHeldBack(std::int64_t now_us) {
  if (held_back_ == 0 || (now_us - window_start_us_ < window_us_ && now_us >= window_start_us_))
    return 0;
  const std::uint64_t n = held_back_;
  held_back_ = 0;
  return n;
}

}  // namespace pumptherm::daemon
