#include "daemon/log.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace pumptherm::daemon {

void LogLine(LogLevel level, std::string_view message) {
  static const bool journal = std::getenv("JOURNAL_STREAM") != nullptr;
  if (journal) {
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
  fmt::print(stderr, "pumpthermd: {}{}\n", tag, message);
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
