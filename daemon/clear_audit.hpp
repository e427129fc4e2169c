#pragma once
/// The audit trail of refused clears when they come faster than anyone can read them (a flood
/// of forged commands): at most a burst of lines per window go to the journal, and what was held
/// back is summarised in one line per source, with the count of each reason, once the window
/// ends, before the next line written, and at stop. Pure bookkeeping: time is the caller's.

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/log.hpp"

namespace pumptherm::daemon {

class ClearAudit {
 public:
  /// At most `burst` lines per `window_s`. Throws std::invalid_argument as LogRateLimiter.
  ClearAudit(int burst, double window_s);

  /// One summary: what was held back from one source.
  struct Summary {
    std::string source;
    std::uint64_t count = 0;
    std::string reasons;  ///< "bad tag 19990, unknown key 3"
    std::string text;     ///< the whole line
  };

  /// A refused clear from `source` for `reason` (a short label) at `now_us`. Returns whether its
  /// own line may be written; `*before` gets the summaries to write before it (what was held
  /// back in the window that ended).
  bool Refused(std::int64_t now_us, std::string_view source, std::string_view reason,
               std::vector<Summary>* before);
  /// The summaries once the window of the lines held back has ended at `now_us` (all of them
  /// with `stop`); each source's count is reported once.
  std::vector<Summary> TakeSummaries(std::int64_t now_us, bool stop);

  /// Every refusal held back so far.
  std::uint64_t held_back_total() const { return limiter_.held_back_total(); }

  /// Sources followed one by one; the rest are summarised together.
  static constexpr std::size_t kMaxSources = 16;

 private:
  std::vector<Summary> Summaries();

  LogRateLimiter limiter_;
  int burst_;
  double window_s_;
  struct Held {
    std::uint64_t count = 0;
    std::map<std::string, std::uint64_t> reasons;
  };
  std::map<std::string, Held> held_;
};

}  // namespace pumptherm::daemon
