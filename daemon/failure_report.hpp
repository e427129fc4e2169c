#pragma once
/// Rate-limited reporting of an operation that fails again and again (LCM sends while the
/// network is gone, state writes while the disk is full): the journal gets the first failure at
/// once, then at most one reminder per `reminder_period_us` with the count since the last
/// report, a line at once when the reason changes, and one line when it works again. Every
/// failure is counted, reported or not. Time enters as an argument (no clock here).

#include <cstdint>
#include <string>
#include <string_view>

namespace pumptherm::daemon {

class FailureReport {
 public:
  enum class Kind {
    kQuiet,      ///< nothing to log
    kFirst,      ///< the first failure of a run of failures
    kChanged,    ///< a failure whose reason differs from the last one reported
    kReminder,   ///< still failing; `failures_since_report` more since the last line
    kRecovered,  ///< a success that ends a run of `run_failures` failures
  };
  struct Report {
    Kind kind = Kind::kQuiet;
    std::uint64_t failures_since_report = 0;  ///< failures since the last line (this one included)
    std::uint64_t run_failures = 0;           ///< failures in the present (or just ended) run
    double run_s = 0.0;                       ///< from the run's first failure to now
  };

  explicit FailureReport(std::int64_t reminder_period_us)
      : reminder_period_us_(reminder_period_us) {}

  /// One failure at `now_us`, for reason `what` (compared with the last reported reason).
  Report Failure(std::int64_t now_us, std::string_view what);
  /// One success at `now_us`.
  Report Success(std::int64_t now_us);

  std::uint64_t failures() const { return failures_; }
  std::uint64_t successes() const { return successes_; }
  bool failing() const { return run_failures_ > 0; }

 private:
  std::int64_t reminder_period_us_;
  std::uint64_t failures_ = 0;
  std::uint64_t successes_ = 0;
  std::uint64_t run_failures_ = 0;
  std::uint64_t unreported_ = 0;
  std::int64_t run_start_us_ = 0;
  std::int64_t last_report_us_ = 0;
  std::string last_what_;
};

}  // namespace pumptherm::daemon
