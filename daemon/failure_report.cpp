#include "daemon/failure_report.hpp"

namespace pumptherm::daemon {

FailureReport::Report FailureReport::Failure(std::int64_t now_us, std::string_view what) {
  ++failures_;
  ++unreported_;
  Report r;
  if (run_failures_++ == 0) {
    run_start_us_ = now_us;
    r.kind = Kind::kFirst;
  } else if (what != last_what_) {
    r.kind = Kind::kChanged;
  } else if (now_us - last_report_us_ >= reminder_period_us_) {
    r.kind = Kind::kReminder;
  }
  r.run_failures = run_failures_;
  r.run_s = static_cast<double>(now_us - run_start_us_) * 1e-6;
  if (r.kind != Kind::kQuiet) {
    r.failures_since_report = unreported_;
    unreported_ = 0;
    last_report_us_ = now_us;
    last_what_.assign(what);
  }
  return r;
}

FailureReport::Report FailureReport::Success(std::int64_t now_us) {
  ++successes_;
  Report r;
  if (run_failures_ == 0) return r;
  r.kind = Kind::kRecovered;
  r.run_failures = run_failures_;
  r.failures_since_report = unreported_;
  r.run_s = static_cast<double>(now_us - run_start_us_) * 1e-6;
  run_failures_ = 0;
  unreported_ = 0;
  last_what_.clear();
  last_report_us_ = now_us;
  return r;
}

}  // namespace pumptherm::daemon
